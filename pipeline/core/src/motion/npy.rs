//! Joint-position arrays in NumPy's `.npy` format, the form most of the field's motion lives in
//! (HumanML3D's `joints`, `pose_data` and `new_joints`): `frames × joints × 3` (or
//! `frames × joints·3`) of float32 or float64, C order. Parsing the header is left to `npyz`;
//! this module checks what the header claims against the bytes before it reads any value.

use glam::DVec3;

use super::bvh::MAX_MAGNITUDE;

/// A `frames × joints` array of positions, frame-major.
#[derive(Debug, Clone, PartialEq)]
pub struct JointArray {
    /// Frames.
    pub frames: usize,
    /// Joints per frame.
    pub joints: usize,
    /// `frames × joints` positions.
    pub positions: Vec<DVec3>,
}

/// Why a `.npy` file is not a joint-position array.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// The header cannot be read.
    #[error("not a NumPy .npy file: {0}")]
    Header(#[source] std::io::Error),
    /// The values are not float32 or float64.
    #[error("values are `{0}`; expected float32 (`<f4`) or float64 (`<f8`)")]
    DType(String),
    /// The array is stored in Fortran order.
    #[error("the array is in Fortran order; expected C order (numpy's default)")]
    FortranOrder,
    /// The shape is not `frames × joints × 3` (or `frames × joints·3`).
    #[error("shape {shape:?}; expected (frames, joints, 3) or (frames, joints*3)")]
    Shape {
        /// The shape the header gives.
        shape: Vec<u64>,
    },
    /// The header promises more values than the file holds.
    #[error("the header promises {expected} bytes of values but the file holds {found}")]
    Truncated {
        /// Bytes the shape needs.
        expected: u64,
        /// Bytes after the header.
        found: u64,
    },
    /// A value is NaN or infinite.
    #[error("frame {frame}, joint {joint}: position is not finite")]
    NotFinite {
        /// The frame.
        frame: usize,
        /// The joint.
        joint: usize,
    },
    /// A value is finite but beyond what any capture holds, in any unit.
    #[error(
        "frame {frame}, joint {joint}: coordinate {value:e} is beyond ±{max:e}, the largest magnitude accepted in any capture (BVH too)",
        max = MAX_MAGNITUDE
    )]
    OutOfRange {
        /// The frame.
        frame: usize,
        /// The joint.
        joint: usize,
        /// The value.
        value: f64,
    },
}

impl NpyError {
    /// The frame holding the bad value, when the fault is in one.
    pub fn frame(&self) -> Option<usize> {
        match self {
            NpyError::NotFinite { frame, .. } | NpyError::OutOfRange { frame, .. } => Some(*frame),
            _ => None,
        }
    }
}

/// Reads a joint-position array from the bytes of a `.npy` file.
pub fn read_joint_positions(bytes: &[u8]) -> Result<JointArray, NpyError> {
    if let Some(shape) = overflowing_shape(bytes) {
        return Err(NpyError::Shape { shape });
    }
    let file = npyz::NpyFile::new(bytes).map_err(NpyError::Header)?;
    if file.order() == npyz::Order::Fortran {
        return Err(NpyError::FortranOrder);
    }
    let shape = file.shape().to_vec();
    let (frames, joints) = match shape.as_slice() {
        [f, j, 3] => (*f, *j),
        [f, n] if n % 3 == 0 => (*f, n / 3),
        _ => return Err(NpyError::Shape { shape }),
    };
    let dtype = file.dtype();
    let width: u64 = match dtype.num_bytes() {
        Some(4) | Some(8) => dtype.num_bytes().map_or(0, |w| w as u64),
        _ => return Err(NpyError::DType(dtype.descr())),
    };
    // What the header claims is checked against what the file holds before anything is
    // allocated for it.
    let values = frames
        .checked_mul(joints)
        .and_then(|n| n.checked_mul(3))
        .ok_or_else(|| NpyError::Shape {
            shape: shape.clone(),
        })?;
    let expected = values.saturating_mul(width);
    let found = file.into_inner().len() as u64;
    if expected > found {
        return Err(NpyError::Truncated { expected, found });
    }
    let file = npyz::NpyFile::new(bytes).map_err(NpyError::Header)?;
    let flat: Vec<f64> = match width {
        8 => file
            .into_vec::<f64>()
            .map_err(|_| NpyError::DType(dtype.descr()))?,
        _ => file
            .into_vec::<f32>()
            .map_err(|_| NpyError::DType(dtype.descr()))?
            .into_iter()
            .map(f64::from)
            .collect(),
    };
    let joints = joints as usize;
    let positions: Vec<DVec3> = flat
        .chunks_exact(3)
        .map(|v| DVec3::new(v[0], v[1], v[2]))
        .collect();
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(NpyError::NotFinite {
            frame: i / joints.max(1),
            joint: i % joints.max(1),
        });
    }
    // The same bound as BVH values: a huge finite value overflows bone lengths and features
    // downstream (1e200 squared is infinite).
    if let Some(i) = positions
        .iter()
        .position(|p| p.abs().max_element() > MAX_MAGNITUDE)
    {
        return Err(NpyError::OutOfRange {
            frame: i / joints.max(1),
            joint: i % joints.max(1),
            value: positions[i].abs().max_element(),
        });
    }
    Ok(JointArray {
        frames: frames as usize,
        joints,
        positions,
    })
}

/// The shape of a header whose element count does not fit in 64 bits. `npyz` multiplies the
/// dimensions unchecked (a panic in debug builds, a wrapped count in release), so such a header is
/// refused before it is handed over. `None` for any other header, readable or not.
fn overflowing_shape(bytes: &[u8]) -> Option<Vec<u64>> {
    let (major, rest) = match bytes.strip_prefix(b"\x93NUMPY")? {
        [major, _minor, rest @ ..] => (*major, rest),
        _ => return None,
    };
    let (len, rest) = match (major, rest) {
        (1, [a, b, rest @ ..]) => (usize::from(u16::from_le_bytes([*a, *b])), rest),
        (_, [a, b, c, d, rest @ ..]) => (u32::from_le_bytes([*a, *b, *c, *d]) as usize, rest),
        _ => return None,
    };
    let header = std::str::from_utf8(rest.get(..len.min(rest.len()))?).ok()?;
    let after = &header[header.find("'shape'")? + "'shape'".len()..];
    let open = after.find('(')?;
    let close = open + after[open..].find(')')?;
    let dims: Vec<u64> = after[open + 1..close]
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .map(|d| d.trim_end_matches(['L', 'l']).parse::<u64>().ok())
        .collect::<Option<_>>()?;
    let fits = dims
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(d))
        .is_some();
    (!fits).then_some(dims)
}
