#!/usr/bin/env bash
# Writes generated AMASS data for `motionforge bench --amass`: a body model folder with the real
# keys and shapes (SMPL-H, 52 joints, 6,890 vertices) and N hard links to one 2,000-frame 120 fps
# SMPL-H sequence of real motion (a HumanML3D clip turned into SMPL-H rotations by the project's
# inverse kinematics), from the tests' generator. AMASS and the SMPL models may not be
# redistributed: with the real ones, point the bench at them instead.
#
#   scripts/amass-bench-data.sh OUT [N]      # N defaults to 2000
#   motionforge bench --amass OUT/npz --body-model OUT/models --build --repeat 1
set -euo pipefail
out="${1:?usage: scripts/amass-bench-data.sh OUT [N]}"
count="${2:-2000}"
cd "$(dirname "$0")/.."
mkdir -p "$out"
out="$(cd "$out" && pwd)"
MOTIONFORGE_PYTHON="$(scripts/python-env.sh)"
export MOTIONFORGE_PYTHON
MOTIONFORGE_AMASS_KEEP="$out" cargo test --test builds \
    amass::reading_and_forward_kinematics_frames_per_second -- --ignored --exact
mkdir -p "$out/npz"
# Each link is read, hashed and put through every stage on its own; the shards compress better
# than different captures would (docs/performance.md says so beside the figures).
for i in $(seq -f "%04g" 1 "$count"); do
    ln -f "$out/long_poses.npz" "$out/npz/take_${i}_poses.npz"
done
echo "wrote $count sequences under $out/npz and the body model under $out/models"
