#!/usr/bin/env bash
# The README's test command: sets up everything the tests need on a fresh machine, then runs them.
# Arguments go to `cargo test` (for example `scripts/test.sh --test loaders`).
set -euo pipefail
cd "$(dirname "$0")/.."
# tests/common runs the independent readers (pyarrow, polars, datasets, duckdb, spaCy) with this
# Python instead of whatever `python3` is on PATH.
scripts/system-packages.sh
MOTIONFORGE_PYTHON="$(scripts/python-env.sh)"
export MOTIONFORGE_PYTHON
cargo test --workspace "$@"
