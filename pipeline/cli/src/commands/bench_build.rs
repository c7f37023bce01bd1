//! `motionforge bench --build`: a whole build timed stage by stage, beside a bare single-thread
//! scan of the same bytes into f64 (issue 12's measuring instrument). The timing and reporting
//! live here, on the binary side; the library only reports its stages through `ProgressSink`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use motionforge::build::{BuildOptions, BuildReport, DATA_DIR, plan};

use super::bench::{bvh_files, peak_rss_kb};
use super::bench_clock::{BuildRun, Phase, Timed, timed_build};
use super::bench_floor::{
    BvhioReference, EncodeReference, Scan, bvhio_reference, encode_reference, scan,
};
use super::bench_machine::{
    CpuSnapshot, folder_sizes, load_average, reset_peak_rss, rss_kb, shard_sizes,
};
use super::load_checked;
use crate::ui::Ui;

/// What `bench --build` is asked to do.
pub(crate) struct BuildBench {
    /// Folder of the BVH captures (with their `.json` sidecars).
    pub(crate) data: PathBuf,
    /// Skeleton profile of the captures.
    pub(crate) profile: String,
    /// Repeats of the full build, the no-op rebuild, the plan and the scan.
    pub(crate) repeat: usize,
    /// The folder listed under this many source names.
    pub(crate) copies: usize,
    /// Keep the config and the dataset here instead of a temporary folder.
    pub(crate) keep: Option<PathBuf>,
    /// File-name pattern; default `<prefix>_{content}_{style}_{take}` from the first file name.
    pub(crate) pattern: Option<String>,
    /// Threads of the rayon pool the builds and the plan run on; default rayon's own
    /// (`RAYON_NUM_THREADS`, else one per CPU).
    pub(crate) threads: Option<usize>,
    /// Also time bvhio reading the folder and computing world positions: `Some` with the
    /// `--python` given, if any.
    pub(crate) bvhio: Option<Option<PathBuf>>,
}

/// The first line of the config the bench writes: marks a `--keep` folder as the bench's own.
pub(super) const CONFIG_MARKER: &str = "# written by `motionforge bench --build`";
const CONFIG_FILE: &str = "bench.toml";
pub(super) const OUTPUT_DIR: &str = "out";

/// Runs the benchmark and prints its table (or JSON with `--json`).
pub(crate) fn bench_build(args: &BuildBench, ui: &Ui) -> Result<()> {
    let copies = args.copies.max(1);
    let repeat = args.repeat.max(1);
    if args.bvhio.is_some() && copies > 1 {
        bail!("--bvhio reads the folder once: it cannot be combined with --copies");
    }
    let input = Input::list(&args.data)?;
    let pattern = match &args.pattern {
        Some(p) => p.clone(),
        None => input.default_pattern()?,
    };
    // Everything the build runs in parallel runs on rayon: a pool of N threads is the build on N
    // cores (the scan and the encode reference are single-threaded by design).
    let bench = BenchWork::new(args.keep.as_deref(), args.threads, "bench-build", |work| {
        Ok(config_text(
            &input.dir,
            &args.profile,
            &pattern,
            copies,
            work,
        ))
    })?;
    let (config, dataset, pool) = (&bench.config, &bench.dataset, &bench.pool);
    let work = &bench.work.path;
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let start_load = load_average();

    // The full builds come first, so the process peak read after them is theirs: nothing before
    // has held more than one capture file.
    let mut full = Vec::new();
    let mut report = None;
    for _ in 0..repeat {
        let (run, r) = bench.fresh_build(ui)?;
        if r.clips == 0 {
            bail!(
                "the build wrote 0 clips from {} captures ({} rejected: {}); does `--pattern {pattern}` match the file names?",
                r.captures,
                r.rejects.len(),
                crate::summary::counts(&r.rejects_by_reason)
            );
        }
        if r.stages.iter().any(|s| s.reused > 0) {
            bail!("the build from scratch reused cached work: {:?}", r.stages);
        }
        full.push(run);
        report = Some(r);
    }
    let Some(report) = report else {
        bail!("no build ran");
    };
    let cache = folder_sizes(&dataset.join(".motionforge").join("cache"))?;
    let shards = shard_sizes(&dataset.join(DATA_DIR))?;

    let (noop, noop_ran) = noop_builds(pool, config, repeat, ui)?;
    let (plans, plan_stale) = timed_plans(pool, config, repeat)?;

    let scan = scan(&input, copies, repeat)?;
    let encode = encode_reference(&dataset.join(DATA_DIR), config.dataset.zstd_level, repeat)?;
    let bvhio = match &args.bvhio {
        Some(python) => Some(bvhio_reference(&input.dir, python.as_deref(), work)?),
        None => None,
    };
    let end_load = load_average();

    let result = Results {
        args,
        input: &input,
        copies,
        repeat,
        threads: bench.threads,
        cpus,
        pattern: &pattern,
        report: &report,
        full,
        noop,
        noop_ran,
        plans,
        plan_stale,
        scan,
        encode,
        bvhio,
        cache,
        shards,
        load: (start_load, end_load),
        kept: args.keep.as_ref().map(|_| dataset.clone()),
    };
    if ui.log.json {
        crate::ui::print_json(&result.json())?;
    } else {
        result.print()?;
    }
    Ok(())
}

/// The no-op rebuilds of a built dataset, `repeat` times, and the stages that ran in them
/// (none, unless a rebuild is not the no-op it should be).
fn noop_builds(
    pool: &rayon::ThreadPool,
    config: &motionforge::config::Config,
    repeat: usize,
    ui: &Ui,
) -> Result<(Vec<BuildRun>, Vec<String>)> {
    let mut noop = Vec::new();
    let mut noop_ran = Vec::new();
    for _ in 0..repeat {
        let (run, r) = pool.install(|| timed_build(config, ui))?;
        noop_ran.extend(
            r.stages
                .iter()
                .filter(|s| s.ran > 0)
                .map(|s| format!("{} ran {}", s.stage, s.ran)),
        );
        noop.push(run);
    }
    Ok((noop, noop_ran))
}

/// `plan` on the built dataset, `repeat` times, and whether any plan found work to do.
fn timed_plans(
    pool: &rayon::ThreadPool,
    config: &motionforge::config::Config,
    repeat: usize,
) -> Result<(Vec<Timed>, bool)> {
    let mut plans = Vec::new();
    let mut plan_stale = false;
    for _ in 0..repeat {
        reset_peak_rss();
        let start_rss_kb = rss_kb();
        let cpu = CpuSnapshot::now();
        let t0 = Instant::now();
        let p = pool.install(|| plan(config, &BuildOptions::default()))?;
        let seconds = t0.elapsed().as_secs_f64();
        plan_stale |= !p.nothing_to_run();
        plans.push(Timed {
            seconds,
            peak_rss_kb: peak_rss_kb(),
            start_rss_kb,
            cpu: cpu.since(),
        });
    }
    Ok((plans, plan_stale))
}

// ---- input -----------------------------------------------------------------------------------

/// The captures of the data folder: paths, bytes and frames (from each file's `Frames:` line).
pub(super) struct Input {
    pub(super) dir: PathBuf,
    pub(super) files: Vec<PathBuf>,
    pub(super) bytes: u64,
    pub(super) frames: u64,
}

impl Input {
    /// Lists `dir/*.bvh` and reads each file once, one at a time: the counts, and a warm page
    /// cache for the first build (which would otherwise also time the disk).
    fn list(dir: &Path) -> Result<Input> {
        // Canonical, so the config and the output name the folder without `..`.
        let dir =
            std::fs::canonicalize(dir).with_context(|| format!("cannot find {}", dir.display()))?;
        let files = bvh_files(&dir)?;
        let (mut bytes, mut frames) = (0u64, 0u64);
        for file in &files {
            let data =
                std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
            bytes += data.len() as u64;
            frames += frames_of(&data);
        }
        Ok(Input {
            dir,
            files,
            bytes,
            frames,
        })
    }

    /// `<prefix>_{content}_{style}_{take}`, the Bandai Namco form, with the prefix of the first
    /// file name (`dataset-2` for dataset 2).
    fn default_pattern(&self) -> Result<String> {
        let stem = self
            .files
            .first()
            .and_then(|f| f.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        match stem.split_once('_') {
            Some((prefix, _)) if !prefix.is_empty() => {
                Ok(format!("{prefix}_{{content}}_{{style}}_{{take}}"))
            }
            _ => bail!(
                "cannot guess a file-name pattern from `{stem}`; pass --pattern (e.g. \"dataset-2_{{content}}_{{style}}_{{take}}\")"
            ),
        }
    }
}

/// The frame count of a BVH file's `Frames:` line (0 when there is none: the build rejects it).
fn frames_of(data: &[u8]) -> u64 {
    data.split(|&b| b == b'\n')
        .find_map(|line| {
            let line = std::str::from_utf8(line).ok()?.trim();
            line.strip_prefix("Frames:")?.trim().parse().ok()
        })
        .unwrap_or(0)
}

/// The build config: the folder under `copies` source names (`bn2-1`..), file-name labels with
/// sidecars as in `fixtures/demo.toml`, and every other section at its default (mirror on,
/// synthetic pairs on, default features, 30 fps).
fn config_text(data: &Path, profile: &str, pattern: &str, copies: usize, work: &Path) -> String {
    // TOML strings quoted by the TOML writer, so any path survives.
    let quote = |s: &str| toml::Value::String(s.to_string()).to_string();
    let glob = format!(
        "{}/*.bvh",
        glob::Pattern::escape(&data.display().to_string())
    );
    let mut text = format!(
        "{CONFIG_MARKER}\n[dataset]\nname = \"bench\"\noutput = {}\nfps = 30\n\n[mirror]\nenabled = true\n",
        quote(&work.join(OUTPUT_DIR).display().to_string())
    );
    for k in 1..=copies {
        text.push_str(&format!(
            "\n[[sources]]\nname = \"bn2-{k}\"\ncaptures = [{}]\nprofile = {}\n\n[sources.labels]\nkind = \"filename\"\npattern = {}\naction = \"{{content}}\"\ntext = \"{{content}}, {{style}} style\"\nsidecar = true\n",
            quote(&glob),
            quote(profile),
            quote(pattern)
        ));
    }
    text
}

/// The folder the bench builds in: `--keep`'s, or a temporary one removed at the end.
pub(super) struct WorkDir {
    pub(super) path: PathBuf,
    remove: bool,
}

impl WorkDir {
    pub(super) fn new(keep: Option<&Path>) -> Result<WorkDir> {
        let (path, remove) = match keep {
            Some(dir) => (std::path::absolute(dir)?, false),
            None => (
                std::env::temp_dir()
                    .join(format!("motionforge-bench-build-{}", std::process::id())),
                true,
            ),
        };
        // A kept folder is emptied of the bench's dataset before each build: refuse one that holds
        // anything else.
        if let Ok(mut entries) = std::fs::read_dir(&path) {
            let ours = std::fs::read_to_string(path.join(CONFIG_FILE))
                .is_ok_and(|t| t.starts_with(CONFIG_MARKER));
            if !ours && entries.next().is_some() {
                bail!(
                    "{} is not empty and holds no earlier `bench --build` run; pass an empty or new folder to --keep",
                    path.display()
                );
            }
        }
        std::fs::create_dir_all(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        Ok(WorkDir { path, remove })
    }
}

/// A bench's builds set up: the work folder with the config written there and loaded, the
/// config's dataset folder, and the rayon pool of `threads` the builds run on.
pub(super) struct BenchWork {
    pub(super) work: WorkDir,
    pub(super) config: motionforge::config::Config,
    pub(super) dataset: PathBuf,
    pub(super) threads: usize,
    pub(super) pool: rayon::ThreadPool,
}

impl BenchWork {
    /// Writes the config `text` gives for the work folder (`keep`, or a temporary one), loads
    /// it, and starts a pool of `threads` (default rayon's own) named `<name>-<i>`.
    pub(super) fn new(
        keep: Option<&Path>,
        threads: Option<usize>,
        name: &'static str,
        text: impl FnOnce(&Path) -> Result<String>,
    ) -> Result<BenchWork> {
        let work = WorkDir::new(keep)?;
        let config_path = work.path.join(CONFIG_FILE);
        std::fs::write(&config_path, text(&work.path)?)
            .with_context(|| format!("cannot write {}", config_path.display()))?;
        let config = load_checked(&config_path, None)?;
        let dataset = config.dataset_dir();
        let threads = threads.unwrap_or_else(rayon::current_num_threads).max(1);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(move |i| format!("{name}-{i}"))
            .build()
            .context("cannot start the build's thread pool")?;
        Ok(BenchWork {
            work,
            config,
            dataset,
            threads,
            pool,
        })
    }

    /// A timed build from scratch on the pool: the dataset folder removed first.
    pub(super) fn fresh_build(&self, ui: &Ui) -> Result<(BuildRun, BuildReport)> {
        if self.dataset.exists() {
            std::fs::remove_dir_all(&self.dataset)
                .with_context(|| format!("cannot remove {}", self.dataset.display()))?;
        }
        self.pool.install(|| timed_build(&self.config, ui))
    }
}

impl Drop for WorkDir {
    fn drop(&mut self) {
        if self.remove {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

// ---- results ---------------------------------------------------------------------------------

struct Results<'a> {
    args: &'a BuildBench,
    input: &'a Input,
    copies: usize,
    repeat: usize,
    /// Threads of the pool the builds ran on.
    threads: usize,
    /// CPUs of the machine.
    cpus: usize,
    pattern: &'a str,
    report: &'a BuildReport,
    full: Vec<BuildRun>,
    noop: Vec<BuildRun>,
    noop_ran: Vec<String>,
    plans: Vec<Timed>,
    plan_stale: bool,
    scan: Scan,
    encode: EncodeReference,
    bvhio: Option<BvhioReference>,
    cache: BTreeMap<String, u64>,
    shards: Vec<u64>,
    load: (Option<String>, Option<String>),
    kept: Option<PathBuf>,
}

/// Smallest and largest of some timings.
fn min_max(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    values
        .into_iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

pub(super) fn rss_mb(kb: Option<u64>) -> String {
    kb.map_or_else(
        || "n/a".to_string(),
        |kb| format!("{:.0} MB", kb as f64 / 1024.0),
    )
}

/// Thousands separated by commas, as the docs write counts.
pub(super) fn grouped(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

impl Results<'_> {
    fn input_bytes(&self) -> u64 {
        self.input.bytes * self.copies as u64
    }

    fn input_frames(&self) -> u64 {
        self.input.frames * self.copies as u64
    }

    /// The fastest full build (its stretches are the table's).
    fn best(&self) -> Option<&BuildRun> {
        self.full.iter().min_by(|a, b| a.total.total_cmp(&b.total))
    }

    fn full_range(&self) -> (f64, f64) {
        min_max(self.full.iter().map(|r| r.total))
    }

    fn scan_range(&self) -> (f64, f64) {
        min_max(self.scan.seconds.iter().copied())
    }

    fn ratio(&self) -> f64 {
        self.full_range().0 / self.scan_range().0
    }

    /// The floor's CPU: the bare scan's plus the encode reference's, each its fastest pass.
    fn floor_cpu(&self) -> f64 {
        let scan = min_max(self.scan.cpu_seconds.iter().copied()).0;
        let encode = min_max(self.encode.cpu_seconds.iter().copied()).0;
        scan + encode
    }

    /// SHA-256 of the input and of the shards: the checksums the dataset records.
    fn digest_cpu(&self) -> f64 {
        self.scan.digest_cpu_seconds + self.encode.digest_cpu_seconds
    }

    /// The fastest build's CPU seconds over the floor's (issue 34's target: at most 1.5).
    fn floor_ratio(&self) -> Option<f64> {
        let floor = self.floor_cpu();
        self.best()
            .filter(|_| floor > 0.0)
            .map(|b| b.cpu_seconds / floor)
    }

    /// A stretch of the fastest build, by name.
    fn best_phase(&self, name: &str) -> Option<&Phase> {
        self.best()?.phases.iter().find(|p| p.name == name)
    }

    fn frames_per_core(&self) -> f64 {
        self.input_frames() as f64 / self.full_range().0 / self.threads as f64
    }

    /// A stretch's range over runs, by name.
    fn phase_range(runs: &[BuildRun], name: &str) -> Option<(f64, f64)> {
        let values: Vec<f64> = runs
            .iter()
            .flat_map(|r| r.phases.iter().filter(|p| p.name == name))
            .map(|p| p.seconds)
            .collect();
        (!values.is_empty()).then(|| min_max(values))
    }

    fn print(&self) -> std::io::Result<()> {
        let mut out = std::io::stdout().lock();
        let r = self.report;
        let synthetic = r
            .kinds
            .get(motionforge::clip::SourceKind::Synthetic.as_str())
            .copied()
            .unwrap_or(0);
        let dropped: usize = r.drops_by_reason.values().sum();
        writeln!(
            out,
            "bench --build: {} captures ({} x {}), {} frames, {:.1} MB of BVH, a pool of {} threads on {} CPUs",
            grouped(self.input.files.len() as u64 * self.copies as u64),
            self.copies,
            self.input.dir.display(),
            grouped(self.input_frames()),
            mb(self.input_bytes()),
            self.threads,
            self.cpus
        )?;
        writeln!(
            out,
            "config: pattern `{}`, profile {}, mirror on, synthetic pairs on, 30 fps, default features",
            self.pattern, self.args.profile
        )?;
        writeln!(
            out,
            "built: {} clips ({} mirrored, {synthetic} synthetic), {} rejects, {dropped} segments dropped",
            grouped(r.clips as u64),
            grouped(r.mirrored as u64),
            r.rejects.len()
        )?;
        writeln!(out)?;
        let (lo, hi) = self.full_range();
        writeln!(
            out,
            "full build from scratch: fastest of {} (range over runs); no-op rebuild: fastest of {}",
            self.repeat, self.repeat
        )?;
        writeln!(
            out,
            "{:<30} {:>8} {:>13} {:>6} {:>5} {:>8} {:>11} {:>7}",
            "stage", "seconds", "range", "share", "cores", "peak MB", "ran/reused", "no-op"
        )?;
        if let Some(best) = self.best() {
            self.print_stages(&mut out, best, (lo, hi))?;
            self.print_against_scan(&mut out, best, lo)?;
            self.print_outputs(&mut out)?;
        }
        Ok(())
    }

    /// The table of the fastest full build's stretches, with their no-op rebuild times.
    fn print_stages(
        &self,
        out: &mut impl Write,
        best: &BuildRun,
        (lo, hi): (f64, f64),
    ) -> std::io::Result<()> {
        for phase in &best.phases {
            let noop_gap = Self::phase_range(&self.noop, &phase.name).map_or(0.0, |r| r.1);
            // Gaps of a few milliseconds are noise; the JSON keeps them.
            if phase.gap && phase.seconds.max(noop_gap) < 0.005 {
                continue;
            }
            let (plo, phi) = Self::phase_range(&self.full, &phase.name)
                .unwrap_or((phase.seconds, phase.seconds));
            let noop = Self::phase_range(&self.noop, &phase.name)
                .map_or_else(|| "-".to_string(), |(n, _)| format!("{n:.2}"));
            let counts = if phase.gap {
                String::new()
            } else {
                format!("{}/{}", phase.ran, phase.reused)
            };
            let cores = if phase.seconds > 0.05 {
                format!("{:.1}", phase.cpu_seconds / phase.seconds)
            } else {
                "-".to_string()
            };
            let peak = phase.peak_kb.map_or_else(
                || "-".to_string(),
                |kb| format!("{:.0}", kb as f64 / 1024.0),
            );
            writeln!(
                out,
                "{:<30} {:>8.2} {:>13} {:>5.1}% {:>5} {:>8} {:>11} {:>7}",
                phase.name,
                phase.seconds,
                format!("{plo:.2}-{phi:.2}"),
                100.0 * phase.seconds / best.total,
                cores,
                peak,
                counts,
                noop
            )?;
        }
        let (nlo, _) = min_max(self.noop.iter().map(|r| r.total));
        writeln!(
            out,
            "{:<30} {:>8.2} {:>13} {:>6} {:>5} {:>8} {:>11} {:>7.2}",
            "total",
            best.total,
            format!("{lo:.2}-{hi:.2}"),
            "100%",
            format!("{:.1}", best.cpu_seconds / best.total.max(1e-9)),
            best.peak_rss_kb.map_or_else(
                || "-".to_string(),
                |kb| format!("{:.0}", kb as f64 / 1024.0)
            ),
            "",
            nlo
        )?;
        Ok(())
    }

    /// The encode reference, the write stage's CPU and the build against the floor (scan plus
    /// encode reference).
    fn print_against_floor(&self, out: &mut impl Write, best: &BuildRun) -> std::io::Result<()> {
        let (elo, ehi) = min_max(self.encode.cpu_seconds.iter().copied());
        let (ewlo, _) = min_max(self.encode.seconds.iter().copied());
        writeln!(
            out,
            "encode reference: {elo:.3} s CPU (range {elo:.3}-{ehi:.3}), {ewlo:.3} s wall: arrow-rs's ArrowWriter on one thread re-encoding the {} shards ({} rows, read into memory first, not timed) with the shard writer's properties, {:.1} MB; the same bytes as the build's: {}",
            self.encode.shards,
            grouped(self.encode.rows as u64),
            mb(self.encode.bytes),
            if self.encode.identical { "yes" } else { "no" }
        )?;
        if let Some(write) = self.best_phase("write") {
            writeln!(
                out,
                "write stage: {:.2} s wall, {:.2} s CPU, {:.2} cores (a pool of {} threads)",
                write.seconds,
                write.cpu_seconds,
                write.cpu_seconds / write.seconds.max(1e-9),
                self.threads
            )?;
        }
        let (scan_cpu, _) = min_max(self.scan.cpu_seconds.iter().copied());
        writeln!(
            out,
            "against the floor: build {:.2} s CPU / (scan {scan_cpu:.3} + encode reference {elo:.3} s CPU) = {}x (target at most 1.5x); wall {:.2} s = build CPU / {:.2} (target: at most CPU / 1.8 = {:.2} s)",
            best.cpu_seconds,
            self.floor_ratio()
                .map_or_else(|| "n/a".to_string(), |r| format!("{r:.2}")),
            best.total,
            best.cpu_seconds / best.total.max(1e-9),
            best.cpu_seconds / 1.8
        )?;
        let digests = self.digest_cpu();
        writeln!(
            out,
            "with the checksums the dataset records (SHA-256 of the input for source_sha256, {:.3} s; of the shards for the manifest, {:.3} s; one thread): build / (scan + encode reference + checksums {:.3} s CPU) = {:.2}x",
            self.scan.digest_cpu_seconds,
            self.encode.digest_cpu_seconds,
            self.floor_cpu() + digests,
            best.cpu_seconds / (self.floor_cpu() + digests).max(1e-9)
        )?;
        let by_stage: Vec<String> = best
            .phases
            .iter()
            .filter(|p| p.cpu_seconds >= 0.005)
            .map(|p| format!("{} {:.2}", p.name, p.cpu_seconds))
            .collect();
        writeln!(
            out,
            "build CPU by stage (s, all threads): {}",
            by_stage.join(", ")
        )
    }

    /// The build against the bare scan, the no-op rebuild and plan, and peak memory.
    fn print_against_scan(
        &self,
        out: &mut impl Write,
        best: &BuildRun,
        lo: f64,
    ) -> std::io::Result<()> {
        let (nlo, nhi) = min_max(self.noop.iter().map(|r| r.total));
        writeln!(out)?;
        let (slo, shi) = self.scan_range();
        writeln!(
            out,
            "bare scan: {slo:.3} s (range {slo:.3}-{shi:.3}, best of {}), one thread, {} numbers from {:.1} MB, {:.0} MB/s",
            self.repeat,
            grouped(self.scan.numbers),
            mb(self.scan.bytes),
            mb(self.scan.bytes) / slo
        )?;
        writeln!(
            out,
            "ratio: {:.1}x the bare scan (full build {lo:.2} s on {} threads / scan {slo:.3} s on one)",
            self.ratio(),
            self.threads
        )?;
        self.print_against_floor(out, best)?;
        writeln!(
            out,
            "frames/s per core: {} ({} frames / {lo:.2} s / {} cores)",
            grouped(self.frames_per_core().round() as u64),
            grouped(self.input_frames()),
            self.threads
        )?;
        writeln!(
            out,
            "no-op rebuild: {nlo:.2} s (range {nlo:.2}-{nhi:.2}){}",
            if self.noop_ran.is_empty() {
                ", nothing ran".to_string()
            } else {
                format!("; not a no-op: {}", self.noop_ran.join(", "))
            }
        )?;
        let (plo, phi) = min_max(self.plans.iter().map(|p| p.seconds));
        writeln!(
            out,
            "plan: {plo:.2} s (range {plo:.2}-{phi:.2}){}",
            if self.plan_stale {
                "; the plan found stages to run"
            } else {
                ", nothing to run"
            }
        )?;
        let noop_peak = self.noop.iter().filter_map(|r| r.peak_rss_kb).max();
        let noop_start = self.noop.iter().filter_map(|r| r.start_rss_kb).max();
        let plan_peak = self.plans.iter().filter_map(|p| p.peak_rss_kb).max();
        let plan_start = self.plans.iter().filter_map(|p| p.start_rss_kb).max();
        writeln!(
            out,
            "peak RSS: full build {} (first run; highest of all runs {}); in this process after the builds, so above what they leave held: no-op rebuild {} (held {} at its start), plan {} (held {}), scan {}",
            rss_mb(self.full.first().and_then(|r| r.peak_rss_kb)),
            rss_mb(self.full.iter().filter_map(|r| r.peak_rss_kb).max()),
            rss_mb(noop_peak),
            rss_mb(noop_start),
            rss_mb(plan_peak),
            rss_mb(plan_start),
            rss_mb(self.scan.peak_rss_kb)
        )?;
        Ok(())
    }

    /// What the build left on disk, and the machine's load meanwhile.
    fn print_outputs(&self, out: &mut impl Write) -> std::io::Result<()> {
        let cache_total: u64 = self.cache.values().sum();
        let per_stage: Vec<String> = self
            .cache
            .iter()
            .map(|(k, v)| format!("{k} {:.1}", mb(*v)))
            .collect();
        writeln!(
            out,
            "stage cache: {:.1} MB ({:.2}x the {:.1} MB of input): {} (MB)",
            mb(cache_total),
            cache_total as f64 / self.input_bytes() as f64,
            mb(self.input_bytes()),
            per_stage.join(", ")
        )?;
        let shard_total: u64 = self.shards.iter().sum();
        writeln!(
            out,
            "shards: {:.1} MB in {} files (data/*.parquet), {:.2}x the input",
            mb(shard_total),
            self.shards.len(),
            shard_total as f64 / self.input_bytes() as f64
        )?;
        let others: Vec<String> = self
            .full
            .iter()
            .map(|r| format!("{:.0}%", 100.0 * r.cpu.others))
            .collect();
        writeln!(
            out,
            "machine: load average {} at start, {} at end; other processes used {} of the CPUs during the full builds",
            self.load.0.as_deref().unwrap_or("n/a"),
            self.load.1.as_deref().unwrap_or("n/a"),
            others.join(", ")
        )?;
        if let Some(b) = &self.bvhio {
            let (lo, _) = self.full_range();
            let cpu = self.best().map_or(0.0, |r| r.cpu_seconds);
            writeln!(
                out,
                "bvhio: {:.3} s wall, {:.3} s CPU, one thread: bvhio {} reading {} files ({} frames) and computing {} world positions",
                b.wall_s,
                b.cpu_s,
                b.version,
                b.files,
                grouped(b.frames),
                grouped(b.positions)
            )?;
            writeln!(
                out,
                "against bvhio: {:.3}x faster (bvhio {:.3} s wall / full build {lo:.3} s wall; target at least 20x); per CPU second {:.3}x (bvhio {:.3} s / build {cpu:.3} s)",
                b.wall_s / lo.max(1e-9),
                b.wall_s,
                b.cpu_s / cpu.max(1e-9),
                b.cpu_s
            )?;
        }
        if let Some(dir) = &self.kept {
            writeln!(out, "kept: {}", dir.display())?;
        }
        Ok(())
    }

    fn json(&self) -> serde_json::Value {
        let run_json = |run: &BuildRun| {
            let phases: Vec<serde_json::Value> = run
                .phases
                .iter()
                .map(|p| {
                    serde_json::json!({
                        "stage": p.name,
                        "gap": p.gap,
                        "seconds": p.seconds,
                        "cpu_seconds": p.cpu_seconds,
                        "peak_rss_kb": p.peak_kb,
                        "ran": p.ran,
                        "reused": p.reused,
                    })
                })
                .collect();
            serde_json::json!({
                "seconds": run.total,
                "stages": phases,
                "peak_rss_kb": run.peak_rss_kb,
                "start_rss_kb": run.start_rss_kb,
                "cpu_seconds": run.cpu_seconds,
                "cpu_share_own": run.cpu.own,
                "cpu_share_others": run.cpu.others,
            })
        };
        let (lo, hi) = self.full_range();
        let (nlo, nhi) = min_max(self.noop.iter().map(|r| r.total));
        let (plo, phi) = min_max(self.plans.iter().map(|p| p.seconds));
        let (slo, shi) = self.scan_range();
        serde_json::json!({
            "data": self.input.dir,
            "copies": self.copies,
            "repeat": self.repeat,
            "threads": self.threads,
            "cpus": self.cpus,
            "pattern": self.pattern,
            "profile": self.args.profile,
            "captures": self.input.files.len() * self.copies,
            "input_bytes": self.input_bytes(),
            "input_frames": self.input_frames(),
            "clips": self.report.clips,
            "mirrored": self.report.mirrored,
            "kinds": self.report.kinds,
            "rejects": self.report.rejects.len(),
            "full_build": {
                "seconds_min": lo,
                "seconds_max": hi,
                "runs": self.full.iter().map(run_json).collect::<Vec<_>>(),
            },
            "noop_rebuild": {
                "seconds_min": nlo,
                "seconds_max": nhi,
                "nothing_ran": self.noop_ran.is_empty(),
                "runs": self.noop.iter().map(run_json).collect::<Vec<_>>(),
            },
            "plan": {
                "seconds_min": plo,
                "seconds_max": phi,
                "nothing_to_run": !self.plan_stale,
                "peak_rss_kb": self.plans.iter().filter_map(|p| p.peak_rss_kb).max(),
                "cpu_share_others": self.plans.iter().map(|p| p.cpu.others).collect::<Vec<_>>(),
            },
            "scan": {
                "seconds_min": slo,
                "seconds_max": shi,
                "seconds": self.scan.seconds,
                "cpu_seconds": self.scan.cpu_seconds,
                "numbers": self.scan.numbers,
                "bytes": self.scan.bytes,
                "peak_rss_kb": self.scan.peak_rss_kb,
                "digest_cpu_seconds": self.scan.digest_cpu_seconds,
            },
            "ratio": self.ratio(),
            "encode_reference": {
                "writer": "arrow-rs ArrowWriter, one thread, the shard writer's properties",
                "seconds": self.encode.seconds,
                "cpu_seconds": self.encode.cpu_seconds,
                "shards": self.encode.shards,
                "rows": self.encode.rows,
                "bytes": self.encode.bytes,
                "identical_to_shards": self.encode.identical,
                "digest_cpu_seconds": self.encode.digest_cpu_seconds,
            },
            "floor_cpu_seconds": self.floor_cpu(),
            "floor_ratio": self.floor_ratio(),
            "frames_per_second_per_core": self.frames_per_core(),
            "peak_rss_kb": {
                "full_build_first": self.full.first().and_then(|r| r.peak_rss_kb),
                "full_build_max": self.full.iter().filter_map(|r| r.peak_rss_kb).max(),
                "noop_rebuild": self.noop.iter().filter_map(|r| r.peak_rss_kb).max(),
            },
            "cache_bytes": self.cache,
            "cache_bytes_total": self.cache.values().sum::<u64>(),
            "shard_bytes": self.shards.iter().sum::<u64>(),
            "shards": self.shards.len(),
            "bvhio": self.bvhio.as_ref().map(|b| serde_json::json!({
                "version": b.version,
                "files": b.files,
                "frames": b.frames,
                "positions": b.positions,
                "wall_s": b.wall_s,
                "cpu_s": b.cpu_s,
                "build_speedup_wall": b.wall_s / lo.max(1e-9),
            })),
            "load_average": { "start": self.load.0, "end": self.load.1 },
            "kept": self.kept,
        })
    }
}
