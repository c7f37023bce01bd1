#!/usr/bin/env bash
# The README's test command: sets up everything the tests need on a fresh machine, then runs them.
# Arguments go to `cargo test` (for example `scripts/test.sh --test loaders`).
set -euo pipefail
cd "$(dirname "$0")/.."
# LaTeX (Debian packages) for the report test's two-column compile of tables.tex; without it
# (not root, no apt-get) that check says it was skipped.
if ! command -v pdflatex >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    texlive-latex-base texlive-latex-recommended
fi
# tests/common runs the independent readers (pyarrow, polars, datasets, duckdb, spaCy) with this
# Python instead of whatever `python3` is on PATH.
MOTIONFORGE_PYTHON="$(scripts/python-env.sh)"
export MOTIONFORGE_PYTHON
cargo test --workspace "$@"
