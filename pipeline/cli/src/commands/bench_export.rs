//! `motionforge bench --export`: `export humanml3d` of a built dataset timed (wall and CPU)
//! beside a NumPy reference of HumanML3D's `process_file` run over the same joint sequences in
//! the same command (issue 34), and the Python references' common plumbing (finding the
//! interpreter, running an embedded script).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use super::bench_machine::load_average;
use crate::ui::Ui;
use anyhow::{Context, Result, bail};

/// `scripts/humanml3d_reference.py`, carried in the binary so the bench runs from anywhere.
const HUMANML3D_REFERENCE: &str = include_str!("../../../../scripts/humanml3d_reference.py");

/// What `bench --export` is asked to do.
pub(crate) struct ExportBench {
    /// The built dataset folder (`<output>/<name>`).
    pub(crate) dataset: PathBuf,
    /// Passes of the export and of the reference; the best of each is reported.
    pub(crate) repeat: usize,
    /// The Python with NumPy; default `MOTIONFORGE_PYTHON`.
    pub(crate) python: Option<PathBuf>,
}

/// The Python that runs a reference: `--python`, else `MOTIONFORGE_PYTHON` (what the tests use,
/// set from `scripts/python-env.sh`).
pub(super) fn reference_python(explicit: Option<&Path>) -> Result<PathBuf> {
    if let Some(path) = explicit {
        return Ok(path.to_path_buf());
    }
    match std::env::var_os("MOTIONFORGE_PYTHON") {
        Some(path) if !path.is_empty() => Ok(PathBuf::from(path)),
        _ => bail!(
            "no Python for the reference: pass --python, or set MOTIONFORGE_PYTHON=$(scripts/python-env.sh) \
             (a virtual environment with requirements-test.txt)"
        ),
    }
}

/// A temporary folder removed when dropped.
pub(super) struct Scratch {
    pub(super) path: PathBuf,
}

impl Scratch {
    pub(super) fn new(what: &str) -> Result<Scratch> {
        let path =
            std::env::temp_dir().join(format!("motionforge-bench-{what}-{}", std::process::id()));
        if path.exists() {
            std::fs::remove_dir_all(&path)
                .with_context(|| format!("cannot remove {}", path.display()))?;
        }
        std::fs::create_dir_all(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        Ok(Scratch { path })
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Writes `script` into `dir` as `name` and runs it with `python` and `args` on one thread
/// (BLAS and OpenMP pools of one), returning its standard output.
pub(super) fn run_python_script(
    python: &Path,
    dir: &Path,
    name: &str,
    script: &str,
    args: &[&std::ffi::OsStr],
) -> Result<String> {
    let path = dir.join(name);
    std::fs::write(&path, script).with_context(|| format!("cannot write {}", path.display()))?;
    let out = Command::new(python)
        .arg(&path)
        .args(args)
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1")
        .output()
        .with_context(|| format!("cannot run {}", python.display()))?;
    if !out.status.success() {
        bail!(
            "{name} under {} failed ({}): {}",
            python.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    String::from_utf8(out.stdout).with_context(|| format!("{name} printed non-UTF-8"))
}

/// User and system CPU seconds of this process, all threads.
pub(super) fn process_cpu_seconds() -> f64 {
    rusage_cpu_seconds(libc::RUSAGE_SELF)
}

/// User CPU seconds of this process's finished children.
fn children_user_seconds() -> f64 {
    rusage_seconds(libc::RUSAGE_CHILDREN).0
}

/// User and system CPU seconds of this process's finished children.
fn children_cpu_seconds() -> f64 {
    let (user, system) = rusage_seconds(libc::RUSAGE_CHILDREN);
    user + system
}

fn rusage_cpu_seconds(who: libc::c_int) -> f64 {
    let (user, system) = rusage_seconds(who);
    user + system
}

/// User and system CPU seconds from `getrusage(who)`.
fn rusage_seconds(who: libc::c_int) -> (f64, f64) {
    // SAFETY: an all-zero rusage is a valid value of this plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes one rusage, which lives on this stack frame.
    if unsafe { libc::getrusage(who, &mut usage) } != 0 {
        return (0.0, 0.0);
    }
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    (seconds(usage.ru_utime), seconds(usage.ru_stime))
}

/// The counts an export wrote in its `export.json`.
struct ExportCounts {
    rows: usize,
    exported: usize,
}

impl ExportCounts {
    fn read(out: &Path) -> Result<ExportCounts> {
        let path = out.join("export.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let value: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{} is not JSON", path.display()))?;
        let count = |key: &str| -> Result<usize> {
            value[key]
                .as_u64()
                .and_then(|n| usize::try_from(n).ok())
                .with_context(|| format!("{}: no count `{key}`", path.display()))
        };
        Ok(ExportCounts {
            rows: count("rows")?,
            exported: count("exported")?,
        })
    }
}

/// What the reference script printed.
#[derive(Debug)]
struct Reference {
    clips: usize,
    frames: usize,
    rows: usize,
    wall_s: f64,
    cpu_s: f64,
    numpy: String,
    max_abs_diff: f64,
    rows_compared: usize,
    shape_mismatches: usize,
}

impl Reference {
    /// The reference's one JSON line.
    fn parse(printed: &str) -> Result<Reference> {
        let value: serde_json::Value = serde_json::from_str(printed.trim())
            .with_context(|| format!("the reference printed {printed:?}"))?;
        let number = |key: &str| {
            value[key]
                .as_f64()
                .with_context(|| format!("no number `{key}` in the reference's {value}"))
        };
        let count = |key: &str| number(key).map(|n| n as usize);
        Ok(Reference {
            clips: count("clips")?,
            frames: count("frames")?,
            rows: count("rows")?,
            wall_s: number("wall_s")?,
            cpu_s: number("cpu_s")?,
            numpy: value["numpy"].as_str().unwrap_or("?").to_string(),
            max_abs_diff: number("max_abs_diff")?,
            rows_compared: count("rows_compared")?,
            shape_mismatches: count("shape_mismatches")?,
        })
    }
}

/// The export's own computation of the rows, without reading shards or writing files:
/// `humanml3d::vectors` over the same joint arrays as the reference, on this thread.
struct VectorsAlone {
    rows: usize,
    wall_s: f64,
    cpu_s: f64,
}

/// Times `humanml3d::vectors` on every `joints/*.npy` of the export in `out` (read first, not
/// timed), best of `repeat` passes on this thread.
fn vectors_alone(out: &Path, repeat: usize) -> Result<VectorsAlone> {
    let dir = out.join("joints");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    files.sort();
    let motions = files
        .iter()
        .map(|f| joints_npy(f))
        .collect::<Result<Vec<_>>>()?;
    let mut alone = VectorsAlone {
        rows: 0,
        wall_s: f64::INFINITY,
        cpu_s: f64::INFINITY,
    };
    for _ in 0..repeat.max(1) {
        alone.rows = 0;
        let cpu0 = super::bench_machine::thread_cpu_seconds();
        let t0 = Instant::now();
        for (file, motion) in files.iter().zip(&motions) {
            let rows = motionforge::humanml3d::vectors(motion)
                .with_context(|| format!("{}", file.display()))?;
            alone.rows += rows.len() / motionforge::humanml3d::DIM;
            std::hint::black_box(rows);
        }
        alone.wall_s = alone.wall_s.min(t0.elapsed().as_secs_f64());
        alone.cpu_s = alone
            .cpu_s
            .min(super::bench_machine::thread_cpu_seconds() - cpu0);
    }
    Ok(alone)
}

/// Writing the export's files alone: every file of the export in `out` written again, same
/// relative path and size, into a fresh folder beside it, on the export's thread pool, as the
/// export writes them (one `fs::write` each); best of `repeat` passes. The bytes are zeros: the
/// kernel's work for a file does not depend on what it holds, and the export's 1.2 GB need not
/// be held in memory.
struct FilesAlone {
    files: usize,
    bytes: u64,
    wall_s: f64,
    cpu_s: f64,
}

fn files_alone(out: &Path, repeat: usize) -> Result<FilesAlone> {
    use rayon::prelude::*;
    let mut files: Vec<(PathBuf, u64)> = Vec::new();
    let mut dirs: Vec<PathBuf> = vec![PathBuf::new()];
    let mut pending = vec![PathBuf::new()];
    while let Some(rel) = pending.pop() {
        let dir = out.join(&rel);
        for entry in
            std::fs::read_dir(&dir).with_context(|| format!("cannot list {}", dir.display()))?
        {
            let entry = entry.with_context(|| format!("cannot list {}", dir.display()))?;
            let meta = entry.metadata()?;
            let child = rel.join(entry.file_name());
            if meta.is_dir() {
                dirs.push(child.clone());
                pending.push(child);
            } else {
                files.push((child, meta.len()));
            }
        }
    }
    files.sort();
    let largest = files.iter().map(|(_, n)| *n).max().unwrap_or(0);
    let zeros = vec![0u8; usize::try_from(largest)?];
    let mut alone = FilesAlone {
        files: files.len(),
        bytes: files.iter().map(|(_, n)| n).sum(),
        wall_s: f64::INFINITY,
        cpu_s: f64::INFINITY,
    };
    // A folder a pass, as for the export's passes.
    let copies: Vec<PathBuf> = (0..repeat.max(1))
        .map(|pass| out.with_extension(format!("files-alone-{pass}")))
        .collect();
    for copy in &copies {
        let cpu0 = process_cpu_seconds();
        let t0 = Instant::now();
        for dir in &dirs {
            std::fs::create_dir_all(copy.join(dir))?;
        }
        files.par_iter().try_for_each(|(rel, size)| {
            let path = copy.join(rel);
            let size = usize::try_from(*size)
                .unwrap_or(zeros.len())
                .min(zeros.len());
            std::fs::write(&path, &zeros[..size])
                .with_context(|| format!("cannot write {}", path.display()))
        })?;
        alone.wall_s = alone.wall_s.min(t0.elapsed().as_secs_f64());
        alone.cpu_s = alone.cpu_s.min(process_cpu_seconds() - cpu0);
    }
    for copy in &copies {
        std::fs::remove_dir_all(copy)?;
    }
    Ok(alone)
}

/// The positions of a `(T, 22, 3)` little-endian float32 `.npy` file as the export writes it
/// (format 1.0, C order).
fn joints_npy(path: &Path) -> Result<Vec<glam::DVec3>> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let bad = |what: &str| anyhow::anyhow!("{}: {what}", path.display());
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" || bytes[6] != 1 {
        return Err(bad("not a version 1 .npy file"));
    }
    let header_len = usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
    let header = bytes
        .get(10..10 + header_len)
        .ok_or_else(|| bad("header runs past the end"))?;
    let header = String::from_utf8_lossy(header);
    if !header.contains("'<f4'") || !header.contains("'fortran_order': False") {
        return Err(bad("not C-order little-endian float32"));
    }
    let data = &bytes[10 + header_len..];
    if data.len() % (4 * 3 * motionforge::humanml3d::NUM_JOINTS) != 0 {
        return Err(bad("not a whole number of 22-joint frames"));
    }
    Ok(data
        .chunks_exact(12)
        .map(|p| {
            let f = |i: usize| f64::from(f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]));
            glam::DVec3::new(f(0), f(4), f(8))
        })
        .collect())
}

/// Runs the benchmark and prints its figures (or JSON with `--json`).
pub(crate) fn bench_export(args: &ExportBench, ui: &Ui) -> Result<()> {
    let repeat = args.repeat.max(1);
    let python = reference_python(args.python.as_deref())?;
    let scratch = Scratch::new("export")?;
    let threads = rayon::current_num_threads();
    let start_load = load_average();
    let (mut wall, mut cpu, mut user) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut summary = None;
    // Each pass is the command a user runs, in a process of its own: a pass in this process
    // would find the captions the one before tagged still remembered.
    // Each pass writes a folder of its own, the earlier ones removed only after the last: ext4
    // skips inodes freed moments before when it allocates, so creating 34,000 files right after
    // removing 34,000 cost the kernel up to 18 s of a pass here, a cost of the benchmark's
    // churn, not of an export.
    let exe = std::env::current_exe().context("cannot find this program to run the export")?;
    let mut passes = Vec::new();
    for pass in 0..repeat {
        let out = scratch.path.join(format!("humanml3d-{pass}"));
        let (cpu0, user0) = (children_cpu_seconds(), children_user_seconds());
        let t0 = Instant::now();
        let run = std::process::Command::new(&exe)
            .args(["export", "humanml3d"])
            .arg(&args.dataset)
            .arg("--output")
            .arg(&out)
            .arg("--quiet")
            .stdout(std::process::Stdio::null())
            .output()
            .with_context(|| format!("cannot run {}", exe.display()))?;
        wall = wall.min(t0.elapsed().as_secs_f64());
        cpu = cpu.min(children_cpu_seconds() - cpu0);
        user = user.min(children_user_seconds() - user0);
        if !run.status.success() {
            bail!(
                "`export humanml3d {}` failed: {}",
                args.dataset.display(),
                String::from_utf8_lossy(&run.stderr).trim()
            );
        }
        summary = Some(ExportCounts::read(&out)?);
        passes.push(out);
    }
    let Some(out) = passes.pop() else {
        bail!("no export ran");
    };
    for earlier in passes {
        std::fs::remove_dir_all(&earlier)
            .with_context(|| format!("cannot remove {}", earlier.display()))?;
    }
    let Some(summary) = summary else {
        bail!("no export ran");
    };
    if summary.rows == 0 {
        bail!(
            "the export of {} wrote no rows: nothing to compare",
            args.dataset.display()
        );
    }
    let alone = vectors_alone(&out, repeat)?;
    let files = files_alone(&out, repeat)?;
    let repeat_arg = repeat.to_string();
    let printed = run_python_script(
        &python,
        &scratch.path,
        "humanml3d_reference.py",
        HUMANML3D_REFERENCE,
        &[out.as_os_str(), "--repeat".as_ref(), repeat_arg.as_ref()],
    )?;
    let reference = Reference::parse(&printed)?;
    let end_load = load_average();
    let figures = Figures {
        rows: summary.rows,
        clips: summary.exported,
        threads,
        repeat,
        wall,
        cpu,
        user,
        reference,
        alone,
        files,
        load: (start_load, end_load),
    };
    if ui.json() {
        writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&figures.json())?
        )?;
    } else {
        figures.print()?;
    }
    Ok(())
}

/// The export's best pass and the reference's.
struct Figures {
    rows: usize,
    clips: usize,
    threads: usize,
    repeat: usize,
    wall: f64,
    cpu: f64,
    /// The user part of `cpu` (the rest is the kernel's, mostly creating and writing files).
    user: f64,
    reference: Reference,
    alone: VectorsAlone,
    files: FilesAlone,
    load: (Option<String>, Option<String>),
}

impl Figures {
    fn rows_per(&self, seconds: f64) -> f64 {
        self.rows as f64 / seconds.max(1e-9)
    }

    fn reference_rows_per(&self, seconds: f64) -> f64 {
        self.reference.rows as f64 / seconds.max(1e-9)
    }

    /// The export's rows per CPU second over the reference's.
    fn cpu_ratio(&self) -> f64 {
        self.rows_per(self.cpu) / self.reference_rows_per(self.reference.cpu_s)
    }

    /// The export's rows per wall second over the reference's.
    fn wall_ratio(&self) -> f64 {
        self.rows_per(self.wall) / self.reference_rows_per(self.reference.wall_s)
    }

    /// The export's CPU seconds without those of writing its files alone, over the reference's.
    fn cpu_ratio_without_files(&self) -> f64 {
        let rest = (self.cpu - self.files.cpu_s).max(1e-9);
        self.rows_per(rest) / self.reference_rows_per(self.reference.cpu_s)
    }

    fn print(&self) -> std::io::Result<()> {
        let r = &self.reference;
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "export humanml3d: {} clips, {} rows of 263 ({} threads); reference: NumPy {} port of process_file, one thread, {} clips, {} frames, {} rows; best of {}",
            self.clips, self.rows, self.threads, r.numpy, r.clips, r.frames, r.rows, self.repeat
        )?;
        writeln!(
            out,
            "export:    {:.3} s wall, {:.3} s CPU ({:.3} s user, {:.3} s system); {:.0} rows/s wall, {:.0} rows per CPU second",
            self.wall,
            self.cpu,
            self.user,
            self.cpu - self.user,
            self.rows_per(self.wall),
            self.rows_per(self.cpu)
        )?;
        writeln!(
            out,
            "reference: {:.3} s wall, {:.3} s CPU; {:.0} rows/s wall, {:.0} rows per CPU second",
            r.wall_s,
            r.cpu_s,
            self.reference_rows_per(r.wall_s),
            self.reference_rows_per(r.cpu_s)
        )?;
        writeln!(
            out,
            "per CPU second: {:.2}x the reference (target 10x); per user CPU second: {:.2}x",
            self.cpu_ratio(),
            self.rows_per(self.user) / self.reference_rows_per(self.reference.cpu_s)
        )?;
        writeln!(
            out,
            "per wall second: {:.2}x the reference (target 15x on 2 cores)",
            self.wall_ratio()
        )?;
        let alone = &self.alone;
        let alone_rate = alone.rows as f64 / alone.cpu_s.max(1e-9);
        writeln!(
            out,
            "vectors alone: {:.3} s CPU, {:.0} rows per CPU second on one thread, {:.2}x the reference (humanml3d::vectors over the same joints, no shard reading or file writing)",
            alone.cpu_s,
            alone_rate,
            alone_rate / self.reference_rows_per(r.cpu_s)
        )?;
        let files = &self.files;
        writeln!(
            out,
            "files alone: {} files, {:.1} MB written as the export writes them (same paths and sizes, {} threads): {:.3} s wall, {:.3} s CPU",
            files.files,
            files.bytes as f64 / 1e6,
            self.threads,
            files.wall_s,
            files.cpu_s
        )?;
        writeln!(
            out,
            "export without writing its files: {:.3} s CPU, {:.2}x the reference per CPU second",
            self.cpu - files.cpu_s,
            self.cpu_ratio_without_files()
        )?;
        writeln!(
            out,
            "agreement: max |export - reference| {:.2e} over {} rows; {} clips of another shape",
            r.max_abs_diff, r.rows_compared, r.shape_mismatches
        )?;
        let (a, b) = &self.load;
        writeln!(
            out,
            "load average: {} at start, {} at end",
            a.as_deref().unwrap_or("?"),
            b.as_deref().unwrap_or("?")
        )
    }

    fn json(&self) -> serde_json::Value {
        let r = &self.reference;
        serde_json::json!({
            "clips": self.clips,
            "rows": self.rows,
            "threads": self.threads,
            "repeat": self.repeat,
            "export": {
                "wall_s": self.wall,
                "cpu_s": self.cpu,
                "user_cpu_s": self.user,
                "rows_per_wall_second": self.rows_per(self.wall),
                "rows_per_cpu_second": self.rows_per(self.cpu),
            },
            "reference": {
                "numpy": r.numpy,
                "clips": r.clips,
                "frames": r.frames,
                "rows": r.rows,
                "wall_s": r.wall_s,
                "cpu_s": r.cpu_s,
                "rows_per_wall_second": self.reference_rows_per(r.wall_s),
                "rows_per_cpu_second": self.reference_rows_per(r.cpu_s),
            },
            "vectors_alone": {
                "rows": self.alone.rows,
                "wall_s": self.alone.wall_s,
                "cpu_s": self.alone.cpu_s,
                "rows_per_cpu_second": self.alone.rows as f64 / self.alone.cpu_s.max(1e-9),
            },
            "files_alone": {
                "files": self.files.files,
                "bytes": self.files.bytes,
                "wall_s": self.files.wall_s,
                "cpu_s": self.files.cpu_s,
            },
            "ratio_per_cpu_second_without_files": self.cpu_ratio_without_files(),
            "ratio_per_cpu_second": self.cpu_ratio(),
            "ratio_per_wall_second": self.wall_ratio(),
            "agreement": {
                "max_abs_diff": r.max_abs_diff,
                "rows_compared": r.rows_compared,
                "shape_mismatches": r.shape_mismatches,
            },
            "load_average": { "start": self.load.0, "end": self.load.1 },
        })
    }
}
