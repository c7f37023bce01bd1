"""bvhio reference for `motionforge bench --build --bvhio` (issue 34).

What it is: the yardstick a small build is measured against. It reads every BVH file of a folder
with bvhio (pinned in requirements-test.txt) and computes every joint's world position in every
frame, on one thread, as a Python user of bvhio would: `readAsHierarchy`, then `loadPose(frame)`
and `PositionWorld` of each joint of `layout()`. The whole of it (reading and positions) is timed.

Usage: bvhio_reference.py FOLDER
Prints one JSON object: files, frames, joints (summed over files), positions (joint-frames
computed), wall_s and cpu_s.
"""

import json
import os
import sys
import time
from importlib.metadata import version

import bvhio


def main(argv):
    if len(argv) != 1:
        sys.exit("usage: bvhio_reference.py FOLDER")
    folder = argv[0]
    files = sorted(
        os.path.join(folder, n) for n in os.listdir(folder) if n.lower().endswith(".bvh")
    )
    frames = joints = positions = 0
    checksum = 0.0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for path in files:
        root = bvhio.readAsHierarchy(path)
        layout = [joint for joint, _, _ in root.layout()]
        count = len(root.Keyframes)
        for frame in range(count):
            root.loadPose(frame)
            for joint in layout:
                p = joint.PositionWorld
                checksum += p.y
        frames += count
        joints += len(layout)
        positions += count * len(layout)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    print(
        json.dumps(
            {
                "files": len(files),
                "frames": frames,
                "joints": joints,
                "positions": positions,
                "wall_s": wall,
                "cpu_s": cpu,
                "bvhio": version("bvhio"),
                "checksum": checksum,
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1:])
