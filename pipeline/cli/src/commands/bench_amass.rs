//! `motionforge bench --amass`: reading AMASS `.npz` files and computing their joints on one
//! thread, beside reading BVH in the same run; with `--build`, a whole build of the folder timed
//! end to end. The files and the body model are the user's (or written by
//! `scripts/amass-bench-data.sh` from the tests' generator: AMASS may not be redistributed).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use motionforge::amass::{self, Family};

use super::bench::bvh_timings;
use super::bench_build::{BenchWork, CONFIG_MARKER, OUTPUT_DIR, grouped, rss_mb};
use super::bench_clock::BuildRun;
use super::bench_machine::load_average;
use crate::ui::Ui;

/// What `bench --amass` is asked to do.
pub(crate) struct AmassBench {
    /// Folder of AMASS `.npz` files, searched recursively.
    pub(crate) dir: PathBuf,
    /// Body model folder laid out as AMASS documents it (`smplh/male/model.npz`, ...).
    pub(crate) body_model: PathBuf,
    /// Folder of BVH files read in the same run, for the comparison.
    pub(crate) bvh: PathBuf,
    /// Skeleton profile of the BVH files.
    pub(crate) bvh_profile: String,
    /// Passes over the files (the fastest is kept); with `build`, builds (the fastest is kept).
    pub(crate) repeat: usize,
    /// Time a whole build of the folder too.
    pub(crate) build: bool,
    /// Keep the build's config and dataset here.
    pub(crate) keep: Option<PathBuf>,
    /// Threads of the build's pool.
    pub(crate) threads: Option<usize>,
}

/// The shape coefficients a build uses by default, as HumanML3D does.
const NUM_BETAS: usize = 10;

/// Runs the benchmark and prints what it measured.
pub(crate) fn bench_amass(args: &AmassBench, ui: &Ui) -> Result<()> {
    let files = npz_files(&args.dir)?;
    let repeat = args.repeat.max(1);
    let load = load_average();
    let amass = amass_timings(&files, &args.body_model, repeat)?;
    let bvh = bvh_timings(&args.bvh, &args.bvh_profile, repeat)?;
    let mut out = std::io::stdout();
    let amass_rate = amass.frames as f64 / amass.seconds;
    let bvh_rate = bvh.frames as f64 / (bvh.read_s + bvh.fk_s);
    writeln!(
        out,
        "AMASS: {} files, {} frames, {:.1} MB ({}), one thread, best of {repeat}",
        files.len(),
        grouped(amass.frames as u64),
        amass.bytes as f64 / 1e6,
        amass.families
    )?;
    writeln!(
        out,
        "read + joints   {amass_rate:>10.0} frames/s  (file read, npz parsed, rest joints, FK)"
    )?;
    writeln!(
        out,
        "BVH:   {} files, {} frames of {}, same run",
        bvh.files,
        grouped(bvh.frames as u64),
        args.bvh.display()
    )?;
    writeln!(
        out,
        "read + fk       {bvh_rate:>10.0} frames/s  (AMASS is {:.2}x)",
        amass_rate / bvh_rate
    )?;
    if args.build {
        let run = build_run(args, &files, amass.family, ui)?;
        let frames = amass.frames as f64;
        writeln!(
            out,
            "build: {} rows from {} files in {:.2} s wall, {:.2} s CPU, peak {}",
            grouped(run.rows as u64),
            files.len(),
            run.best.total,
            run.best.cpu_seconds,
            rss_mb(run.best.peak_rss_kb)
        )?;
        writeln!(
            out,
            "       {:.0} input frames/s per core by wall time on {} threads, {:.0} per CPU second",
            frames / run.best.total / run.threads as f64,
            run.threads,
            frames / run.best.cpu_seconds
        )?;
        for phase in run.best.phases.iter().filter(|p| !p.gap) {
            writeln!(out, "       {:<26} {:>7.2} s", phase.name, phase.seconds)?;
        }
    }
    writeln!(
        out,
        "load average: {} at the start",
        load.as_deref().unwrap_or("n/a")
    )?;
    Ok(())
}

/// The AMASS sequences under `dir`, recursively, in path order; `shape.npz` and MoSh's
/// `*_stagei.npz` are not motions and are left out, as a build leaves them out.
fn npz_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        let entries = std::fs::read_dir(&folder)
            .with_context(|| format!("cannot list {}", folder.display()))?;
        for entry in entries {
            let path = entry
                .with_context(|| format!("cannot list {}", folder.display()))?
                .path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            if path.is_dir() {
                folders.push(path);
            } else if let Some(name) = name
                && name.ends_with(".npz")
                && !amass::is_not_a_motion(&name)
            {
                files.push(path);
            }
        }
    }
    files.sort();
    if files.is_empty() {
        bail!(
            "no AMASS .npz files under {} (scripts/amass-bench-data.sh writes generated ones)",
            dir.display()
        );
    }
    Ok(files)
}

/// Best-of-`repeat` seconds of reading every file and computing its joints on one thread.
struct AmassTimings {
    frames: usize,
    bytes: usize,
    seconds: f64,
    /// The files' families and genders, for the printout.
    families: String,
    /// The first file's family: the build's skeleton profile.
    family: Family,
}

fn amass_timings(files: &[PathBuf], body_model: &Path, repeat: usize) -> Result<AmassTimings> {
    // Models are read before the timing, once each, as a build reads them; the files are read
    // in the timing, one at a time (a few megabytes each, thousands of them), as a build does.
    let mut kinds = std::collections::BTreeMap::new();
    let mut family = None;
    let mut bytes = 0;
    for file in files {
        let (seq, gender) = read_one(file)?;
        amass::load_model(
            &amass::model_path(body_model, seq.family, gender),
            NUM_BETAS,
        )
        .with_context(|| format!("{}: body model", file.display()))?;
        *kinds
            .entry(format!("{} {gender}", seq.family.folder()))
            .or_insert(0usize) += 1;
        family.get_or_insert(seq.family);
        bytes += std::fs::metadata(file).map_or(0, |m| m.len() as usize);
    }
    let Some(family) = family else {
        bail!("no AMASS files to read");
    };
    let mut best = AmassTimings {
        frames: 0,
        bytes,
        seconds: f64::INFINITY,
        families: kinds
            .iter()
            .map(|(k, n)| format!("{n} {k}"))
            .collect::<Vec<_>>()
            .join(", "),
        family,
    };
    for _ in 0..repeat {
        let start = std::time::Instant::now();
        let mut frames = 0;
        for file in files {
            let (seq, gender) = read_one(file)?;
            let model = amass::load_model(
                &amass::model_path(body_model, seq.family, gender),
                NUM_BETAS,
            )
            .with_context(|| format!("{}: body model", file.display()))?;
            let fps = seq.fps.unwrap_or(amass::HUMANML3D_FPS);
            let motion = amass::to_motion(&seq, &model, 1, fps)
                .with_context(|| format!("{}: joints", file.display()))?;
            std::hint::black_box(motion.forward_kinematics());
            frames += motion.num_frames();
        }
        best.seconds = best.seconds.min(start.elapsed().as_secs_f64());
        best.frames = frames;
    }
    Ok(best)
}

/// One file read and parsed, with the gender folder of its model.
fn read_one(file: &Path) -> Result<(amass::Sequence, &'static str)> {
    let name = file.display().to_string();
    let bytes = std::fs::read(file).with_context(|| format!("cannot read {name}"))?;
    let seq = amass::read_sequence(&name, &bytes, true)?;
    let gender = amass::model_gender(amass::GenderChoice::File, seq.gender.as_ref(), false)
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    Ok((seq, gender))
}

/// The fastest of `repeat` builds of the folder from scratch.
struct AmassBuild {
    best: BuildRun,
    rows: usize,
    threads: usize,
}

fn build_run(args: &AmassBench, files: &[PathBuf], family: Family, ui: &Ui) -> Result<AmassBuild> {
    let bench = BenchWork::new(args.keep.as_deref(), args.threads, "bench-amass", |work| {
        config_text(args, files, family, work)
    })?;
    let mut best: Option<(BuildRun, usize)> = None;
    for _ in 0..args.repeat.max(1) {
        let (run, report) = bench.fresh_build(ui)?;
        if report.clips == 0 || !report.rejects.is_empty() {
            bail!(
                "the build wrote {} rows from {} files and rejected {}: {}",
                report.clips,
                report.captures,
                report.rejects.len(),
                crate::summary::counts(&report.rejects_by_reason)
            );
        }
        if best.as_ref().is_none_or(|(b, _)| run.total < b.total) {
            best = Some((run, report.clips));
        }
    }
    let Some((best, rows)) = best else {
        bail!("no build ran");
    };
    Ok(AmassBuild {
        best,
        rows,
        threads: bench.threads,
    })
}

/// The build config: every file of the folder as one clip labelled by its name, on the body
/// model's bundled profile, resampled to 30 fps and mirrored, no synthetic pairs.
fn config_text(
    args: &AmassBench,
    files: &[PathBuf],
    family: Family,
    work: &Path,
) -> Result<String> {
    let quote = |s: &str| toml::Value::String(s.to_string()).to_string();
    let dir = std::path::absolute(&args.dir)?;
    let body_model = std::path::absolute(&args.body_model)?;
    let glob = format!(
        "{}/**/*.npz",
        glob::Pattern::escape(&dir.display().to_string())
    );
    let profile = match family {
        Family::SmplH => "smplh-52",
        Family::SmplX => "smplx-55",
    };
    Ok(format!(
        "{CONFIG_MARKER} --amass ({} files)\n[dataset]\nname = \"bench-amass\"\noutput = {}\nfps = 30\n\n[mirror]\nenabled = true\n\n[synthetic]\nenabled = false\n\n[[sources]]\nname = \"amass\"\ncaptures = [{}]\nprofile = \"{profile}\"\n\n[sources.labels]\nkind = \"filename\"\npattern = \"^(?P<name>.+)$\"\naction = \"move\"\ntext = \"a person moves\"\n\n[sources.segment]\nmax_seconds = 600\n\n[sources.amass]\nbody_model = {}\nnum_betas = {NUM_BETAS}\n",
        files.len(),
        quote(&work.join(OUTPUT_DIR).display().to_string()),
        quote(&glob),
        quote(&body_model.display().to_string()),
    ))
}
