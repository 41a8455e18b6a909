//! `glissade submit`: a run as a Slurm batch job (docs/operations.md, "On a cluster").

use super::*;
use std::io::Write as _;
use std::path::Path;

/// A path as one word of a bash command line (single-quoted).
fn quoted(p: &Path) -> String {
    format!("'{}'", p.display().to_string().replace('\'', r"'\''"))
}

/// The lines of the batch script that runs `scene` (absolute) with its outputs in `out`
/// (absolute) as run `run_id`: the `#SBATCH` lines (job name, nodes, one task per node, the
/// console file, time and partition where given) and the `glissade run --slurm` line.
fn batch_script(args: &SubmitArgs, exe: &Path, (scene, out): (&Path, &Path), run_id: &str, name: &str) -> Vec<String> {
    let stem = format!("{name}-{run_id}");
    let mut lines = vec![
        "#!/bin/bash".to_string(),
        format!("#SBATCH --job-name=glissade-{}", name),
        format!("#SBATCH --nodes={}", args.nodes),
        "#SBATCH --ntasks-per-node=1".to_string(),
        format!(
            "#SBATCH --output={}",
            out.join(format!("{stem}.slurm-%j.out")).display()
        ),
    ];
    if let Some(t) = &args.time {
        lines.push(format!("#SBATCH --time={t}"));
    }
    if let Some(p) = &args.partition {
        lines.push(format!("#SBATCH --partition={p}"));
    }
    lines.push(
        "# The launcher runs here; its node processes are job steps of this job (`srun`), spread over its hosts."
            .to_string(),
    );
    lines.push("# scancel sends SIGTERM: the run ends Interrupted with its recording and summary written.".to_string());
    let mut run = format!(
        "exec {} run {} --slurm --quiet --out {} --run-id {run_id}",
        quoted(exe),
        quoted(scene),
        quoted(out)
    );
    if let Some(a) = args.solver.accuracy {
        run += &format!(" --accuracy {a:e}");
    }
    if let Some(n) = args.solver.max_iterations {
        run += &format!(" --max-iterations {n}");
    }
    if args.no_record {
        run += " --no-record";
    }
    lines.push(run);
    lines
}

/// Submits `script` with `sbatch --parsable`; its job id.
fn sbatch(script_path: &Path) -> anyhow::Result<String> {
    let sbatch = std::process::Command::new("sbatch")
        .arg("--parsable")
        .arg(script_path)
        .output()
        .with_context(|| {
            format!(
                "cannot run sbatch (is this a Slurm cluster's login node?); the batch script is {}",
                script_path.display()
            )
        })?;
    anyhow::ensure!(
        sbatch.status.success(),
        "sbatch refused {}: {}",
        script_path.display(),
        String::from_utf8_lossy(&sbatch.stderr).trim()
    );
    let said = String::from_utf8_lossy(&sbatch.stdout);
    let job = said.trim().split(';').next().unwrap_or("").to_string();
    anyhow::ensure!(
        !job.is_empty() && job.chars().all(|c| c.is_ascii_digit()),
        "sbatch said `{}` instead of a job id",
        said.trim()
    );
    Ok(job)
}

/// Writes the batch script of a `glissade run <scene> --slurm` beside the run's outputs, submits
/// it with `sbatch` and says the job id and where its outputs will be. Nothing is written if the
/// scene is refused or the run id already has outputs there.
pub(crate) fn submit(args: &SubmitArgs) -> anyhow::Result<ExitCode> {
    // The scene and the solver overrides, checked as `glissade run` will check them in the job.
    let overrides = Overrides {
        accuracy: args.solver.accuracy,
        max_iterations: args.solver.max_iterations,
        ..Default::default()
    };
    let sc = load_scene(&args.scene)?.with_overrides(&args.scene.display().to_string(), &overrides)?;
    let run_id = run_id_of(args.run_id.as_deref())?;
    // What goes into `#SBATCH` lines: one word each, nothing a line break or a space could split,
    // and no `%` in the output path (Slurm expands it as a file-name pattern).
    let plain = |what: &str, v: &str| -> anyhow::Result<()> {
        anyhow::ensure!(
            !v.is_empty() && v.chars().all(|c| c.is_ascii_alphanumeric() || "-_:.,+".contains(c)),
            "{what} `{v}`: only letters, digits and - _ : . , + are taken into the batch script"
        );
        Ok(())
    };
    if let Some(t) = &args.time {
        plain("--time", t)?;
    }
    if let Some(p) = &args.partition {
        plain("--partition", p)?;
    }
    let absolute = |p: &Path| std::path::absolute(p).with_context(|| format!("cannot resolve {}", p.display()));
    let (out, scene) = (absolute(&args.out)?, absolute(&args.scene)?);
    let shown = out.display().to_string();
    anyhow::ensure!(
        !shown.chars().any(|c| c.is_whitespace() || c.is_control() || c == '%'),
        "--out {shown}: the job's console is written there through `#SBATCH --output`, which takes no \
         space, control character or `%` in its path; choose another --out"
    );
    ensure_writable(&args.out)?;
    ensure_new_run(&args.out, &sc.model.name, &run_id)?;
    let exe = std::env::current_exe().context("cannot locate the glissade executable for the batch script")?;
    let stem = format!("{}-{run_id}", sc.model.name);
    let script_path = out.join(format!("{stem}.sbatch"));
    let lines = batch_script(args, &exe, (&scene, &out), &run_id, &sc.model.name);
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&script_path)
        .with_context(|| format!("cannot write the batch script {}", script_path.display()))?;
    file.write_all((lines.join("\n") + "\n").as_bytes())
        .with_context(|| format!("cannot write the batch script {}", script_path.display()))?;
    drop(file);
    let job = sbatch(&script_path)?;
    println!("submitted Slurm job {job}: run {run_id} of scene `{}`", sc.model.name);
    println!("batch script: {}", script_path.display());
    println!("outputs: {}/{stem}.*", out.display());
    println!("console: {}", out.join(format!("{stem}.slurm-{job}.out")).display());
    println!("cancel with `scancel {job}`: the run ends Interrupted, its recording and summary written");
    Ok(ExitCode::SUCCESS)
}
