//! Positions from the representation, as HumanML3D's `recover_from_ric` recovers them (the
//! heading integrated from the rotation velocities, the root path from the linear velocities,
//! the joints from their root-relative positions), plus the last frame the rows imply.

use glam::{DQuat, DVec3};

use super::{DIM, NUM_JOINTS};

/// Heading per row: the rotation velocities summed (the first row's heading is zero), as a
/// rotation about y by twice the sum, which is how the representation encodes it.
fn headings(vectors: &[f32]) -> Vec<DQuat> {
    let mut angle = 0.0f64;
    vectors
        .chunks_exact(DIM)
        .map(|row| {
            let q = DQuat::from_xyzw(0.0, angle.sin(), 0.0, angle.cos());
            angle += f64::from(row[0]);
            q
        })
        .collect()
}

/// Root positions per row: the linear velocities taken back to the ground frame and summed,
/// with the stored height.
fn roots(vectors: &[f32], headings: &[DQuat]) -> Vec<DVec3> {
    let mut at = DVec3::ZERO;
    let mut previous: Option<(&[f32], DQuat)> = None;
    vectors
        .chunks_exact(DIM)
        .zip(headings)
        .map(|(row, heading)| {
            if let Some((before, _)) = previous {
                let step = DVec3::new(f64::from(before[1]), 0.0, f64::from(before[2]));
                at += heading.conjugate() * step;
            }
            previous = Some((row, *heading));
            DVec3::new(at.x, f64::from(row[3]), at.z)
        })
        .collect()
}

/// `recover_from_ric`: the positions of every row (`rows × 22`, y-up metres) from the root
/// motion and the root-relative joint positions. A trailing partial row is ignored.
pub fn recover_from_ric(vectors: &[f32]) -> Vec<DVec3> {
    let headings = headings(vectors);
    let roots = roots(vectors, &headings);
    let mut out = Vec::with_capacity(headings.len() * NUM_JOINTS);
    for ((row, heading), root) in vectors.chunks_exact(DIM).zip(&headings).zip(&roots) {
        out.push(*root);
        let back = heading.conjugate();
        for j in 0..NUM_JOINTS - 1 {
            let local = DVec3::new(
                f64::from(row[4 + 3 * j]),
                f64::from(row[5 + 3 * j]),
                f64::from(row[6 + 3 * j]),
            );
            let p = back * local;
            out.push(DVec3::new(p.x + root.x, p.y, p.z + root.z));
        }
    }
    out
}

/// Every frame the rows describe (`rows + 1`): the recovered positions and, after them, the last
/// frame, which no row holds as a position but the last row's joint velocities reach.
/// Recovering a HumanML3D `new_joint_vecs` array this way gives back the positions it was made
/// from (HumanML3D's own `new_joints` stop one frame short).
pub fn positions_from_vectors(vectors: &[f32]) -> Vec<DVec3> {
    let mut out = recover_from_ric(vectors);
    let headings = headings(vectors);
    if let (Some(row), Some(heading)) = (vectors.chunks_exact(DIM).last(), headings.last()) {
        let frames = out.len() / NUM_JOINTS;
        let back = heading.conjugate();
        let last: Vec<DVec3> = (0..NUM_JOINTS)
            .map(|j| {
                let at = 193 + 3 * j;
                let v = DVec3::new(
                    f64::from(row[at]),
                    f64::from(row[at + 1]),
                    f64::from(row[at + 2]),
                );
                out[(frames - 1) * NUM_JOINTS + j] + back * v
            })
            .collect();
        out.extend(last);
    }
    out
}
