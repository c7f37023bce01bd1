#!/usr/bin/env bash
# Installs the Debian packages the tests drive (tests/browser.rs: headless Chromium and its
# driver) when they are missing. Needs root or sudo; on a machine without apt-get it says what to
# install instead of guessing.
set -euo pipefail
packages=(chromium chromium-driver)
if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then
  exit 0
fi
if ! command -v apt-get >/dev/null; then
  echo "scripts/system-packages.sh: install ${packages[*]} (Chromium and ChromeDriver) with your package manager; tests/browser.rs needs them" >&2
  exit 1
fi
sudo=()
[ "$(id -u)" -eq 0 ] || sudo=(sudo)
echo "installing ${packages[*]} for the browser test (first run only)" >&2
"${sudo[@]}" apt-get update -qq >&2
DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq "${packages[@]}" >&2
