//! The `motionforge` command: argument parsing and human output over the library.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Result;
use clap::{Parser, Subcommand};

use motionforge::build::{BuildOptions, Stage, build};
use motionforge::config::{Config, DEFAULT_CONFIG};
use motionforge::motion::ProfileSpec;
use motionforge::progress::ProgressSink;
use motionforge::terminal::{BarProgress, LogOptions, LogProgress};

mod cli;
use cli::bench_build::{BuildBench, bench_build};
use cli::labels::{LabelsCommand, PromptCommand, labels_command, prompt_command};
use cli::session::{PlanSessionArgs, parse_capture, plan_session};
use cli::summary::{counts, print_plan, print_report, print_status};
use cli::tools::{bench, bench_write, calibrate_mirror, export_bvh, mirror_text};

// A build makes and frees many small values on every core (clip texts, decoded cache entries,
// Parquet pages); with mimalloc's per-thread heaps a full build of Bandai Namco 2 took about 5%
// less time and CPU than with glibc's allocator, for about 40 MB more peak memory
// (docs/performance.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Exit codes, shown after `--help` and documented in docs/reference.md (a macro so that
/// commands can put their examples before it with `concat!`).
macro_rules! exit_codes {
    () => {
        "\
Exit codes:
  0  success (including a build with rejected inputs, unless --strict)
  1  failure: a file that cannot be read or written (disk full, no permission), another
     build holding the dataset folder (see --wait), an LLM stage that cannot run
  2  usage or config error: bad arguments, a config that is missing, does not parse or
     fails its checks, or names files that do not exist (`motionforge config check`)
  3  build --strict finished, but some inputs were rejected (see rejects.jsonl)
  4  build finished with 0 clips: every capture was rejected or every segment dropped
     (see rejects.jsonl and build-report.json)

Logging: progress and log lines go to standard error (bars on a terminal, plain lines
otherwise, JSON lines with --json); results go to standard output."
    };
}

/// A command's `--help` ending: its examples, then the exit codes.
macro_rules! examples_then_exit_codes {
    ($examples:literal) => {
        concat!("Examples:\n", $examples, "\n\n", exit_codes!())
    };
}

/// A command's `--help` ending: its examples.
macro_rules! examples {
    ($examples:literal) => {
        concat!("Examples:\n", $examples)
    };
}

/// Examples and exit codes of `plan-session`.
const PLAN_SESSION_HELP: &str = "\
Examples:
  # a session for the living room, balanced only within itself
  motionforge plan-session --scene schemas/scenes/living-room.toml --seed 7 -o sessions
  # steered toward what the built dataset lacks, under a name of your choice
  motionforge plan-session --scene schemas/scenes/living-room.toml --seed 8 \\
      --dataset out/demo --capture living-room-0008 -o sessions

Exit codes:
  0  success
  1  a file that cannot be read or written (the dataset's shards, the output folder)
  2  a scene that does not parse, fails its checks, or has no valid session";
const CLIPS_EXAMPLES: &str = "\
Examples:
  motionforge clips out/demo --type wave
  motionforge clips out/demo --kind synthetic --split train --limit 5 --json";

const PREVIEW_EXAMPLES: &str = "\
Examples:
  motionforge preview out/demo --clip 'cmu/01_01:1207-2407' --with mirror
  motionforge preview out/demo --kind synthetic --limit 3 --with sources -o /tmp/pairs";

const EXPORT_BVH_EXAMPLES: &str = "\
Examples:
  motionforge export-bvh out/demo --clip 'cmu/01_01:1207-2407:m' -o jump-mirrored.bvh
  motionforge export-bvh --config fixtures/demo.toml --clip 'cmu/01_01:1207-2407'";

/// Build text-to-motion training sets from mocap captures: segment, mirror, label, compose,
/// and write sharded Parquet with statistics for papers.
#[derive(Parser)]
#[command(
    name = "motionforge",
    version,
    about,
    long_about = None,
    propagate_version = true,
    after_help = examples_then_exit_codes!(
        "  motionforge build --config fixtures/demo.toml     # the demo dataset into out/demo/
  motionforge status --config fixtures/demo.toml    # what is built, rows per split"
    )
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Print only warnings and errors (no progress, no build summary).
    #[arg(long, short, global = true, conflicts_with = "verbose")]
    quiet: bool,
    /// Log more: -v adds debug lines (stage starts, timings, fields), -vv trace lines, -vvv
    /// dependencies' lines too.
    #[arg(long, short, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Machine-readable output: log lines as JSON objects on standard error, and results (the
    /// build report, label scores, config check) as JSON on standard output.
    #[arg(long, global = true)]
    json: bool,
}

/// `--wait` values: `30s`, `5m`, `1h 30m`, or bare seconds.
fn parse_wait(text: &str) -> Result<Duration, String> {
    if let Ok(seconds) = text.trim().parse::<u64>() {
        return Ok(Duration::from_secs(seconds));
    }
    humantime::parse_duration(text.trim())
        .map_err(|e| format!("{e}; expected a duration such as 30s, 5m or 1h"))
}

/// What `build` and `run` share.
#[derive(clap::Args)]
struct BuildArgs {
    /// Build configuration (TOML); relative paths inside resolve against its folder.
    #[arg(long, short, default_value = DEFAULT_CONFIG)]
    config: PathBuf,
    /// Write the dataset here instead of the config's `dataset.output`.
    #[arg(long, short)]
    output: Option<PathBuf>,
    /// Recompute, ignoring cached stage outputs.
    #[arg(long)]
    force: bool,
    /// Exit with code 3 when any input was rejected.
    #[arg(long)]
    strict: bool,
    /// Send no LLM request: LLM stages use cached answers only.
    #[arg(long)]
    offline: bool,
    /// When another build holds the dataset folder, wait this long for it (30s, 5m, 1h)
    /// instead of failing at once.
    #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
    wait: Option<Duration>,
}

#[derive(Subcommand)]
enum Command {
    /// Run every stage of a build: read captures, label, resample, mirror, write the clip table.
    ///
    /// Work whose inputs, config and stage version are unchanged is reused from the output
    /// folder's cache; bad inputs are listed in `rejects.jsonl` and the build goes on.
    #[command(after_help = examples_then_exit_codes!(
        "  motionforge build --config fixtures/demo.toml
  motionforge build --config my.toml --output /data/sets --offline --wait 5m"
    ))]
    Build {
        #[command(flatten)]
        args: BuildArgs,
    },
    /// Check a build configuration without building: every value, and every file it names.
    ///
    /// Prints every problem at once, as `file:line: key: value: expected ...` (exit code 2), or
    /// one line with what the build would read.
    #[command(after_help = examples!(
        "  motionforge config check --config fixtures/demo.toml"
    ))]
    Config {
        #[command(subcommand)]
        command: ConfigCommand,
    },
    /// Remove a built dataset's outputs (shards, card, manifest, report, stage cache), or with
    /// --cache-only only its stage cache.
    ///
    /// Only what a build writes is removed, and only inside `<output>/<name>`; the LLM response
    /// cache and files you put there are kept. Takes the dataset folder's lock, like a build.
    #[command(after_help = examples_then_exit_codes!(
        "  motionforge clean --config fixtures/demo.toml
  motionforge clean --config fixtures/demo.toml --cache-only"
    ))]
    Clean {
        /// Build configuration naming the dataset folder.
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The output folder the dataset was built into with `build --output`.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Remove only the stage cache (`.motionforge/cache`); the next build recomputes every
        /// stage but rewrites no output that would be identical.
        #[arg(long)]
        cache_only: bool,
        /// When a build holds the dataset folder, wait this long for it (30s, 5m, 1h).
        #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
        wait: Option<Duration>,
    },
    /// Run the named stages and every stage they depend on, nothing after them.
    ///
    /// Stages, in order: ingest, segment, label, paraphrase, plan, mirror, compose, write,
    /// report; each depends on all before it. `run segment` reads and cuts every capture and
    /// caches the result; a later `build` reuses it.
    #[command(after_help = examples!(
        "  motionforge run segment --config fixtures/demo.toml      # read and cut every capture
  motionforge run label mirror --config fixtures/demo.toml"
    ))]
    Run {
        /// Stages to run (with their dependencies).
        #[arg(required = true, value_parser = parse_stage)]
        stages: Vec<Stage>,
        #[command(flatten)]
        args: BuildArgs,
    },
    /// Show what a build would run and why (which input, config key or stage version changed),
    /// without running anything.
    #[command(after_help = examples!(
        "  motionforge plan --config fixtures/demo.toml
  motionforge plan --config fixtures/demo.toml --through label"
    ))]
    Plan {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The dataset folder's parent, instead of the config's `dataset.output`.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Plan only up to this stage.
        #[arg(long, value_parser = parse_stage)]
        through: Option<Stage>,
    },
    /// Show each stage's state: fresh or stale, when it last ran and what it did, and the rows of
    /// the written dataset.
    #[command(after_help = examples!(
        "  motionforge status --config fixtures/demo.toml"
    ))]
    Status {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// The dataset folder's parent, instead of the config's `dataset.output`.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
    /// Mirror caption lines: swap left/right and clockwise/counterclockwise, whole words only.
    ///
    /// Reads FILE (or standard input) line by line and writes the mirrored lines to standard
    /// output, e.g. to mirror an existing HumanML3D-style caption set. Common misspellings
    /// (`rigth`, `conterclockwise`) and a side word glued to the word before it
    /// (`degreeleftwards`) are mirrored too; `upright`, `bright` or `leftover` are not.
    #[command(after_help = examples!(
        "  echo 'a person waves with the left hand' | motionforge mirror-text
  motionforge mirror-text captions.txt > captions-mirrored.txt"
    ))]
    MirrorText {
        /// Text file to mirror; standard input when absent.
        file: Option<PathBuf>,
    },
    /// Calibrate a skeleton profile's mirror reflections on captures and print them as TOML.
    ///
    /// Among the per-joint reflections that fit the skeleton's offsets, picks the one whose
    /// mirrored rotations best match the real ones (one roughly symmetric take, e.g. a walk,
    /// is enough). Paste the output into the profile's `[reflections]` table.
    #[command(after_help = examples!(
        "  motionforge calibrate-mirror --profile bandai-namco \\
      ../shared/data/bandai-namco-1/data/dataset-1_walk_normal_001.bvh"
    ))]
    CalibrateMirror {
        /// Bundled profile name (bandai-namco, cmu, smpl-22) or a profile TOML file.
        #[arg(long)]
        profile: String,
        /// BVH captures of that skeleton.
        #[arg(required = true)]
        captures: Vec<PathBuf>,
    },
    /// Write one clip (real, mirrored or synthetic) as a BVH file on its source skeleton, for
    /// inspection in Blender: from a built dataset folder alone (shards and skeletons.json), or
    /// with --config by re-running the build's stages from the captures.
    ///
    /// Both routes write the clip as the dataset stores it (its f32 rotations), so they give the
    /// same file (docs/decisions.md).
    #[command(after_help = EXPORT_BVH_EXAMPLES)]
    ExportBvh {
        /// The dataset folder (`<output>/<name>`, holding data/ and skeletons.json).
        #[arg(conflicts_with = "config")]
        dataset: Option<PathBuf>,
        /// Instead of a dataset folder: the build configuration; stages reuse their cached
        /// outputs (default motionforge.toml when no dataset folder is given).
        #[arg(long, short)]
        config: Option<PathBuf>,
        /// The clip id, as in the table's `clip_id` column.
        #[arg(long)]
        clip: String,
        /// Output file; default `<clip id with / and : replaced>.bvh` in the working folder.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Send no LLM request while re-running stages.
        #[arg(long)]
        offline: bool,
        /// When a build holds the dataset folder (whose stage cache this reads and refreshes),
        /// wait this long for it (30s, 5m, 1h).
        #[arg(long, value_name = "DURATION", value_parser = parse_wait)]
        wait: Option<Duration>,
    },
    /// List a built dataset's clips: id, split, kind, motion type, frames and caption, from its
    /// shards alone, with filters.
    ///
    /// Every filter given must match. `--kind` takes a source kind (real_single, real_pair,
    /// synthetic) or `mirrored` / `original`; `--text` is a case-insensitive substring of the id,
    /// motion type, action, caption, texts or paraphrases.
    #[command(after_help = CLIPS_EXAMPLES)]
    Clips {
        /// The dataset folder (`<output>/<name>`, holding data/).
        dataset: PathBuf,
        #[command(flatten)]
        filter: cli::browse::FilterArgs,
        /// Print a JSON array of the clips' metadata instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Render clips as animated stick figures from a built dataset's shards alone: an animated
    /// GIF and a PNG filmstrip per clip, optionally beside its mirror or a synthetic pair's sources.
    ///
    /// Each clip is drawn in its canonical frame (first frame's pelvis at the origin, facing +y)
    /// by a fixed camera in front of the character, 20 degrees above, over a half-metre ground
    /// grid; bones are coloured by body part (left arm blue, left leg teal, right arm red, right
    /// leg orange, torso dark grey), the pelvis goal is a purple cross, and the caption and clip id
    /// are the title. Files: `<output>/<clip id with / : + as _>.gif` and `.png`.
    #[command(after_help = PREVIEW_EXAMPLES)]
    Preview {
        /// The dataset folder (`<output>/<name>`, holding data/ and skeletons.json).
        dataset: PathBuf,
        /// A clip id (repeat for several); without it, every clip the filters keep.
        #[arg(long)]
        clip: Vec<String>,
        #[command(flatten)]
        filter: cli::browse::FilterArgs,
        /// Draw beside each clip: its mirror (`mirror`) or a synthetic pair's two sources
        /// (`sources`).
        #[arg(long, value_enum, default_value = "none")]
        with: cli::browse::WithArg,
        /// Folder to write the previews into.
        #[arg(long, short, default_value = "previews")]
        output: PathBuf,
        /// Frames per second of the GIF (the clip is resampled to it).
        #[arg(long, default_value_t = 20.0)]
        fps: f64,
        /// Size in pixels of one clip's square drawing.
        #[arg(long, default_value_t = 280)]
        size: u32,
        /// Poses in the filmstrip.
        #[arg(long, default_value_t = 8)]
        strip: usize,
    },
    /// Export a built dataset in another layout, from its shards alone (no rebuild).
    #[command(after_help = examples!(
        "  motionforge export humanml3d --dataset out/demo"
    ))]
    Export {
        #[command(subcommand)]
        command: ExportCommand,
    },
    /// Write the statistics report of a built dataset: tables (LaTeX, Markdown), figures (SVG,
    /// PNG) and stats.json, from its shards and manifest alone.
    #[command(after_help = examples!(
        "  motionforge report out/demo
  motionforge report out/demo --output paper/figures"
    ))]
    Report {
        /// The dataset folder (`<output>/<name>`, holding data/ and manifest.json).
        dataset: PathBuf,
        /// Where to write; default `<dataset>/report`.
        #[arg(long, short)]
        output: Option<PathBuf>,
    },
    /// Plan the next capture session for a scene: the instructions an actor performs, as an
    /// event log to time during the capture and a sheet for the operator.
    ///
    /// A Markov chain over the scene's interactions (LINGO's Motion Planner) emits only
    /// instructions whose requirements hold (posture, place, free or holding hands) and ends in
    /// the scene's end state. With --dataset, it favours the motion types the built dataset has
    /// fewest clips of, toward the scene's target (docs/planner.md). The same scene, dataset and
    /// seed give the same session.
    #[command(after_help = PLAN_SESSION_HELP)]
    PlanSession {
        /// The scene file (TOML; schemas/scene.md, schemas/scenes/living-room.toml).
        #[arg(long)]
        scene: PathBuf,
        /// A built dataset folder (`<output>/<name>`) whose clips per motion type to balance.
        #[arg(long)]
        dataset: Option<PathBuf>,
        /// Seed of the chain.
        #[arg(long)]
        seed: u64,
        /// Folder to write `<capture>.csv` (the event log) and `<capture>.md` (the sheet) into.
        #[arg(long, short, default_value = ".")]
        output: PathBuf,
        /// The capture's name, and so the files' stem; default `<scene name>-<seed>`.
        #[arg(long, value_parser = parse_capture)]
        capture: Option<String>,
    },
    /// Print the clip table schema (columns, types, version) as JSON.
    #[command(after_help = examples!(
        "  motionforge schema > clips.schema.json"
    ))]
    Schema,
    /// Serve an HTTP API that builds the datasets on request and on their `dataset.schedule`,
    /// one build at a time per dataset, with the run history kept across restarts
    /// (docs/service.md). Calls that change state need `Authorization: Bearer <token>`.
    #[command(after_help = examples!(
        "  MOTIONFORGE_TOKEN=$(openssl rand -hex 16) motionforge serve --config fixtures/demo.toml"
    ))]
    Serve {
        /// A dataset's build configuration; repeat to serve several datasets.
        #[arg(long, short, default_value = "motionforge.toml")]
        config: Vec<PathBuf>,
        /// Address to listen on.
        #[arg(long, default_value = motionforge::serve::DEFAULT_BIND)]
        bind: String,
        /// Folder of the run history database.
        #[arg(long, default_value = motionforge::serve::DEFAULT_STATE_DIR)]
        state: PathBuf,
        /// Environment variable holding the bearer token (required: the service will not start
        /// without it).
        #[arg(long, default_value = motionforge::serve::DEFAULT_TOKEN_ENV)]
        token_env: String,
    },
    /// Run one build for `motionforge serve`, in a process of its own (the service starts it;
    /// docs/service.md describes the protocol).
    #[command(name = "serve-build", hide = true)]
    ServeBuild {
        /// The job file the service wrote.
        #[arg(long)]
        job: PathBuf,
    },
    /// Work with prompt templates.
    #[command(after_help = examples!(
        "  motionforge prompt render part_labels --text 'a person kicks with the right leg'"
    ))]
    Prompt {
        #[command(subcommand)]
        command: PromptCommand,
    },
    /// Body-part labels: import existing LLM answers, evaluate labellers.
    #[command(after_help = examples!(
        "  motionforge labels eval --gold ../shared/data/sinc/part-labels-gold-dev.json"
    ))]
    Labels {
        #[command(subcommand)]
        command: LabelsCommand,
    },
    /// Measure BVH read, forward kinematics and mirroring throughput on a folder of captures; or,
    /// with --build, a whole build of the folder stage by stage beside a bare number scan.
    ///
    /// `bench --build` writes a config (file-name labels and sidecars as in fixtures/demo.toml,
    /// mirror and synthetic pairs on, default features, 30 fps) into a temporary folder and runs:
    /// full builds from scratch (wall time per stage), no-op rebuilds, `plan`, and a single-thread
    /// scan that parses every number of the same bytes into f64. It prints the ratio of the build
    /// to the scan, frames/s per core, peak memory, and the stage cache and shard bytes.
    #[command(after_help = examples!(
        "  motionforge bench --repeat 1
  motionforge bench --build --data ../shared/data/bandai-namco-1/data --repeat 1
  motionforge bench --captions ../shared/data/sinc/clean_labels.txt"
    ))]
    Bench {
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
        /// Instead, time the HumanML3D caption tagger (spaCy's network) on the distinct captions
        /// of this text file, one a line, on one thread: captions per second.
        #[arg(long, value_name = "FILE", conflicts_with_all = ["build", "write_frames", "previews"])]
        captions: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum ExportCommand {
    /// A HumanML3D folder (new_joint_vecs, new_joints, joints, texts, Mean/Std, split lists)
    /// that text-to-motion, T2M-GPT, MoMask and their evaluators load as they load HumanML3D.
    ///
    /// Every row becomes SMPL's 22 body joints (by its skeleton profile's [smpl22] table), y up,
    /// 20 fps, and HumanML3D's 263 numbers per frame computed as HumanML3D computes them
    /// (docs/humanml3d.md). Mirrored rows are named M<name>, in their original's split.
    #[command(after_help = examples_then_exit_codes!(
        "  motionforge export humanml3d --dataset out/demo
  motionforge export humanml3d --dataset out/demo --out /data/HumanML3D-demo --force"
    ))]
    Humanml3d {
        /// The dataset folder (`<output>/<name>`, holding data/ and skeletons.json).
        #[arg(long, short)]
        dataset: PathBuf,
        /// The folder to write; default `<dataset>/humanml3d`.
        #[arg(long, short)]
        out: Option<PathBuf>,
        /// Replace the output folder if it exists.
        #[arg(long)]
        force: bool,
        /// A skeleton profile TOML for a skeleton that is not bundled; repeatable.
        #[arg(long, value_name = "TOML")]
        profile: Vec<PathBuf>,
    },
}

#[derive(Subcommand)]
enum ConfigCommand {
    /// Check every value of the config and every file it names; print all problems at once.
    ///
    /// With --probe, also ask the [llm] server for its model list (GET {base_url}/models, at most
    /// 5 s) and fail (exit code 1) when nothing answers.
    #[command(after_help = examples_then_exit_codes!(
        "  motionforge config check --config fixtures/demo.toml
  motionforge config check --config my.toml --probe --json"
    ))]
    Check {
        /// Build configuration (TOML).
        #[arg(long, short, default_value = DEFAULT_CONFIG)]
        config: PathBuf,
        /// Check the dataset folder under this output folder, as `build --output` would.
        #[arg(long, short)]
        output: Option<PathBuf>,
        /// Also try the [llm] endpoint: one GET of its model list.
        #[arg(long)]
        probe: bool,
    },
}

fn main() -> ExitCode {
    ignore_file_size_signal();
    let cli = Cli::parse();
    let ui = Ui::new(&cli);
    let result = run(cli, &ui);
    ui.clear_bars();
    match result {
        Ok(code) => code,
        Err(err) => {
            // A closed pipe (`motionforge mirror-text | head`) is not an error worth reporting.
            if err.chain().any(|e| {
                e.downcast_ref::<std::io::Error>()
                    .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
            }) {
                return ExitCode::SUCCESS;
            }
            let code = exit_code(&err);
            let message = error_message(&err);
            if ui.log.json {
                tracing::error!(exit_code = code, "{message}");
            } else {
                eprintln!("error: {message}");
            }
            ExitCode::from(code)
        }
    }
}

/// Past a file size limit (`ulimit -f`), the kernel sends SIGXFSZ, whose default action kills
/// the process mid-write. Ignored, the write fails with EFBIG instead, which the build reports as
/// "File too large" (exit code 1) after removing its temporary file.
fn ignore_file_size_signal() {
    // SAFETY: setting a signal's disposition to SIG_IGN installs no handler code; it runs before
    // any other thread exists.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

/// How this run reports to whoever started it: log level and form, and progress bars.
struct Ui {
    log: LogOptions,
    bars: Option<Arc<BarProgress>>,
}

impl Ui {
    /// Sets up logging to standard error; bars only when it is a terminal and lines are not
    /// asked for.
    fn new(cli: &Cli) -> Ui {
        let log = LogOptions {
            quiet: cli.quiet,
            verbose: cli.verbose,
            json: cli.json,
        };
        // Commands that print a summary on standard output log finished stages at `debug` only.
        let summary_follows = !log.quiet && !log.json;
        let bars = log.bars(std::io::stderr().is_terminal()).then(|| {
            Arc::new(if summary_follows {
                BarProgress::before_summary()
            } else {
                BarProgress::new()
            })
        });
        let subscriber = match &bars {
            Some(b) => motionforge::terminal::subscriber(&log, b.log_writer()),
            None => motionforge::terminal::subscriber(&log, std::io::stderr),
        };
        // Only fails if a subscriber is already set, and none is: nothing to report.
        let _ = tracing::subscriber::set_global_default(subscriber);
        Ui { log, bars }
    }

    /// Where a build reports its stages.
    fn progress(&self) -> ProgressSink {
        match &self.bars {
            Some(bars) => ProgressSink::new(bars.clone()),
            None if self.status() && !self.log.json => {
                ProgressSink::new(Arc::new(LogProgress::before_summary()))
            }
            None => ProgressSink::new(Arc::new(LogProgress::new())),
        }
    }

    /// Whether status lines (the build summary, "wrote ..." lines) are printed.
    fn status(&self) -> bool {
        !self.log.quiet
    }

    fn clear_bars(&self) {
        if let Some(bars) = &self.bars {
            bars.clear();
        }
    }
}

/// The error and its causes on one line, skipping causes the message already quotes.
fn error_message(err: &anyhow::Error) -> String {
    let mut message = err.to_string();
    for cause in err.chain().skip(1) {
        let text = cause.to_string();
        if !message.contains(&text) {
            message = format!("{message}: {text}");
        }
    }
    message
}

/// 2 for mistakes in the config or what it names (documented exit codes), 1 otherwise.
fn exit_code(err: &anyhow::Error) -> u8 {
    use motionforge::build::BuildError;
    let usage = err.chain().any(|e| {
        e.downcast_ref::<motionforge::config::ConfigError>()
            .is_some()
            || e.downcast_ref::<motionforge::source::SourceError>()
                .is_some()
            || e.downcast_ref::<motionforge::annotate::taxonomy::TaxonomyError>()
                .is_some()
            || e.downcast_ref::<motionforge::motion::profile::ProfileError>()
                .is_some()
            || e.downcast_ref::<motionforge::llm::prompt::PromptError>()
                .is_some()
            || e.downcast_ref::<motionforge::planner::SceneError>()
                .is_some()
            || e.downcast_ref::<motionforge::planner::PlanError>()
                .is_some()
            || matches!(
                e.downcast_ref::<motionforge::build::clean::CleanError>(),
                Some(
                    motionforge::build::clean::CleanError::NotADataset { .. }
                        | motionforge::build::clean::CleanError::Refused(_)
                )
            )
            || e.downcast_ref::<cli::UsageError>().is_some()
            // An output that would replace or write into a folder the user keeps.
            || e.downcast_ref::<motionforge::base::guard::Refused>()
                .is_some()
            || matches!(
                e.downcast_ref::<motionforge::export::ExportError>(),
                Some(
                    motionforge::export::ExportError::Refused(_)
                        | motionforge::export::ExportError::NotAnExport { .. }
                )
            )
            || matches!(
                e.downcast_ref::<motionforge::report::ReportError>(),
                Some(motionforge::report::ReportError::Refused(_))
            )
            || matches!(
                e.downcast_ref::<BuildError>(),
                Some(
                    BuildError::Source(_)
                        | BuildError::Refused(_)
                        | BuildError::Taxonomy(_)
                        | BuildError::Prompt(_)
                        | BuildError::Split(_)
                )
            )
    });
    if usage { 2 } else { 1 }
}

fn run(cli: Cli, ui: &Ui) -> Result<ExitCode> {
    match cli.command {
        Command::Build { args } => return build_command(args, None, ui),
        Command::Run { stages, args } => {
            return build_command(args, stages.iter().copied().max(), ui);
        }
        Command::Plan {
            config,
            output,
            through,
        } => {
            let config = load_checked(&config, output)?;
            let plan = motionforge::build::plan(
                &config,
                &BuildOptions {
                    through,
                    ..BuildOptions::default()
                },
            )?;
            if ui.log.json {
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&plan)?
                )?;
            } else {
                print_plan(&plan)?;
            }
        }
        Command::Status { config, output } => {
            let config = load_checked(&config, output)?;
            let status = motionforge::build::status(&config)?;
            if ui.log.json {
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&status)?
                )?;
            } else {
                print_status(&status)?;
            }
        }
        Command::Config {
            command:
                ConfigCommand::Check {
                    config,
                    output,
                    probe,
                },
        } => config_check(&config, output, probe, ui)?,
        Command::Clean {
            config,
            output,
            cache_only,
            wait,
        } => {
            let mut config = Config::load(&config)?;
            if let Some(output) = output {
                config.dataset.output = std::path::absolute(&output).unwrap_or(output);
            }
            let dir = config.dataset_dir();
            let report = motionforge::build::clean::clean(&dir, cache_only, wait)?;
            let mut out = std::io::stdout().lock();
            if ui.log.json {
                let value = serde_json::json!({
                    "dataset_dir": dir,
                    "removed": report.removed,
                    "bytes": report.bytes,
                    "kept": report.kept,
                });
                writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
            } else if ui.status() {
                if report.removed.is_empty() {
                    writeln!(out, "nothing to clean in {}", dir.display())?;
                } else {
                    writeln!(
                        out,
                        "removed {} ({:.1} MB) from {}",
                        report.removed.join(", "),
                        report.bytes as f64 / 1e6,
                        dir.display()
                    )?;
                }
                if !report.kept.is_empty() {
                    writeln!(out, "kept: {}", report.kept.join(", "))?;
                }
            }
        }
        Command::MirrorText { file } => mirror_text(file.as_deref())?,
        Command::CalibrateMirror { profile, captures } => calibrate_mirror(&profile, &captures)?,
        Command::ExportBvh {
            dataset: Some(dataset),
            clip,
            output,
            ..
        } => cli::browse::export_bvh_from_shards(&dataset, &clip, output, ui)?,
        Command::ExportBvh {
            dataset: None,
            config,
            clip,
            output,
            offline,
            wait,
        } => {
            let config = config.unwrap_or_else(|| PathBuf::from(DEFAULT_CONFIG));
            export_bvh(&config, &clip, output, offline, wait, ui)?
        }
        Command::Clips {
            dataset,
            filter,
            json,
        } => cli::browse::clips(&dataset, &filter, json)?,
        Command::Preview {
            dataset,
            clip,
            filter,
            with,
            output,
            fps,
            size,
            strip,
        } => {
            let options = motionforge::dataset::preview::PreviewOptions {
                fps,
                size,
                strip_frames: strip,
                animate: true,
            };
            cli::browse::preview(&dataset, &clip, &filter, with, &output, &options, ui)?
        }
        Command::Report { dataset, output } => {
            let files = motionforge::report::report_dataset(&dataset, output.as_deref())?;
            if ui.log.json {
                let value = serde_json::json!({
                    "output": output.clone().unwrap_or_else(|| dataset.join("report")),
                    "files": files,
                });
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&value)?
                )?;
            } else if ui.status() {
                writeln!(
                    std::io::stdout(),
                    "wrote {} report files to {}",
                    files.len(),
                    output.unwrap_or_else(|| dataset.join("report")).display()
                )?;
            }
        }
        Command::Export {
            command:
                ExportCommand::Humanml3d {
                    dataset,
                    out,
                    force,
                    profile,
                },
        } => {
            let mut profiles = Vec::new();
            for path in profile {
                let text = std::fs::read_to_string(&path)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
                profiles.push(ProfileSpec::from_toml(&path.display().to_string(), &text)?);
            }
            let out =
                out.unwrap_or_else(|| dataset.join(motionforge::export::humanml3d::DEFAULT_DIR));
            let options = motionforge::export::ExportOptions { force, profiles };
            let summary = motionforge::export::export_humanml3d(&dataset, &out, &options)?;
            if ui.status() {
                let mut stdout = std::io::stdout();
                writeln!(
                    stdout,
                    "exported {} of {} clips ({} rows of 263) to {}",
                    summary.exported,
                    summary.clips,
                    summary.rows,
                    out.display()
                )?;
                for s in &summary.skipped {
                    writeln!(stdout, "  skipped {}: {}", s.clip_id, s.reason)?;
                }
                if !summary.filtered_by_loaders.is_empty() {
                    writeln!(
                        stdout,
                        "  {} clips are outside 40 to 199 rows: HumanML3D's loaders drop them (listed in export.json)",
                        summary.filtered_by_loaders.len()
                    )?;
                }
            }
        }
        Command::Prompt { command } => prompt_command(command)?,
        Command::Serve {
            config,
            bind,
            state,
            token_env,
        } => motionforge::serve::run(&motionforge::serve::ServeCommand {
            configs: config,
            bind,
            state_dir: state,
            token_env,
            // Builds run in processes of this very binary, so service and builds agree.
            builder: std::env::current_exe()
                .map_err(|e| anyhow::anyhow!("cannot find this program's own path: {e}"))?,
        })?,
        Command::ServeBuild { job } => return Ok(motionforge::serve::worker::main(&job)),
        Command::Labels { command } => labels_command(command, ui.log.json)?,
        Command::PlanSession {
            scene,
            dataset,
            seed,
            output,
            capture,
        } => plan_session(
            PlanSessionArgs {
                scene,
                dataset,
                seed,
                output,
                capture,
            },
            ui.log.json,
            ui.status(),
        )?,
        Command::Schema => writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&motionforge::io::schema::clip_schema_json())?
        )?,
        Command::Bench {
            data,
            profile,
            repeat,
            write_frames,
            build,
            copies,
            keep,
            pattern,
            threads,
            previews,
            captions,
        } => match write_frames {
            _ if captions.is_some() => {
                cli::tools::bench_captions(captions.as_deref().unwrap_or(Path::new(".")))?
            }
            _ if previews.is_some() => {
                cli::browse::bench_previews(previews.as_deref().unwrap_or(Path::new(".")))?
            }
            Some(frames) => bench_write(&data, &profile, frames)?,
            None if build => bench_build(
                &BuildBench {
                    data,
                    profile,
                    repeat,
                    copies,
                    keep,
                    pattern,
                    threads: threads.map(usize::from),
                },
                ui,
            )?,
            None => bench(&data, &profile, repeat.max(1))?,
        },
    }
    Ok(ExitCode::SUCCESS)
}

/// Loads a config for a build: its values and every file it names, all problems at once.
/// `build`, or `run` up to `through`: the build with logs, progress and the summary.
fn build_command(args: BuildArgs, through: Option<Stage>, ui: &Ui) -> Result<ExitCode> {
    let config = load_checked(&args.config, args.output)?;
    let dataset_dir = config.dataset_dir();
    tracing::info!(
        dataset = %config.dataset.name,
        folder = %dataset_dir.display(),
        "building {} into {}",
        config.dataset.name,
        dataset_dir.display()
    );
    let started = std::time::Instant::now();
    let report = build(
        &config,
        &BuildOptions {
            force: args.force,
            offline: args.offline,
            progress: ui.progress(),
            lock_wait: args.wait,
            through,
        },
    )?;
    ui.clear_bars();
    let seconds = started.elapsed().as_secs_f64();
    // The summary on standard output (or the JSON report) says this too; `-v` shows the line.
    tracing::debug!(
        clips = report.clips,
        captures = report.captures,
        rejects = report.rejects.len(),
        seconds,
        "built {} clips from {} captures in {seconds:.1} s",
        report.clips,
        report.captures
    );
    if !report.rejects.is_empty() {
        tracing::warn!(
            rejects = report.rejects.len(),
            "{} inputs rejected ({}), listed in {}",
            report.rejects.len(),
            counts(&report.rejects_by_reason),
            dataset_dir.join(motionforge::build::REJECTS_FILE).display()
        );
    }
    if ui.log.json {
        writeln!(
            std::io::stdout(),
            "{}",
            serde_json::to_string_pretty(&report)?
        )?;
    } else if ui.status() {
        print_report(&report, seconds)?;
    }
    if report.clips == 0 && through.is_none_or(|t| t >= Stage::Write) {
        let dropped: usize = report.drops_by_reason.values().sum();
        tracing::error!(
            captures = report.captures,
            rejects = report.rejects.len(),
            dropped,
            "0 clips: {}; see {} and {}",
            empty_reason(report.captures, report.rejects.len(), dropped),
            dataset_dir.join(motionforge::build::REJECTS_FILE).display(),
            dataset_dir.join(motionforge::build::REPORT_FILE).display()
        );
        return Ok(ExitCode::from(EXIT_EMPTY));
    }
    if args.strict && !report.rejects.is_empty() {
        return Ok(ExitCode::from(3));
    }
    Ok(ExitCode::SUCCESS)
}

/// Exit code of a build that finished but wrote no row (every capture rejected or dropped).
const EXIT_EMPTY: u8 = 4;

/// Why a build has no rows, in words.
fn empty_reason(captures: usize, rejects: usize, dropped: usize) -> String {
    let captures_word = if captures == 1 { "capture" } else { "captures" };
    match (captures, rejects, dropped) {
        (0, _, _) => "no capture was found".to_string(),
        (c, r, 0) if r >= c => format!("every capture was rejected ({r} of {c} {captures_word})"),
        (c, r, d) => format!(
            "{r} of {c} {captures_word} rejected and every segment of the others dropped ({d} segments)"
        ),
    }
}

fn load_checked(path: &Path, output: Option<PathBuf>) -> Result<Config> {
    let (config, summary) = Config::load_checked(path, output)?;
    for warning in &summary.warnings {
        tracing::warn!("{warning}");
    }
    Ok(config)
}

/// `config check --probe`: one GET of the endpoint's model list; `None` without an `[llm]` section.
fn probe_llm(config: &Config) -> Result<Option<(String, motionforge::llm::client::Probe)>> {
    let Some(llm) = &config.llm else {
        return Ok(None);
    };
    let client = motionforge::llm::client::LlmClient::new(llm.clone())?;
    let probe = client.probe()?;
    let served = if probe.models.is_empty() {
        String::new()
    } else {
        format!("; serves {}", probe.models.join(", "))
    };
    let line = format!(
        "LLM {} at {}: answered GET {} with HTTP {} in {} ms{served}",
        llm.model,
        llm.root(),
        probe.url,
        probe.status,
        probe.elapsed.as_millis()
    );
    Ok(Some((line, probe)))
}

fn config_check(path: &Path, output: Option<PathBuf>, probe: bool, ui: &Ui) -> Result<()> {
    let (config, summary) = match Config::load_checked(path, output) {
        Ok(ok) => ok,
        Err(err) => {
            if ui.log.json {
                let problems: Vec<serde_json::Value> = match &err {
                    motionforge::config::ConfigError::Invalid { problems, .. } => problems
                        .iter()
                        .map(|p| {
                            serde_json::json!({
                                "key": p.key, "value": p.value, "expected": p.expected, "line": p.line,
                            })
                        })
                        .collect(),
                    other => vec![serde_json::json!({ "message": other.to_string() })],
                };
                let value =
                    serde_json::json!({ "ok": false, "config": path, "problems": problems });
                writeln!(
                    std::io::stdout(),
                    "{}",
                    serde_json::to_string_pretty(&value)?
                )?;
            }
            return Err(err.into());
        }
    };
    for warning in &summary.warnings {
        tracing::warn!("{warning}");
    }
    let probed = if probe { probe_llm(&config)? } else { None };
    let captures: usize = summary.captures.iter().sum();
    let mut out = std::io::stdout().lock();
    if ui.log.json {
        let sources: Vec<serde_json::Value> = config
            .sources
            .iter()
            .zip(&summary.captures)
            .map(|(s, n)| serde_json::json!({ "name": s.name, "captures": n }))
            .collect();
        let value = serde_json::json!({
            "ok": true,
            "config": path,
            "dataset": config.dataset.name,
            "dataset_dir": config.dataset_dir(),
            "sources": sources,
            "warnings": summary.warnings,
            "probe": probed.as_ref().map(|(_, p)| serde_json::json!({
                "url": p.url,
                "status": p.status,
                "millis": p.elapsed.as_millis() as u64,
                "models": p.models,
            })),
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else if ui.status() {
        let splits: Vec<String> = config
            .splits
            .ratios
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        writeln!(
            out,
            "config {}: OK: dataset `{}` into {}, {} sources with {captures} captures, {} fps, seed {}, splits {}, LLM {}",
            path.display(),
            config.dataset.name,
            config.dataset_dir().display(),
            config.sources.len(),
            config.dataset.fps,
            config.dataset.seed,
            splits.join(" / "),
            config
                .llm
                .as_ref()
                .map(|l| format!("{} at {}", l.model, l.base_url))
                .unwrap_or_else(|| "none".into())
        )?;
        match (&probed, probe) {
            (Some((line, _)), _) => writeln!(out, "{line}")?,
            (None, true) => writeln!(out, "no [llm] section: nothing to probe")?,
            (None, false) => {}
        }
    }
    Ok(())
}

fn parse_stage(s: &str) -> std::result::Result<Stage, String> {
    s.parse()
}
