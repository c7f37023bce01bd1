#!/usr/bin/env bash
# The README's test command: sets up everything the tests need on a fresh machine, then runs them.
# Arguments go to `cargo test` (for example `scripts/test.sh --test builds loaders::`).
set -euo pipefail
cd "$(dirname "$0")/.."
# Debian packages the tests drive (Chromium, LaTeX), when missing.
scripts/system-packages.sh
# tests/common runs the independent readers (pyarrow, polars, datasets, duckdb, spaCy, selenium)
# with this Python instead of whatever `python3` is on PATH.
MOTIONFORGE_PYTHON="$(scripts/python-env.sh)"
export MOTIONFORGE_PYTHON
cargo test --workspace "$@"
