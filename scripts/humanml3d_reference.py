"""NumPy reference of HumanML3D's `process_file` for `motionforge bench --export` (issue 34).

What it is: an independent NumPy implementation, written for motionforge from HumanML3D's
published method (Guo et al. 2022, `motion_representation.ipynb`), of the computation that turns
22 SMPL body-joint positions (y up, metres, 20 fps) into the 263 numbers per frame: uniform
skeleton (inverse kinematics to bone rotations, forward kinematics with the reference bone
lengths), floor, origin, face +Z, foot contacts, root rotation (smoothed facing) and velocity,
ric positions, cont6d rotations and local velocities. It is not HumanML3D's code. The quirks
motionforge reproduces (docs/humanml3d.md) are reproduced here too, so both compute the same rows.

The bench runs it on one thread over the `joints/<name>.npy` arrays of an export it just wrote
(the same joint sequences the export converted), timing the computation only (the arrays are
loaded first), and compares every row with the export's `new_joint_vecs/<name>.npy`.

Usage: humanml3d_reference.py EXPORT_DIR [--repeat N]
Prints one JSON object: clips, frames, rows, wall_s and cpu_s (best of N passes), and the
agreement with the export (max_abs_diff, rows_compared, shape_mismatches).
"""

import json
import os
import sys
import time

# One thread: the reference is timed as HumanML3D runs it, one process per core at most.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

NUM_JOINTS = 22
PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]
CHAINS = [
    [0, 2, 5, 8, 11],
    [0, 1, 4, 7, 10],
    [0, 3, 6, 9, 12, 15],
    [9, 14, 17, 19, 21],
    [9, 13, 16, 18, 20],
]
# Rest direction of each bone from its parent (SMPL's T pose, y up, facing +z).
REST = np.array(
    [
        [0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, -1, 0], [0, 1, 0],
        [0, -1, 0], [0, -1, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1], [0, 1, 0], [1, 0, 0],
        [-1, 0, 0], [0, 0, 1], [0, -1, 0], [0, -1, 0], [0, -1, 0], [0, -1, 0], [0, -1, 0],
        [0, -1, 0],
    ],
    dtype=np.float64,
)
# Bone lengths every clip is retargeted to: frame 0 of HumanML3D clip 000021, float32.
TARGET_LENGTHS = np.array(
    [
        0.0, 0.10307393223047256, 0.10988342016935349, 0.13156823813915253,
        0.3936232626438141, 0.3901881277561188, 0.14319021999835968, 0.4324330985546112,
        0.42564353346824646, 0.05736473575234413, 0.14338184893131256, 0.14941902458667755,
        0.21936005353927612, 0.13748674094676971, 0.14338286221027374, 0.1030392199754715,
        0.13161404430866241, 0.12298443913459778, 0.25683990120887756, 0.26309171319007874,
        0.26601195335388184, 0.2698764503002167,
    ]
)
LEG = [5, 8]  # right knee and ankle bones: their lengths set the scale
FEET_L, FEET_R = [7, 10], [8, 11]
CONTACT_THRESHOLD = 0.002
FACING_SIGMA = 20.0
UP = np.array([0.0, 1.0, 0.0])
FORWARD = np.array([0.0, 0.0, 1.0])


# ---- quaternions (w, x, y, z), broadcasting over leading axes ----------------------------------

def qmul(q, r):
    w1, x1, y1, z1 = np.moveaxis(q, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(r, -1, 0)
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def qinv(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def qrot(q, v):
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + q[..., :1] * t + np.cross(u, t)


def qbetween(v0, v1):
    """Shortest-arc rotation taking v0 to v1; a half turn about a perpendicular axis where they
    are opposite (the published formula divides zero by zero there)."""
    v0, v1 = np.broadcast_arrays(v0, v1)
    axis = np.cross(v0, v1)
    w = np.sqrt((v0 ** 2).sum(-1) * (v1 ** 2).sum(-1)) + (v0 * v1).sum(-1)
    q = np.concatenate([w[..., None], axis], axis=-1)
    norm = np.sqrt((q ** 2).sum(-1))
    scale = np.sqrt((v0 ** 2).sum(-1) * (v1 ** 2).sum(-1))
    degenerate = norm <= 1e-12 * np.maximum(scale, np.finfo(float).tiny)
    if np.any(degenerate):
        perp = np.cross(v0, UP)
        small = (perp ** 2).sum(-1) < 1e-24
        perp[small] = np.cross(v0[small], np.array([1.0, 0.0, 0.0]))
        perp = perp / np.sqrt((perp ** 2).sum(-1, keepdims=True))
        flip = np.concatenate([np.zeros_like(w)[..., None], perp], axis=-1)
        q = np.where(degenerate[..., None], flip, q)
        norm = np.where(degenerate, 1.0, norm)
    return q / norm[..., None]


def cont6d(q):
    """First two columns of each rotation matrix."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y),
            2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x),
        ],
        axis=-1,
    )


def normalize(v):
    return v / np.sqrt((v ** 2).sum(-1, keepdims=True))


def gaussian_nearest(values, sigma):
    """scipy.ndimage.gaussian_filter1d(values, sigma, axis=0, mode='nearest'), truncate 4."""
    radius = int(4.0 * sigma + 0.5)
    x = np.arange(-radius, radius + 1)
    weights = np.exp(-0.5 / (sigma * sigma) * x * x)
    weights /= weights.sum()
    padded = np.pad(values, ((radius, radius), (0, 0)), mode="edge")
    return np.stack(
        [np.convolve(padded[:, c], weights, mode="valid") for c in range(values.shape[1])],
        axis=-1,
    )


# ---- process_file ---------------------------------------------------------------------------------

def inverse_kinematics(joints, across_hips, smooth):
    """Per-joint local rotations along each chain, each chain starting from the root rotation;
    the root's rotation faces the body towards +z (first frame: identity)."""
    across = (joints[:, across_hips[0]] - joints[:, across_hips[1]]) + (
        joints[:, 17] - joints[:, 16]
    )
    forward = np.cross(UP, normalize(across))
    if smooth:
        forward = gaussian_nearest(forward, FACING_SIGMA)
    root = qbetween(normalize(forward), FORWARD)
    root[0] = [1.0, 0.0, 0.0, 0.0]
    quats = np.zeros(joints.shape[:-1] + (4,))
    quats[:, 0] = root
    for chain in CHAINS:
        r = root
        for parent, child in zip(chain[:-1], chain[1:]):
            bone = normalize(joints[:, child] - joints[:, parent])
            local = qmul(qinv(r), qbetween(REST[child], bone))
            quats[:, child] = local
            r = qmul(r, local)
    return quats


def forward_kinematics(quats, root_positions, lengths):
    joints = np.zeros(quats.shape[:-1] + (3,))
    joints[:, 0] = root_positions
    for chain in CHAINS:
        r = quats[:, 0]
        for parent, child in zip(chain[:-1], chain[1:]):
            r = qmul(r, quats[:, child])
            joints[:, child] = qrot(r, REST[child] * lengths[child]) + joints[:, parent]
    return joints


def uniform_skeleton(positions):
    """Retarget to the reference bone lengths: IK on the clip, FK with the target offsets, the
    root path scaled by the ratio of leg lengths (source lengths in float32, from frame 0)."""
    first = positions[0]
    source = np.array(
        [0.0] + [np.linalg.norm(first[j] - first[PARENTS[j]]) for j in range(1, NUM_JOINTS)]
    ).astype(np.float32).astype(np.float64)
    scale = TARGET_LENGTHS[LEG].sum() / source[LEG].sum()
    quats = inverse_kinematics(positions, (2, 1), smooth=False)
    return forward_kinematics(quats, positions[:, 0] * scale, TARGET_LENGTHS)


def process(positions):
    """(T, 22, 3) positions -> (T - 1, 263) float32 rows."""
    positions = uniform_skeleton(positions)
    positions[..., 1] -= positions[..., 1].min()
    positions -= positions[0, 0] * np.array([1.0, 0.0, 1.0])
    p0 = positions[0]
    across = normalize((p0[2] - p0[1]) + (p0[17] - p0[16]))
    face = qbetween(normalize(np.cross(UP, across)), FORWARD)
    # From here the published method holds positions in float32.
    positions = qrot(face, positions).astype(np.float32).astype(np.float64)
    global_positions = positions

    p32 = positions.astype(np.float32)
    step = p32[1:] - p32[:-1]
    squared = step[..., 0] ** 2 + step[..., 1] ** 2 + step[..., 2] ** 2
    contacts = (squared < np.float32(CONTACT_THRESHOLD)).astype(np.float32)
    feet_l, feet_r = contacts[:, FEET_L], contacts[:, FEET_R]

    # The published IK unpacks its face joints as (left hip, right hip, ...): across is
    # joint 1 minus joint 2 here (reproduced; evaluators were trained on it).
    quats = inverse_kinematics(positions, (1, 2), smooth=True)
    r_rot = quats[:, 0]
    r_velocity = qmul(r_rot[1:], qinv(r_rot[:-1]))
    velocity = qrot(r_rot[1:], positions[1:, 0] - positions[:-1, 0])

    ric = positions.copy()
    ric[..., 0] -= positions[:, 0:1, 0]
    ric[..., 2] -= positions[:, 0:1, 2]
    ric = qrot(np.repeat(r_rot[:, None], NUM_JOINTS, axis=1), ric)

    rows = len(positions) - 1
    root_data = np.concatenate(
        [
            np.arcsin(np.clip(r_velocity[:, 2:3], -1.0, 1.0)),
            velocity[:, [0, 2]],
            positions[:-1, 0, 1:2],
        ],
        axis=-1,
    )
    ric_data = ric[:-1, 1:].reshape(rows, -1)
    rot_data = cont6d(quats[:-1, 1:]).reshape(rows, -1)
    local_vel = qrot(
        np.repeat(r_rot[:-1, None], NUM_JOINTS, axis=1),
        global_positions[1:] - global_positions[:-1],
    ).reshape(rows, -1)
    return np.concatenate(
        [root_data, ric_data, rot_data, local_vel, feet_l, feet_r], axis=-1
    ).astype(np.float32)


# ---- the bench ------------------------------------------------------------------------------------

def main(argv):
    if not argv or argv[0].startswith("-"):
        sys.exit("usage: humanml3d_reference.py EXPORT_DIR [--repeat N]")
    export = argv[0]
    repeat = int(argv[argv.index("--repeat") + 1]) if "--repeat" in argv else 1
    names = sorted(n[:-4] for n in os.listdir(os.path.join(export, "joints")) if n.endswith(".npy"))
    motions = [np.load(os.path.join(export, "joints", n + ".npy")).astype(np.float64) for n in names]
    best_wall, best_cpu, outputs = float("inf"), float("inf"), None
    for _ in range(max(repeat, 1)):
        results = outputs = None  # one pass's rows held at a time
        cpu0, wall0 = time.process_time(), time.perf_counter()
        results = [process(m) for m in motions]
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        best_wall, best_cpu, outputs = min(best_wall, wall), min(best_cpu, cpu), results
    max_diff, compared, mismatched = 0.0, 0, 0
    for name, rows in zip(names, outputs):
        theirs = np.load(os.path.join(export, "new_joint_vecs", name + ".npy"))
        if theirs.shape != rows.shape:
            mismatched += 1
            continue
        max_diff = max(max_diff, float(np.abs(theirs.astype(np.float64) - rows).max(initial=0.0)))
        compared += len(rows)
    print(
        json.dumps(
            {
                "clips": len(names),
                "frames": int(sum(len(m) for m in motions)),
                "rows": int(sum(len(r) for r in outputs)),
                "wall_s": best_wall,
                "cpu_s": best_cpu,
                "repeat": max(repeat, 1),
                "numpy": np.__version__,
                "max_abs_diff": max_diff,
                "rows_compared": compared,
                "shape_mismatches": mismatched,
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1:])
