//! Commands that work on captures and clips directly: mirror-text, calibrate-mirror, bench,
//! export-bvh.

use crate::{Ui, load_checked};
use anyhow::{Context, Result, bail};
use motionforge::build::BuildOptions;
use motionforge::config::Config;
use motionforge::motion::{MirrorPlan, OffsetPolicy, ProfileSpec, calibrate, read_bvh};
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

pub(crate) fn mirror_text(file: Option<&Path>) -> Result<()> {
    let stdin = std::io::stdin();
    let reader: Box<dyn BufRead> = match file {
        Some(p) => Box::new(std::io::BufReader::new(
            std::fs::File::open(p).with_context(|| format!("cannot open {}", p.display()))?,
        )),
        None => Box::new(stdin.lock()),
    };
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for line in reader.lines() {
        let line = line.context("reading text")?;
        writeln!(out, "{}", motionforge::text::mirror_text(&line))?;
    }
    out.flush()?;
    Ok(())
}

pub(crate) fn load_profile(name: &str) -> Result<ProfileSpec> {
    if name.ends_with(".toml") {
        let text =
            std::fs::read_to_string(name).with_context(|| format!("cannot read profile {name}"))?;
        Ok(ProfileSpec::from_toml(name, &text)?)
    } else {
        Ok(ProfileSpec::bundled(name)?)
    }
}

pub(crate) fn read_capture(path: &Path) -> Result<motionforge::motion::Bvh> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    read_bvh(&text).with_context(|| format!("{}", path.display()))
}

pub(crate) fn calibrate_mirror(profile: &str, captures: &[PathBuf]) -> Result<()> {
    let spec = load_profile(profile)?;
    let bvhs: Vec<_> = captures
        .iter()
        .map(|p| read_capture(p))
        .collect::<Result<_>>()?;
    let skeleton = &bvhs[0].skeleton;
    if let Some((p, _)) = captures
        .iter()
        .zip(&bvhs)
        .find(|(_, b)| b.skeleton.names().ne(skeleton.names()))
    {
        bail!(
            "{} has a different skeleton from {}",
            p.display(),
            captures[0].display()
        );
    }
    let bound = spec.bind(skeleton)?;
    let motions: Vec<_> = bvhs.iter().map(|b| &b.motion).collect();
    let reflections = calibrate(skeleton, &bound, &motions);
    let names: Vec<String> = captures
        .iter()
        .filter_map(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .collect();
    writeln!(
        std::io::stdout(),
        "# Calibrated on {} with `motionforge calibrate-mirror`.\n[reflections]",
        names.join(", ")
    )?;
    for (joint, r) in skeleton.joints.iter().zip(&reflections) {
        writeln!(
            std::io::stdout(),
            "{} = \"{}\"",
            joint.name,
            serde_json::to_value(r)?.as_str().unwrap_or_default()
        )?;
    }
    Ok(())
}

pub(crate) fn bench(data: &Path, profile: &str, repeat: usize) -> Result<()> {
    let spec = load_profile(profile)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(data)
        .with_context(|| format!("cannot list {}", data.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "bvh"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no .bvh files in {}", data.display());
    }
    let texts: Vec<String> = files
        .iter()
        .map(std::fs::read_to_string)
        .collect::<std::io::Result<_>>()?;
    let bytes: usize = texts.iter().map(String::len).sum();
    let first = read_bvh(&texts[0]).with_context(|| files[0].display().to_string())?;
    let plan = MirrorPlan::from_profile(&first.skeleton, &spec.bind(&first.skeleton)?)?;
    let (mut parse_s, mut fk_s, mut mirror_s, mut total_s) =
        (f64::INFINITY, f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut frames = 0usize;
    for _ in 0..repeat {
        let (mut p, mut f, mut m) = (0.0, 0.0, 0.0);
        frames = 0;
        for text in &texts {
            let t0 = std::time::Instant::now();
            let bvh = read_bvh(text)?;
            let t1 = std::time::Instant::now();
            let pose = bvh.motion.forward_kinematics();
            let t2 = std::time::Instant::now();
            let mirrored = plan.mirror(&bvh.motion, OffsetPolicy::default());
            let t3 = std::time::Instant::now();
            std::hint::black_box((&pose, &mirrored));
            frames += bvh.motion.num_frames();
            p += (t1 - t0).as_secs_f64();
            f += (t2 - t1).as_secs_f64();
            m += (t3 - t2).as_secs_f64();
        }
        parse_s = parse_s.min(p);
        fk_s = fk_s.min(f);
        mirror_s = mirror_s.min(m);
        total_s = total_s.min(p + f + m);
    }
    let mb = bytes as f64 / 1e6;
    writeln!(
        std::io::stdout(),
        "{} files, {frames} frames, {mb:.1} MB, one thread, best of {repeat}",
        files.len()
    )?;
    writeln!(
        std::io::stdout(),
        "read      {:>10.0} frames/s  {:>7.1} MB/s",
        frames as f64 / parse_s,
        mb / parse_s
    )?;
    writeln!(
        std::io::stdout(),
        "fk        {:>10.0} frames/s",
        frames as f64 / fk_s
    )?;
    writeln!(
        std::io::stdout(),
        "mirror    {:>10.0} frames/s",
        frames as f64 / mirror_s
    )?;
    writeln!(
        std::io::stdout(),
        "read+fk+mirror {:>10.0} frames/s  {:>7.1} MB/s",
        frames as f64 / total_s,
        mb / total_s
    )?;
    Ok(())
}

pub(crate) fn export_bvh(
    path: &Path,
    clip_id: &str,
    output: Option<PathBuf>,
    offline: bool,
    wait: Option<Duration>,
    ui: &Ui,
) -> Result<()> {
    let config = load_checked(path, None)?;
    // The stages read and refresh the dataset's stage cache, which a running build is writing.
    let _lock = motionforge::build::lock::WorkspaceLock::acquire(&config.dataset_dir(), wait)?;
    let (found, ids) = motionforge::build::find_clip(
        &config,
        &BuildOptions {
            offline,
            ..BuildOptions::default()
        },
        clip_id,
    )?;
    let Some((clip, profile)) = found else {
        let hint = motionforge::dataset::near_clip_ids(clip_id, &ids);
        bail!(
            "no clip `{clip_id}` in this build ({} clips){hint}",
            ids.len()
        );
    };
    // The clip as the dataset stores it, so this route and `export-bvh <dataset>` write the same
    // file.
    let motion = motionforge::build::stored_motion(&clip, &profile);
    let text =
        motionforge::motion::write_bvh(&motion).with_context(|| format!("clip `{clip_id}`"))?;
    let path = output.unwrap_or_else(|| crate::cli::browse::default_bvh_path(clip_id));
    motionforge::build::write_atomic(&path, text.as_bytes())?;
    crate::cli::browse::say_bvh_written(&path, &clip.motion, &clip.clip.profile, ui)
}

/// Peak resident memory of this process in kB (Linux `VmHWM`), if readable.
pub(crate) fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

pub(crate) fn bench_write(data: &Path, profile: &str, target_frames: usize) -> Result<()> {
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
/// caption line, once on one thread, then all of them again (remembered by `caption::tokens`).
pub(crate) fn bench_captions(path: &Path) -> Result<()> {
    use motionforge::caption::tokens;
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
         first pass {first:.3} s, {:.0} captions/s; again {again:.3} s, {:.0} captions/s (remembered)",
        captions.len(),
        load * 1e3,
        captions.len() as f64 / first.max(1e-9),
        captions.len() as f64 / again.max(1e-9)
    )?;
    Ok(())
}
