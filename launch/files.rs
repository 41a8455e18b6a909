//! Writing files so that a reader never sees half of one and nothing already there is lost: a
//! file goes through a partial file beside it and is renamed into place, never over an existing
//! file unless asked; I/O errors in words (a full disk named as such).

use crate::error::{Error, Result};
use std::path::Path;

/// An I/O error in words, a full disk named as such.
pub fn io_why(e: &std::io::Error) -> String {
    if e.raw_os_error() == Some(libc::ENOSPC) {
        "no space left on device (ENOSPC)".to_string()
    } else {
        e.to_string()
    }
}

/// Writes the file `path` through `.<name>.partial` beside it: `fill` writes the content, which is
/// flushed, then the partial file is renamed to `path`; unless `replace`, never over an existing
/// `path` (checked by the rename itself). On any failure the partial file is removed and the
/// error names `path` and the cause (ENOSPC as "no space left on device").
pub fn write_through_partial(
    path: &Path,
    replace: bool,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| Error::Write {
            path: path.to_path_buf(),
            why: "not a file name".into(),
        })?
        .to_string_lossy();
    let tmp = path.with_file_name(format!(".{name}.partial"));
    // A stale partial file of a run's output is refused (a run never starts over one); others
    // are replaced.
    let file = if replace {
        std::fs::File::create(&tmp)
    } else {
        std::fs::File::create_new(&tmp)
    };
    let written = file.and_then(|file| {
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w)?;
        w.into_inner().map_err(|e| e.into_error())?;
        Ok(())
    });
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::Write {
            path: path.to_path_buf(),
            why: format!("{} (nothing of it was kept)", io_why(&e)),
        });
    }
    let published = if replace {
        std::fs::rename(&tmp, path)
    } else {
        rename_new(&tmp, path)
    };
    if let Err(e) = published {
        let _ = std::fs::remove_file(&tmp);
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            return Err(Error::Exists(path.to_path_buf()));
        }
        return Err(Error::Move {
            from: tmp,
            to: path.to_path_buf(),
            why: io_why(&e),
        });
    }
    Ok(())
}

/// Renames `from` to `to` (a file or a folder) unless `to` exists: one atomic step
/// (`renameat2(RENAME_NOREPLACE)`), or, where the file system does not support it, a hard link
/// then the removal of `from` (files only).
pub fn rename_new(from: &Path, to: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_bytes()).map_err(std::io::Error::other);
    let (f, t) = (c(from)?, c(to)?);
    // SAFETY: two NUL-terminated paths that live across the call.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            f.as_ptr(),
            libc::AT_FDCWD,
            t.as_ptr(),
            libc::RENAME_NOREPLACE,
        )
    };
    if r == 0 {
        return Ok(());
    }
    let e = std::io::Error::last_os_error();
    if e.raw_os_error() != Some(libc::EINVAL) || from.is_dir() {
        return Err(e);
    }
    std::fs::hard_link(from, to)?;
    std::fs::remove_file(from)
}
