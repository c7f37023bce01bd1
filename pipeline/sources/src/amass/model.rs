//! The user's SMPL-H or SMPL-X body model (`model.npz`, as AMASS documents it): only what joint
//! positions need, `v_template`, `shapedirs`, `J_regressor` and `kintree_table`, read once and
//! reduced to rest joints that are affine in the shape coefficients.

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::npz::{Npz, NpzError};

/// The keys a body model file must have (AMASS's and smplx's names). Only the first four are
/// read; the others are checked to be present, which costs nothing (the archive's directory).
pub const MODEL_KEYS: [&str; 7] = [
    "v_template",
    "shapedirs",
    "J_regressor",
    "kintree_table",
    "posedirs",
    "weights",
    "f",
];

/// The most shape coefficients a model is asked for (SMPL-X has 300 shape and 100 expression
/// directions).
pub const MAX_BETAS: usize = 400;

/// The body model families AMASS releases use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Family {
    /// SMPL-H (AMASS's "SMPL+H G"): 52 joints, poses `(T, 156)`.
    SmplH,
    /// SMPL-X (AMASS's "SMPL-X G"): 55 joints, poses `(T, 165)`.
    SmplX,
}

impl Family {
    /// The folder of the body model tree (`smplh`, `smplx`).
    pub fn folder(self) -> &'static str {
        match self {
            Family::SmplH => "smplh",
            Family::SmplX => "smplx",
        }
    }

    /// Joints of the family's skeleton.
    pub fn joints(self) -> usize {
        self.names().len()
    }

    /// Its joint names, in the model's order (smplx's names, `_smplhf` dropped from the eyes).
    pub fn names(self) -> &'static [&'static str] {
        match self {
            Family::SmplH => &SMPLH_JOINTS,
            Family::SmplX => &SMPLX_JOINTS,
        }
    }

    /// The bundled skeleton profile for the family.
    pub fn profile(self) -> &'static str {
        match self {
            Family::SmplH => "smplh-52",
            Family::SmplX => "smplx-55",
        }
    }
}

macro_rules! hand {
    ($side:literal) => {
        [
            concat!($side, "_index1"),
            concat!($side, "_index2"),
            concat!($side, "_index3"),
            concat!($side, "_middle1"),
            concat!($side, "_middle2"),
            concat!($side, "_middle3"),
            concat!($side, "_pinky1"),
            concat!($side, "_pinky2"),
            concat!($side, "_pinky3"),
            concat!($side, "_ring1"),
            concat!($side, "_ring2"),
            concat!($side, "_ring3"),
            concat!($side, "_thumb1"),
            concat!($side, "_thumb2"),
            concat!($side, "_thumb3"),
        ]
    };
}

/// SMPL's 22 body joints, the first joints of both families: the joints HumanML3D keeps.
pub const BODY_JOINTS: [&str; 22] = motionforge_core::humanml3d::JOINTS;

const fn concat_names<const N: usize>(parts: [&[&'static str]; 4]) -> [&'static str; N] {
    let mut out = [""; N];
    let mut i = 0;
    let mut p = 0;
    while p < parts.len() {
        let mut k = 0;
        while k < parts[p].len() {
            out[i] = parts[p][k];
            i += 1;
            k += 1;
        }
        p += 1;
    }
    out
}

/// SMPL-H's 52 joints: the body, then the left hand's 15, then the right hand's.
pub const SMPLH_JOINTS: [&str; 52] =
    concat_names([&BODY_JOINTS, &[], &hand!("left"), &hand!("right")]);

/// SMPL-X's 55 joints: the body, jaw and eyes, then the hands.
pub const SMPLX_JOINTS: [&str; 55] = concat_names([
    &BODY_JOINTS,
    &["jaw", "left_eye", "right_eye"],
    &hand!("left"),
    &hand!("right"),
]);

/// Why a body model cannot be used: each names the file and the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// The file is not there (or its metadata cannot be read).
    #[error("body model {path}: cannot read: no such file")]
    NotFound {
        /// The model file.
        path: PathBuf,
    },
    /// The file cannot be read.
    #[error("body model {path}: cannot read: {message}")]
    Read {
        /// The model file.
        path: PathBuf,
        /// The I/O error's text: a loaded model (or its error) is cached and cloned, and
        /// `std::io::Error` is not `Clone`.
        message: String,
    },
    /// The archive or one of its arrays is unreadable, or a key is missing.
    #[error("body model {path}: {source}")]
    Npz {
        /// The model file.
        path: PathBuf,
        /// What is wrong, naming the key.
        source: NpzError,
    },
    /// An array's shape or values do not fit the others.
    #[error("body model {path}: `{key}`: {fault}")]
    Shape {
        /// The model file.
        path: PathBuf,
        /// The key.
        key: &'static str,
        /// What is wrong.
        fault: ModelFault,
    },
}

/// What is wrong with a body model's array: its shape, its values, or how it fits the others.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ModelFault {
    /// Strings where numbers belong.
    #[error("{kind} values, not numbers")]
    NotNumbers {
        /// The values' kind (`str`, `bytes`).
        kind: &'static str,
    },
    /// A NaN or infinite value.
    #[error("value {index} is not finite")]
    NotFinite {
        /// The value's position, in C order.
        index: usize,
    },
    /// `v_template` is not `(vertices, 3)`.
    #[error("shape {shape:?}; expected (vertices, 3)")]
    TemplateShape {
        /// The shape found.
        shape: Vec<usize>,
    },
    /// `J_regressor` is not `(joints, vertices)`.
    #[error("shape {shape:?}; expected (joints, {vertices})")]
    RegressorShape {
        /// The shape found.
        shape: Vec<usize>,
        /// Vertices of `v_template`.
        vertices: usize,
    },
    /// `shapedirs` is not `(vertices, 3, betas)`.
    #[error("shape {shape:?}; expected ({vertices}, 3, betas)")]
    ShapedirsShape {
        /// The shape found.
        shape: Vec<usize>,
        /// Vertices of `v_template`.
        vertices: usize,
    },
    /// Fewer shape directions than `num_betas`.
    #[error("holds {stored} shape directions; num_betas = {num_betas} needs that many")]
    TooFewDirections {
        /// Directions the file holds.
        stored: usize,
        /// Directions asked for.
        num_betas: usize,
    },
    /// `kintree_table` is not integers of shape `(2, joints)`.
    #[error("{kind} values of shape {shape:?}; expected integers of shape (2, {joints})")]
    KintreeShape {
        /// The values' kind.
        kind: &'static str,
        /// The shape found.
        shape: Vec<usize>,
        /// Joints of `J_regressor`.
        joints: usize,
    },
    /// A joint whose parent is not a joint before it.
    #[error("joint {joint} has parent {parent}; expected a joint before it")]
    ParentOrder {
        /// The joint.
        joint: usize,
        /// Its parent as stored.
        parent: i64,
    },
}

/// A body model reduced to its rest joints: `J(β) = J_template + Σ_b β_b · J_dirs[b]`, which is
/// `J_regressor · (v_template + shapedirs · β)` regrouped.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyModel {
    /// The model file.
    pub path: PathBuf,
    /// Parent of each joint (`None` for the root, joint 0), from `kintree_table[0]`.
    pub parents: Vec<Option<usize>>,
    /// Shape coefficients used (`num_betas`).
    pub num_betas: usize,
    /// `J_regressor · v_template`, per joint.
    template: Vec<DVec3>,
    /// `J_regressor · shapedirs[..., b]`, per coefficient then joint.
    directions: Vec<DVec3>,
}

impl BodyModel {
    /// Reads `path` and keeps what `num_betas` shape coefficients need.
    pub fn load(path: &Path, num_betas: usize) -> Result<BodyModel, ModelError> {
        let bytes = std::fs::read(path).map_err(|e| ModelError::Read {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        BodyModel::from_bytes(path, &bytes, num_betas)
    }

    /// [`BodyModel::load`] of bytes already read; `path` names the file in errors.
    pub fn from_bytes(
        path: &Path,
        bytes: &[u8],
        num_betas: usize,
    ) -> Result<BodyModel, ModelError> {
        let file = ModelFile {
            path,
            npz: Npz::new(bytes).map_err(|e| npz_error(path, e))?,
        };
        if let Some(key) = MODEL_KEYS.iter().find(|k| !file.npz.has(k)) {
            return Err(npz_error(
                path,
                NpzError::Missing {
                    key: key.to_string(),
                },
            ));
        }
        let (shape, v_template) = file.floats("v_template")?;
        let vertices = match shape.as_slice() {
            [v, 3] if *v > 0 => *v,
            _ => {
                return Err(file.shape_err("v_template", ModelFault::TemplateShape { shape }));
            }
        };
        let (shape, regressor) = file.floats("J_regressor")?;
        let joints = match shape.as_slice() {
            [j, v] if *v == vertices && *j > 0 => *j,
            _ => {
                return Err(file.shape_err(
                    "J_regressor",
                    ModelFault::RegressorShape { shape, vertices },
                ));
            }
        };
        let (shape, shapedirs) = file.floats("shapedirs")?;
        let stored = match shape.as_slice() {
            [v, 3, b] if *v == vertices => *b,
            _ => {
                return Err(
                    file.shape_err("shapedirs", ModelFault::ShapedirsShape { shape, vertices })
                );
            }
        };
        if num_betas > stored {
            return Err(file.shape_err(
                "shapedirs",
                ModelFault::TooFewDirections { stored, num_betas },
            ));
        }
        let parents = file.parents(joints)?;
        let mesh = ShapeArrays {
            vertices,
            v_template: &v_template,
            shapedirs: &shapedirs,
            stored,
        };
        let (template, directions) = mesh.regress(&regressor, joints, num_betas);
        Ok(BodyModel {
            path: path.to_path_buf(),
            parents,
            num_betas,
            template,
            directions,
        })
    }

    /// Joints of the model.
    pub fn joints(&self) -> usize {
        self.parents.len()
    }

    /// Rest joint positions for shape coefficients `betas` (the first `num_betas` are used;
    /// the caller checks there are that many).
    pub fn rest_joints(&self, betas: &[f64]) -> Vec<DVec3> {
        let n = self.joints();
        let mut out = self.template.clone();
        for (b, &beta) in betas.iter().take(self.num_betas).enumerate() {
            for (j, o) in out.iter_mut().enumerate() {
                *o += beta * self.directions[b * n + j];
            }
        }
        out
    }
}

fn npz_error(path: &Path, source: NpzError) -> ModelError {
    ModelError::Npz {
        path: path.to_path_buf(),
        source,
    }
}

/// A body model file being read: its path for errors and its archive.
struct ModelFile<'a> {
    path: &'a Path,
    npz: Npz<'a>,
}

impl ModelFile<'_> {
    fn shape_err(&self, key: &'static str, fault: ModelFault) -> ModelError {
        ModelError::Shape {
            path: self.path.to_path_buf(),
            key,
            fault,
        }
    }

    /// The array `key` as finite numbers, with its shape.
    fn floats(&self, key: &'static str) -> Result<(Vec<usize>, Vec<f64>), ModelError> {
        let array = self.npz.array(key).map_err(|e| npz_error(self.path, e))?;
        let values = array
            .floats()
            .ok_or_else(|| self.shape_err(key, ModelFault::NotNumbers { kind: array.kind() }))?
            .into_owned();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.shape_err(key, ModelFault::NotFinite { index: i }));
        }
        Ok((array.shape, values))
    }

    /// Each joint's parent from `kintree_table[0]`: `None` for joint 0, else a joint before it.
    fn parents(&self, joints: usize) -> Result<Vec<Option<usize>>, ModelError> {
        let kintree = self
            .npz
            .array("kintree_table")
            .map_err(|e| npz_error(self.path, e))?;
        let table = match (&kintree.values, kintree.shape.as_slice()) {
            (super::npz::Values::Int(v), [2, j]) if *j == joints => v,
            _ => {
                return Err(self.shape_err(
                    "kintree_table",
                    ModelFault::KintreeShape {
                        kind: kintree.kind(),
                        shape: kintree.shape.clone(),
                        joints,
                    },
                ));
            }
        };
        let mut parents = Vec::with_capacity(joints);
        for (j, &p) in table[..joints].iter().enumerate() {
            if j == 0 {
                parents.push(None);
                continue;
            }
            match usize::try_from(p) {
                Ok(p) if p < j => parents.push(Some(p)),
                _ => {
                    return Err(self.shape_err(
                        "kintree_table",
                        ModelFault::ParentOrder {
                            joint: j,
                            parent: p,
                        },
                    ));
                }
            }
        }
        Ok(parents)
    }
}

/// The model's checked vertex arrays: the template mesh and its shape directions.
struct ShapeArrays<'a> {
    vertices: usize,
    /// `vertices × 3`.
    v_template: &'a [f64],
    /// `vertices × 3 × stored`.
    shapedirs: &'a [f64],
    /// Shape directions the file holds.
    stored: usize,
}

impl ShapeArrays<'_> {
    /// Regrouped sums through the joint regressor (`joints × vertices`): `J_template =
    /// R · v_template`, `J_dirs[b] = R · shapedirs[.., b]` (per coefficient then joint).
    fn regress(
        &self,
        regressor: &[f64],
        joints: usize,
        num_betas: usize,
    ) -> (Vec<DVec3>, Vec<DVec3>) {
        let (stored, shapedirs) = (self.stored, self.shapedirs);
        let mut template = vec![DVec3::ZERO; joints];
        let mut directions = vec![DVec3::ZERO; joints * num_betas];
        for (j, row) in regressor.chunks_exact(self.vertices).enumerate() {
            let mut acc = DVec3::ZERO;
            let mut dirs = vec![DVec3::ZERO; num_betas];
            for (v, &w) in row.iter().enumerate() {
                if w == 0.0 {
                    continue;
                }
                acc += w * DVec3::from_slice(&self.v_template[3 * v..3 * v + 3]);
                for (b, d) in dirs.iter_mut().enumerate() {
                    let at = v * 3 * stored + b;
                    *d += w * DVec3::new(
                        shapedirs[at],
                        shapedirs[at + stored],
                        shapedirs[at + 2 * stored],
                    );
                }
            }
            template[j] = acc;
            for (b, d) in dirs.into_iter().enumerate() {
                directions[b * joints + j] = d;
            }
        }
        (template, directions)
    }
}

#[cfg(test)]
mod tests {
    use super::super::npz::tests::{f8, npy, npz};
    use super::*;

    fn i8s(values: &[i64]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    /// A model of 2 vertices, 2 joints and 2 shape directions, with `(key, npy bytes)` replacing
    /// arrays.
    fn model(changes: &[(&str, Vec<u8>)]) -> Vec<u8> {
        let arrays: Vec<(String, Vec<u8>)> = vec![
            ("v_template".into(), npy("<f8", "(2, 3)", &f8(&[0.0; 6]))),
            ("shapedirs".into(), npy("<f8", "(2, 3, 2)", &f8(&[0.0; 12]))),
            (
                "J_regressor".into(),
                npy("<f8", "(2, 2)", &f8(&[1.0, 0.0, 0.0, 1.0])),
            ),
            (
                "kintree_table".into(),
                npy("<i8", "(2, 2)", &i8s(&[-1, 0, 0, 1])),
            ),
            ("posedirs".into(), npy("<f8", "(1,)", &f8(&[0.0]))),
            ("weights".into(), npy("<f8", "(1,)", &f8(&[0.0]))),
            ("f".into(), npy("<i8", "(1,)", &i8s(&[0]))),
        ];
        npz(arrays, changes)
    }

    /// The texts of the shape faults, as errors show them: they must not change.
    #[test]
    fn every_shape_fault_reads_as_it_always_has() {
        let path = Path::new("m/model.npz");
        assert!(BodyModel::from_bytes(path, &model(&[]), 2).is_ok());
        let cases: Vec<(&str, Vec<u8>, usize, &str)> = vec![
            (
                "v_template",
                npy("<f8", "(3, 2)", &f8(&[0.0; 6])),
                2,
                "body model m/model.npz: `v_template`: shape [3, 2]; expected (vertices, 3)",
            ),
            (
                "J_regressor",
                npy("<f8", "(1, 4)", &f8(&[0.0; 4])),
                2,
                "body model m/model.npz: `J_regressor`: shape [1, 4]; expected (joints, 2)",
            ),
            (
                "shapedirs",
                npy("<f8", "(2, 6)", &f8(&[0.0; 12])),
                2,
                "body model m/model.npz: `shapedirs`: shape [2, 6]; expected (2, 3, betas)",
            ),
            (
                "shapedirs",
                npy("<f8", "(2, 3, 2)", &f8(&[0.0; 12])),
                3,
                "body model m/model.npz: `shapedirs`: holds 2 shape directions; num_betas = 3 needs that many",
            ),
            (
                "v_template",
                npy("<U2", "()", &[0u8; 8]),
                2,
                "body model m/model.npz: `v_template`: str values, not numbers",
            ),
            (
                "v_template",
                npy("<f8", "(2, 3)", &f8(&[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0])),
                2,
                "body model m/model.npz: `v_template`: value 2 is not finite",
            ),
            (
                "kintree_table",
                npy("<f8", "(2, 2)", &f8(&[0.0; 4])),
                2,
                "body model m/model.npz: `kintree_table`: float values of shape [2, 2]; expected integers of shape (2, 2)",
            ),
            (
                "kintree_table",
                npy("<i8", "(2, 2)", &i8s(&[-1, 1, 0, 1])),
                2,
                "body model m/model.npz: `kintree_table`: joint 1 has parent 1; expected a joint before it",
            ),
        ];
        for (key, bytes, betas, want) in cases {
            let err = BodyModel::from_bytes(path, &model(&[(key, bytes)]), betas).unwrap_err();
            assert_eq!(err.to_string(), want);
            assert!(
                matches!(err, ModelError::Shape { key: k, .. } if k == key),
                "{err}"
            );
        }
    }
}
