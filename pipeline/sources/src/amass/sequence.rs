//! One AMASS sequence file (`*_poses.npz` of SMPL+H G, `*_stageii.npz` of SMPL-X G): its pose
//! parameters, translation, shape, gender and frame rate, checked key by key.

use glam::DVec3;

use super::model::Family;
use super::npz::{Npz, NpzError, Values};

/// The largest magnitude accepted in `poses` (radians) and `trans` (metres): far beyond any body,
/// far below what would overflow.
const MAX_VALUE: f64 = 1e4;

/// Why an AMASS file is refused: the file and what is wrong, naming the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {kind}")]
pub struct AmassError {
    /// The file, as shown in reports.
    pub file: String,
    /// What is wrong.
    pub kind: AmassErrorKind,
}

/// What is wrong with an AMASS file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AmassErrorKind {
    /// The archive or an array is unreadable, or a key is missing.
    #[error("{0}")]
    Npz(NpzError),
    /// Neither frame-rate key is there.
    #[error(
        "no frame rate: neither `mocap_framerate` (SMPL+H G) nor `mocap_frame_rate` (SMPL-X G); set the rate with sources.fps_override"
    )]
    NoFrameRate,
    /// An array has the wrong shape or type.
    #[error("`{key}`: {message}")]
    Shape {
        /// The key.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A value is NaN, infinite or absurdly large.
    #[error(
        "`{key}`: frame {frame}, value {index}: {value} is not a finite value within ±{MAX_VALUE}"
    )]
    Value {
        /// The key.
        key: &'static str,
        /// The frame.
        frame: usize,
        /// Position of the value in the frame.
        index: usize,
        /// The value.
        value: f64,
    },
}

/// The gender a file states, and how it is stored (which HumanML3D's quirk depends on).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileGender {
    /// The value, trimmed.
    pub value: String,
    /// Stored as bytes (`|S`), not str (`<U`).
    pub bytes: bool,
}

/// An AMASS sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// SMPL-H or SMPL-X, from the width of `poses`.
    pub family: Family,
    /// Frames.
    pub frames: usize,
    /// Axis-angle rotations, `frames × joints × 3`, in the family's joint order.
    pub poses: Vec<f64>,
    /// Root translation per frame (metres, AMASS's z-up world).
    pub trans: Vec<DVec3>,
    /// Shape coefficients as stored.
    pub betas: Vec<f64>,
    /// The stated gender, when the file has a readable one.
    pub gender: Option<FileGender>,
    /// The frame rate (`None` when `fps_required` was false and the file has none).
    pub fps: Option<f64>,
}

/// True for the files that sit beside AMASS sequences but hold no motion: `shape.npz` (the
/// subject's betas) and MoSh's `*_stagei.npz` (the marker-fitting first stage).
pub fn is_not_a_motion(file_name: &str) -> bool {
    file_name == "shape.npz" || file_name.ends_with("_stagei.npz")
}

/// Reads a sequence from the bytes of its `.npz`; `file` names it in errors. With
/// `fps_required` false a missing frame rate is no error (an override gives it).
pub fn read_sequence(file: &str, bytes: &[u8], fps_required: bool) -> Result<Sequence, AmassError> {
    let fail = |kind| AmassError {
        file: file.to_string(),
        kind,
    };
    let shape = |key: &'static str, message: String| fail(AmassErrorKind::Shape { key, message });
    let npz = Npz::new(bytes).map_err(|e| fail(AmassErrorKind::Npz(e)))?;
    let get = |key: &str| npz.array(key).map_err(|e| fail(AmassErrorKind::Npz(e)));
    let floats = |key: &'static str| -> Result<(Vec<usize>, Vec<f64>), AmassError> {
        let array = get(key)?;
        match array.floats() {
            Some(v) => Ok((array.shape.clone(), v.into_owned())),
            None => Err(shape(key, format!("{} values, not numbers", array.kind()))),
        }
    };
    let (pose_shape, poses) = floats("poses")?;
    let (frames, width) = match pose_shape.as_slice() {
        [t, w] => (*t, *w),
        _ => {
            return Err(shape(
                "poses",
                format!(
                    "shape {pose_shape:?}; expected (frames, 156) for SMPL-H or (frames, 165) for SMPL-X"
                ),
            ));
        }
    };
    let family = match width {
        156 => Family::SmplH,
        165 => Family::SmplX,
        _ => {
            return Err(shape(
                "poses",
                format!("{width} values per frame; expected 156 (SMPL-H) or 165 (SMPL-X)"),
            ));
        }
    };
    check_values("poses", &poses, width).map_err(fail)?;
    let (trans_shape, trans) = floats("trans")?;
    if trans_shape.as_slice() != [frames, 3] {
        return Err(shape(
            "trans",
            format!("shape {trans_shape:?}; expected ({frames}, 3), a translation per pose"),
        ));
    }
    check_values("trans", &trans, 3).map_err(fail)?;
    let (betas_shape, betas) = floats("betas")?;
    if betas_shape.len() != 1 {
        return Err(shape(
            "betas",
            format!("shape {betas_shape:?}; expected (betas,)"),
        ));
    }
    check_values("betas", &betas, betas.len().max(1)).map_err(fail)?;
    let gender = match npz.has("gender") {
        false => None,
        true => match get("gender")?.values {
            Values::Text(value) => Some(FileGender {
                value: value.trim().to_string(),
                bytes: false,
            }),
            Values::Bytes(value) => Some(FileGender {
                value: value.trim().to_string(),
                bytes: true,
            }),
            _ => return Err(shape("gender", "numbers, not a str or bytes value".into())),
        },
    };
    let rate_key = ["mocap_framerate", "mocap_frame_rate"]
        .into_iter()
        .find(|k| npz.has(k));
    let fps = match rate_key {
        None if fps_required => return Err(fail(AmassErrorKind::NoFrameRate)),
        None => None,
        Some(key) => {
            let key: &'static str = if key == "mocap_framerate" {
                "mocap_framerate"
            } else {
                "mocap_frame_rate"
            };
            let (_, v) = floats(key)?;
            match v.as_slice() {
                [fps] if fps.is_finite() && *fps > 0.0 => Some(*fps),
                _ => {
                    return Err(shape(
                        key,
                        format!("{v:?}; expected one positive frame rate"),
                    ));
                }
            }
        }
    };
    Ok(Sequence {
        family,
        frames,
        poses,
        trans: trans
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect(),
        betas,
        gender,
        fps,
    })
}

fn check_values(key: &'static str, values: &[f64], width: usize) -> Result<(), AmassErrorKind> {
    match values
        .iter()
        .position(|v| !(v.is_finite() && v.abs() <= MAX_VALUE))
    {
        None => Ok(()),
        Some(i) => Err(AmassErrorKind::Value {
            key,
            frame: i / width,
            index: i % width,
            value: values[i],
        }),
    }
}

/// Frames kept and the effective rate of HumanML3D's pose_data step: every `int(fps / 20)`-th
/// frame from frame 0 (`range(0, frames, stride)`), so a 250 fps file gives 20.83 fps and a
/// 59.99999 fps file 30 fps. A file under 20 fps (stride 0, an error in the notebook) keeps
/// every frame.
pub fn humanml3d_stride(fps: f64) -> (usize, f64) {
    let stride = ((fps / 20.0).floor() as usize).max(1);
    (stride, fps / stride as f64)
}
