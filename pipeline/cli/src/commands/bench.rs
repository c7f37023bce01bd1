//! `bench`: throughput of reading, forward kinematics and mirroring; with its options, of
//! writing shards, of a whole build (`bench_build`), of previews or of the caption tagger.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use motionforge::build::BuildOptions;
use motionforge::config::Config;
use motionforge::motion::{MirrorPlan, OffsetPolicy, read_bvh};

use super::bench_amass::{AmassBench, bench_amass};
use super::bench_build::{BuildBench, bench_build};
use super::bench_export::{ExportBench, bench_export};
use super::mirror::load_profile;
use crate::ui::Ui;

/// Measure BVH read, forward kinematics and mirroring throughput on a folder of captures; or,
/// with --build, a whole build of the folder stage by stage beside a bare number scan; with
/// --export, `export humanml3d` beside a NumPy reference of HumanML3D's computation.
///
/// `bench --build` writes a config (file-name labels and sidecars as in fixtures/demo.toml,
/// mirror and synthetic pairs on, default features, 30 fps) into a temporary folder and runs:
/// full builds from scratch (wall time per stage), no-op rebuilds, `plan`, and a single-thread
/// scan that parses every number of the same bytes into f64. It prints the ratio of the build
/// to the scan, frames/s per core, peak memory, and the stage cache and shard bytes.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge bench --repeat 1
  motionforge bench --build --data ../shared/data/bandai-namco-1/data --repeat 1
  motionforge bench --captions ../shared/data/sinc/clean_labels.txt
  motionforge bench --export out/bench --repeat 1 --python $(scripts/python-env.sh)"
))]
pub(crate) struct BenchArgs {
    /// Folder of BVH files (all must share one skeleton profile).
    #[arg(long, default_value = "../shared/data/bandai-namco-1/data")]
    data: PathBuf,
    /// Skeleton profile of the captures.
    #[arg(long, default_value = "bandai-namco")]
    profile: String,
    /// Repeat the whole folder this many times and keep the fastest pass; with --build, run
    /// each measurement (full build, no-op rebuild, plan, scan) this many times.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Instead, measure writing Parquet shards of at least this many frames (the folder's
    /// clips and mirrors, repeated), with the write's peak memory.
    #[arg(long, conflicts_with = "build")]
    write_frames: Option<usize>,
    /// Instead, time a whole build of the folder stage by stage, beside a bare single-thread
    /// scan of the same bytes into f64.
    #[arg(long)]
    build: bool,
    /// With --build: list the folder under this many source names (`bn2-1`..`bn2-N`), so the
    /// build has N times the captures; the scan reads the bytes N times.
    #[arg(long, default_value_t = 1, requires = "build")]
    copies: usize,
    /// With --build: build in this folder (new, empty, or an earlier run's) and keep the
    /// config and dataset there, instead of a temporary folder removed at the end.
    #[arg(long, value_name = "DIR", requires = "build")]
    keep: Option<PathBuf>,
    /// With --build: the file-name pattern of the labels; default
    /// `<prefix>_{content}_{style}_{take}` with the prefix of the first file name (Bandai
    /// Namco: `dataset-2_{content}_{style}_{take}`).
    #[arg(long, requires = "build")]
    pattern: Option<String>,
    /// With --build: run the builds and the plan on a pool of this many threads (1 to measure
    /// one core, 2 for two...); default one per CPU (or `RAYON_NUM_THREADS`).
    #[arg(long, value_name = "N", requires = "build", value_parser = clap::value_parser!(u16).range(1..))]
    threads: Option<u16>,
    /// Instead, time `preview` (GIF and filmstrip, one thread) on the first 100 original
    /// clips of this built dataset folder, written to a temporary folder: previews per second.
    #[arg(long, value_name = "DATASET", conflicts_with_all = ["build", "write_frames"])]
    previews: Option<PathBuf>,
    /// Instead, time reading the AMASS `.npz` files under this folder (recursively) and
    /// computing their joints on one thread, beside reading the BVH files of --data in the same
    /// run; with --build, also a whole build of the folder (one clip per file, mirrored, 30 fps).
    /// Needs --body-model.
    #[arg(long, value_name = "DIR", requires = "body_model", conflicts_with_all = ["write_frames", "previews"])]
    amass: Option<PathBuf>,
    /// With --amass: the body model folder, laid out as AMASS documents it
    /// (`smplh/male/model.npz`, ...).
    #[arg(long, value_name = "DIR", requires = "amass")]
    body_model: Option<PathBuf>,
    /// Instead, time the HumanML3D caption tagger (spaCy's network) on the distinct captions
    /// of this text file, one a line, on one thread: captions per second.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["build", "write_frames", "previews", "amass"])]
    captions: Option<PathBuf>,
    /// Instead, time `export humanml3d` of this built dataset folder (wall and CPU, rows/s),
    /// beside a NumPy reference of HumanML3D's `process_file` (scripts/humanml3d_reference.py)
    /// run on one thread over the same joint sequences: the ratios per CPU and per wall second.
    #[arg(long, value_name = "DATASET", conflicts_with_all = ["build", "write_frames", "previews", "amass", "captions"])]
    export: Option<PathBuf>,
    /// With --build: also time `bvhio` (Python, one thread) reading every BVH file of the
    /// folder and computing every joint's world position in every frame; prints the build's
    /// wall time over bvhio's.
    #[arg(long, requires = "build")]
    bvhio: bool,
    /// With --export or --bvhio: the Python to run the reference with (NumPy, bvhio); default
    /// `MOTIONFORGE_PYTHON`, as the tests (`$(scripts/python-env.sh)`).
    #[arg(long, value_name = "PYTHON")]
    python: Option<PathBuf>,
}

/// `motionforge bench`.
pub(crate) fn run(args: BenchArgs, ui: &Ui) -> Result<ExitCode> {
    if let Some(file) = &args.captions {
        bench_captions(file)?;
    } else if let Some(dataset) = args.export {
        let bench = ExportBench {
            dataset,
            repeat: args.repeat,
            python: args.python,
        };
        bench_export(&bench, ui)?;
    } else if let Some(dataset) = &args.previews {
        super::preview::bench_previews(dataset)?;
    } else if let (Some(dir), Some(body_model)) = (&args.amass, &args.body_model) {
        let bench = AmassBench {
            dir: dir.clone(),
            body_model: body_model.clone(),
            bvh: args.data,
            bvh_profile: args.profile,
            repeat: args.repeat,
            build: args.build,
            keep: args.keep,
            threads: args.threads.map(usize::from),
        };
        bench_amass(&bench, ui)?;
    } else if let Some(frames) = args.write_frames {
        bench_write(&args.data, &args.profile, frames)?;
    } else if args.build {
        let bench = BuildBench {
            data: args.data,
            profile: args.profile,
            repeat: args.repeat,
            copies: args.copies,
            keep: args.keep,
            pattern: args.pattern,
            threads: args.threads.map(usize::from),
            bvhio: args.bvhio.then_some(args.python),
        };
        bench_build(&bench, ui)?;
    } else {
        bench(&args.data, &args.profile, args.repeat.max(1))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Best-of-`repeat` seconds of reading, forward kinematics and mirroring a folder of BVH files
/// on one thread.
pub(crate) struct BvhTimings {
    /// Files read.
    pub(crate) files: usize,
    /// Frames in them.
    pub(crate) frames: usize,
    /// Their bytes.
    pub(crate) bytes: usize,
    /// Parsing the text.
    pub(crate) read_s: f64,
    /// World positions of every joint.
    pub(crate) fk_s: f64,
    /// The mirrored motion.
    pub(crate) mirror_s: f64,
    /// The three in one pass (the best pass, not the sum of the bests).
    pub(crate) total_s: f64,
}

/// The `.bvh` files of `dir` (not below it), in name order; none is an error.
pub(super) fn bvh_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "bvh"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no .bvh files in {}", dir.display());
    }
    Ok(files)
}

/// Reads, forward kinematics and mirrors every capture in `data`, best of `repeat` passes.
pub(crate) fn bvh_timings(data: &Path, profile: &str, repeat: usize) -> Result<BvhTimings> {
    let spec = load_profile(profile)?;
    let files = bvh_files(data)?;
    let texts: Vec<String> = files
        .iter()
        .map(std::fs::read_to_string)
        .collect::<std::io::Result<_>>()?;
    let first = read_bvh(&texts[0]).with_context(|| files[0].display().to_string())?;
    let plan = MirrorPlan::from_profile(&first.skeleton, &spec.bind(&first.skeleton)?)?;
    let mut best = BvhTimings {
        files: files.len(),
        frames: 0,
        bytes: texts.iter().map(String::len).sum(),
        read_s: f64::INFINITY,
        fk_s: f64::INFINITY,
        mirror_s: f64::INFINITY,
        total_s: f64::INFINITY,
    };
    for _ in 0..repeat.max(1) {
        let (mut p, mut f, mut m) = (0.0, 0.0, 0.0);
        best.frames = 0;
        for text in &texts {
            let t0 = std::time::Instant::now();
            let bvh = read_bvh(text)?;
            let t1 = std::time::Instant::now();
            let pose = bvh.motion.forward_kinematics();
            let t2 = std::time::Instant::now();
            let mirrored = plan.mirror(&bvh.motion, OffsetPolicy::default());
            let t3 = std::time::Instant::now();
            std::hint::black_box((&pose, &mirrored));
            best.frames += bvh.motion.num_frames();
            p += (t1 - t0).as_secs_f64();
            f += (t2 - t1).as_secs_f64();
            m += (t3 - t2).as_secs_f64();
        }
        best.read_s = best.read_s.min(p);
        best.fk_s = best.fk_s.min(f);
        best.mirror_s = best.mirror_s.min(m);
        best.total_s = best.total_s.min(p + f + m);
    }
    Ok(best)
}

/// Read, forward kinematics and mirroring of every capture in `data`, best of `repeat` passes.
fn bench(data: &Path, profile: &str, repeat: usize) -> Result<()> {
    let t = bvh_timings(data, profile, repeat)?;
    let frames = t.frames as f64;
    let mb = t.bytes as f64 / 1e6;
    let mut out = std::io::stdout();
    writeln!(
        out,
        "{} files, {} frames, {mb:.1} MB, one thread, best of {repeat}",
        t.files, t.frames
    )?;
    writeln!(
        out,
        "read      {:>10.0} frames/s  {:>7.1} MB/s",
        frames / t.read_s,
        mb / t.read_s
    )?;
    writeln!(out, "fk        {:>10.0} frames/s", frames / t.fk_s)?;
    writeln!(out, "mirror    {:>10.0} frames/s", frames / t.mirror_s)?;
    writeln!(
        out,
        "read+fk+mirror {:>10.0} frames/s  {:>7.1} MB/s",
        frames / t.total_s,
        mb / t.total_s
    )?;
    Ok(())
}

/// Peak resident memory of this process in kB (Linux `VmHWM`), if readable.
pub(crate) fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

fn bench_write(data: &Path, profile: &str, target_frames: usize) -> Result<()> {
    let work = std::env::temp_dir().join(format!("motionforge-bench-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let data = std::path::absolute(data)?;
    let config_text = format!(
        "[dataset]\nname = \"bench\"\noutput = \"out\"\n\n[synthetic]\nenabled = false\n\n[[sources]]\nname = \"bench\"\ncaptures = [\"{}/*.bvh\"]\nprofile = \"{profile}\"\n[sources.labels]\nkind = \"filename\"\npattern = \"^(?P<name>.+)$\"\naction = \"{{name}}\"\ntext = \"{{name}}\"\n[sources.segment]\nmax_seconds = 600\n",
        data.display()
    );
    let config_path = work.join("bench.toml");
    std::fs::write(&config_path, config_text)?;
    let config = Config::load(&config_path)?;
    let base = motionforge::build::collect_clips(&config, &BuildOptions::default())?;
    let base_frames: usize = base.iter().map(|c| c.motion.num_frames()).sum();
    if base_frames == 0 {
        bail!("no frames in {}", data.display());
    }
    let copies = target_frames.div_ceil(base_frames);
    let spec = load_profile(profile)?;
    let mut profiles = std::collections::BTreeMap::new();
    profiles.insert(spec.name.clone(), spec.bind(&base[0].motion.skeleton)?);
    let features = motionforge::features::FeatureConfig::default();
    // Shards of about 64 MB of rows each, as a build would cut them.
    let mut shards: Vec<Vec<motionforge::clip::LoadedClip>> = vec![Vec::new()];
    let mut size = 0u64;
    for k in 0..copies {
        for c in &base {
            let bytes = (c.motion.num_frames() * c.motion.num_joints() * 7 * 4) as u64;
            if size + bytes > 64 << 20 && shards.last().is_some_and(|s| !s.is_empty()) {
                shards.push(Vec::new());
                size = 0;
            }
            size += bytes;
            let mut clip = c.clone();
            clip.clip.clip_id = format!("{}#{k}", c.clip.clip_id);
            if let Some(s) = shards.last_mut() {
                s.push(clip);
            }
        }
    }
    let frames = base_frames * copies;
    let before = peak_rss_kb();
    // Reset the peak so what follows measures the write alone (Linux: 5 > clear_refs).
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let start = std::time::Instant::now();
    let mut bytes = 0u64;
    for (i, shard) in shards.iter().enumerate() {
        let path = work.join(format!("shard-{i:05}.parquet"));
        let file = std::fs::File::create(&path)?;
        motionforge::io::parquet::write_clips(file, shard, &profiles, "{}", &features)?;
        bytes += std::fs::metadata(&path)?.len();
    }
    let seconds = start.elapsed().as_secs_f64();
    let peak = peak_rss_kb();
    let _ = std::fs::remove_dir_all(&work);
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{} clips, {frames} frames ({copies} copies of {} frames), {} shards, {:.1} MB written, one thread",
        shards.iter().map(Vec::len).sum::<usize>(),
        base_frames,
        shards.len(),
        bytes as f64 / 1e6
    )?;
    writeln!(
        out,
        "write     {:>10.0} frames/s  {:>7.1} MB/s  ({seconds:.2} s)",
        frames as f64 / seconds,
        bytes as f64 / 1e6 / seconds
    )?;
    if let (Some(b), Some(p)) = (before, peak) {
        writeln!(
            out,
            "peak RSS  {:.0} MB before writing (clips in memory), {:.0} MB peak while writing",
            b as f64 / 1024.0,
            p as f64 / 1024.0
        )?;
    }
    Ok(())
}

/// `bench --captions FILE`: tags each distinct caption of the file (one a line) for a HumanML3D
/// caption line on one thread, all of them together as the export does (`caption::remember_all`),
/// then all of them again (remembered by `caption::tokens`).
fn bench_captions(path: &Path) -> Result<()> {
    use motionforge::caption::{remember_all, tokens};
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let captions: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let start = std::time::Instant::now();
    tokens("walk").context("loading the caption tagger")?;
    let load = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let (mut words, mut refused) = (0usize, 0usize);
    remember_all(&captions).context("loading the caption tagger")?;
    for caption in &captions {
        match tokens(caption) {
            Ok(t) => words += t.len(),
            Err(_) => refused += 1,
        }
    }
    let first = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    for caption in &captions {
        let _ = tokens(caption);
    }
    let again = start.elapsed().as_secs_f64();
    writeln!(
        std::io::stdout(),
        "{} distinct captions ({words} words kept, {refused} refused), one thread: tagger load {:.0} ms; \
         first pass (tagged together) {first:.3} s, {:.0} captions/s; again {again:.3} s, {:.0} captions/s (remembered)",
        captions.len(),
        load * 1e3,
        captions.len() as f64 / first.max(1e-9),
        captions.len() as f64 / again.max(1e-9)
    )?;
    Ok(())
}
