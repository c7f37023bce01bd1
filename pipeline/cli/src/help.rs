//! The `--help` endings the commands share: examples, exit codes, where logs go.

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
