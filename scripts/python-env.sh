#!/usr/bin/env bash
# Prints the path of a Python with the tests' independent readers (requirements-test.txt), making
# its virtual environment first if needed. The environment lives outside the repository, keyed by
# the requirements file's hash, so a fresh clone (CI) reuses it and a changed pin makes a new one.
# MOTIONFORGE_VENV names another place for it.
set -euo pipefail
cd "$(dirname "$0")/.."
req=requirements-test.txt
hash=$(sha256sum "$req" | cut -c1-16)
venv="${MOTIONFORGE_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/motionforge/venv-$hash}"
# `.complete` is written last, so an install that was interrupted is redone rather than trusted.
if [ ! -f "$venv/.complete" ]; then
  echo "setting up $venv from $req (first run only; downloads from PyPI)" >&2
  rm -rf "$venv"
  python3 -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$req" >&2
  touch "$venv/.complete"
fi
echo "$venv/bin/python"
