//! `mirror-text` and `calibrate-mirror`: mirroring captions, and calibrating a profile's
//! mirror reflections on captures.

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use motionforge::motion::{ProfileSpec, calibrate, read_bvh};

/// Mirror caption lines: swap left/right and clockwise/counterclockwise, whole words only.
///
/// Reads FILE (or standard input) line by line and writes the mirrored lines to standard
/// output, e.g. to mirror an existing HumanML3D-style caption set. Common misspellings
/// (`rigth`, `conterclockwise`) and a side word glued to the word before it
/// (`degreeleftwards`) are mirrored too; `upright`, `bright` or `leftover` are not.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  echo 'a person waves with the left hand' | motionforge mirror-text
  motionforge mirror-text captions.txt > captions-mirrored.txt"
))]
pub(crate) struct MirrorTextArgs {
    /// Text file to mirror; standard input when absent.
    file: Option<PathBuf>,
}

/// Calibrate a skeleton profile's mirror reflections on captures and print them as TOML.
///
/// Among the per-joint reflections that fit the skeleton's offsets, picks the one whose
/// mirrored rotations best match the real ones (one roughly symmetric take, e.g. a walk,
/// is enough). Paste the output into the profile's `[reflections]` table.
#[derive(clap::Args)]
#[command(after_help = examples!(
    "  motionforge calibrate-mirror --profile bandai-namco \\
      ../shared/data/bandai-namco-1/data/dataset-1_walk_normal_001.bvh"
))]
pub(crate) struct CalibrateMirrorArgs {
    /// Bundled profile name (bandai-namco, cmu, smpl-22) or a profile TOML file.
    #[arg(long)]
    profile: String,
    /// BVH captures of that skeleton.
    #[arg(required = true)]
    captures: Vec<PathBuf>,
}

/// `motionforge mirror-text`.
pub(crate) fn mirror_text(args: MirrorTextArgs) -> Result<ExitCode> {
    let file = args.file.as_deref();
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
    Ok(ExitCode::SUCCESS)
}

/// A bundled profile by name, or a profile TOML file.
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

/// `motionforge calibrate-mirror`.
pub(crate) fn calibrate_mirror(args: CalibrateMirrorArgs) -> Result<ExitCode> {
    let (profile, captures) = (args.profile.as_str(), args.captures.as_slice());
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
    Ok(ExitCode::SUCCESS)
}
