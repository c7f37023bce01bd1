#!/usr/bin/env bash
# Installs the Debian packages the tests drive when they are missing: headless Chromium and its
# driver (tests/browser.rs), LaTeX (tests/report.rs compiles tables.tex and figures.tex in a
# two-column document) and poppler-utils (tests/report.rs rasterises that page with pdftoppm and
# finds the figures' labels with pdftotext), and util-linux's `script` (tests/cli.rs runs `clips` on
# a pseudo-terminal to check it fits the terminal's width). Needs root or sudo; on a machine without apt-get it
# says what to install instead.
set -euo pipefail
missing=()
command -v chromium >/dev/null || missing+=(chromium)
command -v chromedriver >/dev/null || missing+=(chromium-driver)
command -v pdflatex >/dev/null || missing+=(texlive-latex-base texlive-latex-recommended)
{ command -v pdftoppm >/dev/null && command -v pdftotext >/dev/null; } || missing+=(poppler-utils)
command -v script >/dev/null || missing+=(bsdutils)
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null; then
  echo "scripts/system-packages.sh: install ${missing[*]} (or your system's equivalents) with your package manager; the browser and report tests need them" >&2
  exit 1
fi
sudo=()
[ "$(id -u)" -eq 0 ] || sudo=(sudo)
echo "installing ${missing[*]} for the tests (first run only)" >&2
"${sudo[@]}" apt-get update -qq >&2
DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
