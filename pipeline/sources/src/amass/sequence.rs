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
    #[error("`{key}`: {fault}")]
    Shape {
        /// The key.
        key: &'static str,
        /// What is wrong.
        fault: ShapeFault,
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

/// What is wrong with the shape or type of an AMASS file's array.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeFault {
    /// Strings where numbers belong.
    #[error("{kind} values, not numbers")]
    NotNumbers {
        /// The values' kind (`str`, `bytes`).
        kind: &'static str,
    },
    /// `poses` is not two-dimensional.
    #[error("shape {shape:?}; expected (frames, 156) for SMPL-H or (frames, 165) for SMPL-X")]
    PosesShape {
        /// The shape found.
        shape: Vec<usize>,
    },
    /// `poses` has a width of neither family.
    #[error("{width} values per frame; expected 156 (SMPL-H) or 165 (SMPL-X)")]
    PosesWidth {
        /// Values per frame found.
        width: usize,
    },
    /// `trans` is not one translation per pose.
    #[error("shape {shape:?}; expected ({frames}, 3), a translation per pose")]
    TransShape {
        /// The shape found.
        shape: Vec<usize>,
        /// Frames of `poses`.
        frames: usize,
    },
    /// `betas` is not one-dimensional.
    #[error("shape {shape:?}; expected (betas,)")]
    BetasShape {
        /// The shape found.
        shape: Vec<usize>,
    },
    /// `gender` holds numbers.
    #[error("numbers, not a str or bytes value")]
    GenderNotText,
    /// The frame-rate key is not one positive, finite number.
    #[error("{values:?}; expected one positive frame rate")]
    FrameRate {
        /// The values found.
        values: Vec<f64>,
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
    let shape = |key: &'static str, fault: ShapeFault| fail(AmassErrorKind::Shape { key, fault });
    let npz = Npz::new(bytes).map_err(|e| fail(AmassErrorKind::Npz(e)))?;
    let get = |key: &str| npz.array(key).map_err(|e| fail(AmassErrorKind::Npz(e)));
    let floats = |key: &'static str| -> Result<(Vec<usize>, Vec<f64>), AmassError> {
        let array = get(key)?;
        match array.floats() {
            Some(v) => Ok((array.shape.clone(), v.into_owned())),
            None => Err(shape(key, ShapeFault::NotNumbers { kind: array.kind() })),
        }
    };
    let (pose_shape, poses) = floats("poses")?;
    let (frames, width) = match pose_shape.as_slice() {
        [t, w] => (*t, *w),
        _ => {
            return Err(shape("poses", ShapeFault::PosesShape { shape: pose_shape }));
        }
    };
    let family = match width {
        156 => Family::SmplH,
        165 => Family::SmplX,
        _ => {
            return Err(shape("poses", ShapeFault::PosesWidth { width }));
        }
    };
    check_values("poses", &poses, width).map_err(fail)?;
    let (trans_shape, trans) = floats("trans")?;
    if trans_shape.as_slice() != [frames, 3] {
        return Err(shape(
            "trans",
            ShapeFault::TransShape {
                shape: trans_shape,
                frames,
            },
        ));
    }
    check_values("trans", &trans, 3).map_err(fail)?;
    let (betas_shape, betas) = floats("betas")?;
    if betas_shape.len() != 1 {
        return Err(shape(
            "betas",
            ShapeFault::BetasShape { shape: betas_shape },
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
            _ => return Err(shape("gender", ShapeFault::GenderNotText)),
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
                    return Err(shape(key, ShapeFault::FrameRate { values: v }));
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

#[cfg(test)]
mod tests {
    use super::super::npz::tests::{f8, npy, npz};
    use super::*;

    /// A sequence file of two SMPL-H frames, with `(key, npy bytes)` replacing or adding arrays.
    fn file(changes: &[(&str, Vec<u8>)]) -> Vec<u8> {
        let arrays: Vec<(String, Vec<u8>)> = vec![
            ("poses".into(), npy("<f8", "(2, 156)", &f8(&[0.0; 312]))),
            ("trans".into(), npy("<f8", "(2, 3)", &f8(&[0.0; 6]))),
            ("betas".into(), npy("<f8", "(16,)", &f8(&[0.0; 16]))),
            ("gender".into(), npy("|S4", "()", b"male")),
            ("mocap_framerate".into(), npy("<f8", "()", &f8(&[120.0]))),
        ];
        npz(arrays, changes)
    }

    /// The texts of the shape faults, as `rejects.jsonl` shows them: they must not change.
    #[test]
    fn every_shape_fault_reads_as_it_always_has() {
        assert!(read_sequence("a.npz", &file(&[]), true).is_ok());
        let cases: Vec<(&str, Vec<u8>, ShapeFault, &str)> = vec![
            (
                "poses",
                npy("|S4", "()", b"walk"),
                ShapeFault::NotNumbers { kind: "bytes" },
                "a.npz: `poses`: bytes values, not numbers",
            ),
            (
                "poses",
                npy("<f8", "(312,)", &f8(&[0.0; 312])),
                ShapeFault::PosesShape { shape: vec![312] },
                "a.npz: `poses`: shape [312]; expected (frames, 156) for SMPL-H or (frames, 165) for SMPL-X",
            ),
            (
                "poses",
                npy("<f8", "(3, 104)", &f8(&[0.0; 312])),
                ShapeFault::PosesWidth { width: 104 },
                "a.npz: `poses`: 104 values per frame; expected 156 (SMPL-H) or 165 (SMPL-X)",
            ),
            (
                "trans",
                npy("<f8", "(3, 2)", &f8(&[0.0; 6])),
                ShapeFault::TransShape {
                    shape: vec![3, 2],
                    frames: 2,
                },
                "a.npz: `trans`: shape [3, 2]; expected (2, 3), a translation per pose",
            ),
            (
                "betas",
                npy("<f8", "(4, 4)", &f8(&[0.0; 16])),
                ShapeFault::BetasShape { shape: vec![4, 4] },
                "a.npz: `betas`: shape [4, 4]; expected (betas,)",
            ),
            (
                "gender",
                npy("<i8", "()", &f8(&[0.0])),
                ShapeFault::GenderNotText,
                "a.npz: `gender`: numbers, not a str or bytes value",
            ),
            (
                "mocap_framerate",
                npy("<f8", "(2,)", &f8(&[60.0, -1.5])),
                ShapeFault::FrameRate {
                    values: vec![60.0, -1.5],
                },
                "a.npz: `mocap_framerate`: [60.0, -1.5]; expected one positive frame rate",
            ),
        ];
        for (key, bytes, fault, want) in cases {
            let err = read_sequence("a.npz", &file(&[(key, bytes)]), true).unwrap_err();
            assert_eq!(err.to_string(), want);
            assert_eq!(err.kind, AmassErrorKind::Shape { key, fault }, "{err}");
        }
    }
}
