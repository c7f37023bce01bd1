//! What the write stage writes beside the shards, made from the table's clips: `skeletons.json`
//! (each distinct skeleton once, with the profile bound to it), the manifest with the dataset's
//! counts, and the dataset card (`README.md`) with Hugging Face's YAML front matter.

use std::collections::BTreeMap;

use motionforge_core::base::layout::DATA_DIR;
use motionforge_core::motion::{MirrorPlan, OffsetPolicy, Profile};
use motionforge_format::io::skeletons::{CaptureAxes, SkeletonEntry, SkeletonJoint, Skeletons};
use motionforge_sources::clip::{Clip, SourceKind, Split};

/// The table's skeletons as `skeletons.json` lists them (by id), and each profile bound to the
/// first skeleton of its clips (what the writer turns frames into rows with).
pub(super) fn skeletons_of(
    shared: &super::capture::Shared<'_>,
    clips: &[Clip],
) -> (BTreeMap<String, Profile>, Skeletons) {
    let mut profiles: BTreeMap<String, Profile> = BTreeMap::new();
    let mut skeletons = Skeletons::new();
    // Clips share their skeleton (`SkeletonPool`): its id, a digest of the whole skeleton, is
    // taken once per shared copy and profile, not once per clip.
    let mut named: std::collections::HashSet<(*const motionforge_core::motion::Skeleton, &str)> =
        Default::default();
    for clip in clips {
        if !named.insert((
            std::sync::Arc::as_ptr(&clip.skeleton),
            clip.profile.as_str(),
        )) {
            continue;
        }
        let id = clip.skeleton_id();
        if skeletons.contains_key(&id) {
            continue;
        }
        if let Some(spec) = shared.specs.iter().find(|s| s.name == clip.profile)
            && let Ok(bound) = shared.bound.bind(spec, &clip.skeleton)
        {
            // A mirror on its own skeleton names the skeleton it reflects (mirroring is an
            // involution, so mirroring this one gives that one back).
            let mirror_of = if clip.mirrored && shared.config.mirror.offsets == OffsetPolicy::Mirror
            {
                MirrorPlan::from_profile(&clip.skeleton, &bound)
                    .ok()
                    .map(|plan| plan.skeleton_of_mirror(&clip.skeleton, OffsetPolicy::Mirror))
                    .map(|original| {
                        motionforge_sources::clip::skeleton_name(&clip.profile, &original)
                    })
                    .filter(|original| *original != id)
            } else {
                None
            };
            skeletons.insert(id, skeleton_json(&clip.skeleton, &bound, mirror_of));
            profiles.entry(clip.profile.clone()).or_insert(bound);
        }
    }
    (profiles, skeletons)
}

/// A skeleton's entry in `skeletons.json`. `mirror_of` names the skeleton (by id) whose
/// reflection this is, for the skeleton of a mirrored clip that differs from its original's.
pub(super) fn skeleton_json(
    skeleton: &motionforge_core::motion::Skeleton,
    profile: &Profile,
    mirror_of: Option<String>,
) -> SkeletonEntry {
    let joints = skeleton
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let o = joint.offset * profile.unit_scale;
            SkeletonJoint {
                name: joint.name.clone(),
                parent: joint.parent,
                offset_m: [o.x, o.y, o.z],
                // In file units as read, with the channel layout and end site: what a BVH of
                // the clip needs beyond the rows (`export-bvh` from the shards).
                offset: Some(joint.offset.to_array()),
                channels: Some(joint.channels.clone()),
                end_site: joint.end_site.map(|e| e.to_array()),
                mirror: Some(skeleton.joints[profile.swap[j]].name.clone()),
                part: profile.part_of[j],
                role: Some(profile.roles[j]),
            }
        })
        .collect();
    SkeletonEntry {
        profile: profile.name.clone(),
        root: skeleton.joints[profile.root].name.clone(),
        capture_axes: CaptureAxes {
            up: profile.up,
            forward: profile.forward,
        },
        unit_scale: profile.unit_scale,
        joints,
        mirror_of,
    }
}

/// Everything written beside the shards that the build computes: manifest fields and card text.
pub(super) struct Companions {
    /// `manifest.json` without the per-shard entries (added here).
    pub(super) manifest: motionforge_format::io::manifest::Manifest,
    /// Dataset card body (Markdown after the YAML front matter).
    pub(super) card_body: String,
    /// Licences of the sources, for the card's front matter.
    pub(super) licences: Vec<String>,
    /// Target shard size.
    pub(super) shard_bytes: u64,
    /// zstd level of the shards.
    pub(super) zstd_level: i32,
    /// Derived feature columns to write.
    pub(super) features: motionforge_core::features::FeatureConfig,
}

impl Companions {
    /// What the write stage writes beside the shards of `clips`: the manifest with the dataset's
    /// counts (made here, once, for the manifest, the card and the build report) and the card.
    pub(super) fn of(
        config: &crate::config::Config,
        clips: &[Clip],
        rejects: &[super::Reject],
        drops_by_reason: motionforge_core::base::Tally<motionforge_core::base::DropReason>,
        label_contradictions: &[motionforge_core::quality::Contradiction],
        table_fingerprint: &str,
    ) -> Companions {
        let counts = motionforge_format::io::manifest::Counts::of(clips, rejects, drops_by_reason);
        let licences: Vec<String> = config
            .sources
            .iter()
            .filter(|s| !s.licence.is_empty())
            .map(|s| format!("{}: {}", s.name, s.licence))
            .collect();
        let card_body = card_body(config, clips, &licences, &counts.source_kind);
        let mut manifest = motionforge_format::io::manifest::Manifest::new(
            config.built_from(),
            clips,
            counts,
            table_fingerprint,
        );
        // The statistics report reads them from the manifest, so a paper's tables list them too.
        manifest.label_contradictions = label_contradictions.to_vec();
        Companions {
            manifest,
            card_body,
            licences,
            shard_bytes: config.dataset.shard_bytes,
            zstd_level: config.dataset.zstd_level,
            features: config.features,
        }
    }
}

/// The card's Markdown body: what the dataset is, where it came from, its columns.
pub(super) fn card_body(
    config: &crate::config::Config,
    clips: &[Clip],
    licences: &[String],
    kinds: &motionforge_core::base::Tally<SourceKind>,
) -> String {
    use std::fmt::Write as _;
    let mut b = String::new();
    let _ = writeln!(b, "# {}\n", config.dataset.name);
    let _ = writeln!(
        b,
        "Text-to-motion clips built by motionforge {} from motion-capture recordings: {} rows at {} fps, joint positions in metres (x right, y forward, z up), local rotations as quaternions.\n",
        env!("CARGO_PKG_VERSION"),
        clips.len(),
        config.dataset.fps
    );
    let _ = writeln!(b, "## Sources and licences\n");
    for source in &config.sources {
        let n = clips
            .iter()
            .filter(|c| c.capture.source == source.name && !c.mirrored)
            .map(|c| &c.capture.path)
            .collect::<std::collections::BTreeSet<_>>()
            .len();
        let licence = if source.licence.is_empty() {
            "licence not stated in the build config"
        } else {
            source.licence.as_str()
        };
        let captures = if n == 1 { "capture" } else { "captures" };
        let _ = writeln!(b, "- `{}` ({n} {captures}): {licence}", source.name);
    }
    if licences.is_empty() {
        let _ = writeln!(
            b,
            "\nNo licence was given in the build config; check each source's terms before sharing."
        );
    }
    let _ = writeln!(b, "\n## Rows by kind\n");
    for (k, n) in kinds {
        let _ = writeln!(b, "- {k}: {n}");
    }
    let _ = writeln!(b, "\n## Using it\n");
    let _ = writeln!(
        b,
        "With Hugging Face `datasets` (no PyTorch needed), from the folder holding this one: one split, one clip's canonical joint positions as a (frames, joints, 3) array, normalised with its skeleton profile's statistics. Every per-frame column comes in the shape the table below gives it (frames x joints x 3, frames x 4, ...): no reshape. Dimensions that are constant over the statistics' split (listed in `normalization/normalization.json`) have their standard deviation floored at 1e-8: set them to 0 rather than divide.\n"
    );
    // The folder's name as a Python string (JSON's quoting is valid Python for these names).
    let root = serde_json::to_string(&config.dataset.name).unwrap_or_default();
    let _ = writeln!(
        b,
        "```python\n{}```",
        CARD_SNIPPET.replace("\"<dataset folder>\"", &root)
    );
    let _ = writeln!(
        b,
        "\n## Columns\n\n| column | type | nullable | meaning |\n|---|---|---|---|"
    );
    for f in motionforge_format::io::schema::clip_schema().fields() {
        let _ = writeln!(
            b,
            "| `{}` | {} | {} | {} |",
            f.name(),
            f.data_type(),
            if f.is_nullable() { "yes" } else { "no" },
            motionforge_format::io::schema::column_meaning(f.name())
        );
    }
    let _ = writeln!(
        b,
        "\nShards: `data/<split>-NNNNN-of-NNNNN.parquet`; checksums and provenance in `manifest.json`; skeletons in `skeletons.json`. Every mirror and synthetic pair is in the split of its source captures."
    );
    let _ = writeln!(b, "\n## Citation\n");
    let _ = writeln!(
        b,
        "Cite the source datasets above under their own terms, and this build as:\n"
    );
    let sources: Vec<&str> = config.sources.iter().map(|s| s.name.as_str()).collect();
    let _ = writeln!(
        b,
        "```bibtex\n@misc{{{key},\n  title = {{{{{name}}}: text-to-motion clips}},\n  note = {{Built with motionforge {version} from {sources}}},\n}}\n```",
        key = bibtex_key(&config.dataset.name),
        name = config.dataset.name,
        version = env!("CARGO_PKG_VERSION"),
        sources = sources.join(", ")
    );
    b
}

/// The card's usage snippet, run by `tests/loaders.rs` on the demo's card.
pub(crate) const CARD_SNIPPET: &str = r#"import numpy as np
from datasets import load_dataset

root = "<dataset folder>"  # this folder (the one holding README.md and data/)
train = load_dataset(root, split="train").with_format("numpy")
row = train[0]
# (frames, joints, 3), metres, the first frame's pelvis over the origin facing +y (x right, z up).
positions = row["canonical_positions"]
profile = str(row["skeleton"]).split(":")[0]
mean = np.load(f"{root}/normalization/{profile}/canonical_positions_mean.npy")  # (joints, 3)
std = np.load(f"{root}/normalization/{profile}/canonical_positions_std.npy")
normalised = (positions - mean) / std
normalised[:, std < 1e-6] = 0.0  # constant dimensions
print(row["text"], positions.shape, normalised.shape)
"#;

/// A BibTeX key of letters and digits from a dataset name.
fn bibtex_key(name: &str) -> String {
    let key: String = name.chars().filter(char::is_ascii_alphanumeric).collect();
    if key.is_empty() {
        "motionforge".to_string()
    } else {
        key
    }
}

/// A column's type in the dataset card's `features` (the form Hugging Face `datasets` writes:
/// `dtype`, `list`, `struct`), at `indent` spaces, from the same Arrow type the writer uses.
fn hf_feature(y: &mut String, data_type: &arrow_schema::DataType, indent: usize) {
    use arrow_schema::DataType;
    let pad = " ".repeat(indent);
    match data_type {
        // A fixed-size list is a `list` with its `length` after it, as `datasets` writes it.
        DataType::List(item) | DataType::FixedSizeList(item, _) => {
            match scalar_dtype(item.data_type()) {
                Some(dtype) => y.push_str(&format!("{pad}list: {dtype}\n")),
                None => {
                    y.push_str(&format!("{pad}list:\n"));
                    hf_nested(y, item.data_type(), indent + 2);
                }
            }
            if let DataType::FixedSizeList(_, n) = data_type {
                y.push_str(&format!("{pad}length: {n}\n"));
            }
        }
        DataType::Struct(fields) => {
            y.push_str(&format!("{pad}struct:\n"));
            hf_fields(y, fields, indent);
        }
        other => y.push_str(&format!(
            "{pad}dtype: {}\n",
            scalar_dtype(other).unwrap_or("string")
        )),
    }
}

/// The inside of a `list:` that is not a scalar: a struct's fields, or another list.
fn hf_nested(y: &mut String, data_type: &arrow_schema::DataType, indent: usize) {
    match data_type {
        arrow_schema::DataType::Struct(fields) => hf_fields(y, fields, indent - 2),
        other => hf_feature(y, other, indent),
    }
}

fn hf_fields(y: &mut String, fields: &arrow_schema::Fields, indent: usize) {
    let pad = " ".repeat(indent);
    for f in fields {
        y.push_str(&format!("{pad}- name: {}\n", f.name()));
        hf_feature(y, f.data_type(), indent + 2);
    }
}

/// The `datasets` dtype name of a scalar Arrow type.
fn scalar_dtype(data_type: &arrow_schema::DataType) -> Option<&'static str> {
    use arrow_schema::DataType;
    Some(match data_type {
        DataType::Utf8 => "string",
        DataType::Boolean => "bool",
        DataType::Int32 => "int32",
        DataType::Int64 => "int64",
        DataType::Float32 => "float32",
        DataType::Float64 => "float64",
        _ => return None,
    })
}

pub(super) fn card(
    name: &str,
    splits: &BTreeMap<Split, usize>,
    split_bytes: &BTreeMap<Split, usize>,
    companions: &Companions,
) -> String {
    let mut y = String::from("---\n");
    y.push_str(&format!("pretty_name: {name}\nlicense: other\n"));
    if !companions.licences.is_empty() {
        y.push_str("license_details: >-\n");
        y.push_str(&format!("  {}\n", companions.licences.join("; ")));
    }
    y.push_str("tags:\n- motion-capture\n- text-to-motion\n- motionforge\nconfigs:\n- config_name: default\n  data_files:\n");
    // Split order (train, validation, test, then others: the maps' own), as loaders list them.
    let order: Vec<&Split> = splits.keys().collect();
    for split in &order {
        y.push_str(&format!(
            "  - split: {split}\n    path: {DATA_DIR}/{split}-*.parquet\n"
        ));
    }
    y.push_str("dataset_info:\n  features:\n");
    for field in motionforge_format::io::schema::clip_schema().fields() {
        y.push_str(&format!("  - name: {}\n", field.name()));
        hf_feature(&mut y, field.data_type(), 4);
    }
    y.push_str("  splits:\n");
    for split in &order {
        let rows = splits.get(*split).copied().unwrap_or(0);
        let bytes = split_bytes.get(*split).copied().unwrap_or(0);
        y.push_str(&format!(
            "  - name: {split}\n    num_bytes: {bytes}\n    num_examples: {rows}\n"
        ));
    }
    y.push_str("---\n\n");
    y.push_str(&companions.card_body);
    y
}
