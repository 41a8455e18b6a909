//! Reading a file word by word (ASCII) or value by value (binary, little-endian), with every
//! error located by its line or byte offset.

use super::MshError;

pub(super) fn clip(s: &str) -> String {
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}

pub(super) struct Parser<'a> {
    pub(super) b: &'a [u8],
    pub(super) pos: usize,
    /// Start of the token or value read last: where an error is located.
    pub(super) at: usize,
    pub(super) binary: bool,
}

impl<'a> Parser<'a> {
    pub(super) fn err(&self, problem: String) -> MshError {
        self.err_at(self.at, problem)
    }

    pub(super) fn err_at(&self, at: usize, problem: String) -> MshError {
        let at = at.min(self.b.len());
        let location = if self.binary {
            format!("byte offset {at}")
        } else {
            format!("line {}", 1 + self.b[..at].iter().filter(|&&c| c == b'\n').count())
        };
        MshError { problem, location }
    }

    pub(super) fn eof(&mut self, what: &str) -> MshError {
        self.at = self.b.len();
        self.err(format!("unexpected end of file: {what} expected"))
    }

    pub(super) fn skip_ws(&mut self) {
        while self.pos < self.b.len() && self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    /// The next whitespace-delimited word (ASCII text).
    pub(super) fn token(&mut self, what: &str) -> Result<&'a str, MshError> {
        self.skip_ws();
        if self.pos >= self.b.len() {
            return Err(self.eof(what));
        }
        self.at = self.pos;
        let start = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        // Gmsh ends every line with a newline: a word cut by the end of the file is a truncated
        // file (but a final `$End…` without its newline is accepted).
        if self.pos == self.b.len() && !self.b[start..].starts_with(b"$End") {
            return Err(self.eof(what));
        }
        std::str::from_utf8(&self.b[start..self.pos])
            .map_err(|_| self.err(format!("{what} expected, found bytes that are not text")))
    }

    /// Consumes the rest of the current line, its newline included (binary data starts after it).
    pub(super) fn end_of_line(&mut self) -> &'a str {
        let start = self.pos;
        while self.pos < self.b.len() && self.b[self.pos] != b'\n' {
            self.pos += 1;
        }
        let line = &self.b[start..self.pos];
        if self.pos < self.b.len() {
            self.pos += 1;
        }
        std::str::from_utf8(line).unwrap_or("")
    }

    pub(super) fn parse_tok<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, MshError> {
        let tok = self.token(what)?;
        tok.parse()
            .map_err(|_| self.err(format!("bad number '{}' ({what} expected)", clip(tok))))
    }

    pub(super) fn raw<const N: usize>(&mut self, what: &str) -> Result<[u8; N], MshError> {
        self.at = self.pos;
        match self.b.get(self.pos..self.pos + N) {
            Some(s) => {
                self.pos += N;
                Ok(s.try_into().expect("get(pos..pos + N) is N bytes long"))
            }
            None => Err(self.eof(what)),
        }
    }

    /// An `int` of the format: a 4-byte integer in binary files, a word in ASCII ones.
    pub(super) fn int(&mut self, what: &str) -> Result<i32, MshError> {
        if self.binary {
            Ok(i32::from_le_bytes(self.raw(what)?))
        } else {
            self.parse_tok(what)
        }
    }

    /// A `size_t` of the format: an 8-byte unsigned integer in binary files, a word in ASCII ones.
    pub(super) fn size(&mut self, what: &str) -> Result<u64, MshError> {
        if self.binary {
            Ok(u64::from_le_bytes(self.raw(what)?))
        } else {
            self.parse_tok(what)
        }
    }

    pub(super) fn double(&mut self, what: &str) -> Result<f64, MshError> {
        if self.binary {
            Ok(f64::from_le_bytes(self.raw(what)?))
        } else {
            self.parse_tok(what)
        }
    }

    /// A count read from the file, as a `usize`.
    pub(super) fn count(&self, value: u64, what: &str) -> Result<usize, MshError> {
        usize::try_from(value).map_err(|_| self.err(format!("{what} {value}: too large")))
    }

    /// How many of `n` items to reserve room for: no more than the rest of the file can hold (at
    /// least `binary_bytes` per item in binary files, `words` words of two bytes in ASCII ones),
    /// so that a corrupt count cannot ask for a huge allocation.
    pub(super) fn capacity(&self, n: usize, binary_bytes: usize, words: usize) -> usize {
        let min = if self.binary { binary_bytes } else { 2 * words };
        n.min((self.b.len() - self.pos) / min.max(1))
    }

    /// A tag of an entity, element type or flag: an `int` that must be within `lo..=hi`.
    pub(super) fn int_in(&mut self, lo: i32, hi: i32, what: &str) -> Result<i32, MshError> {
        let v = self.int(what)?;
        if v < lo || v > hi {
            return Err(self.err(format!("{what} {v}: expected {lo} to {hi}")));
        }
        Ok(v)
    }

    pub(super) fn skip_ws_in_line(&mut self) {
        while self.pos < self.b.len() && matches!(self.b[self.pos], b' ' | b'\t') {
            self.pos += 1;
        }
    }
}
