//! A built dataset read back from its folder alone (issue 14): `clips` listing and filters against
//! an independent reader, `export-bvh` from the shards against the config route, previews.
use crate::common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use common::*;
use motionforge::build::{BuildOptions, build, find_clip, stored_motion};
use motionforge::config::Config;
use motionforge::dataset::{self, ClipFilter};
use motionforge::motion::{read_bvh, write_bvh};

/// The demo built into a fresh folder, with its config pointed there.
fn demo() -> (tempfile::TempDir, Config) {
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config::load(&repo().join("fixtures/demo.toml")).unwrap();
    config.dataset.output = dir.path().to_path_buf();
    build(&config, &BuildOptions::default()).unwrap();
    (dir, config)
}

#[test]
fn clips_lists_every_row_and_filters_count_as_the_report_reader_does() {
    let (_dir, config) = demo();
    let ds = config.dataset_dir();
    let listed = dataset::list_clips(&ds).unwrap();
    // The report's own reader (another code path over the same shards) as the reference.
    let tables = motionforge::report::find_clip_tables(&ds).unwrap();
    let rows = motionforge::report::read_rows(&tables).unwrap();
    assert_eq!(listed.len(), rows.len());
    assert!(listed.len() >= 20, "{} rows", listed.len());
    for (a, b) in listed.iter().zip(&rows) {
        assert_eq!(
            (&a.clip_id, &a.split, &a.source_kind, a.mirrored, a.frames),
            (&b.clip_id, &b.split, &b.source_kind, b.mirrored, b.frames)
        );
        assert_eq!(a.motion_type, b.motion_type);
    }
    let count = |f: ClipFilter| dataset::find_clips(&ds, &f, None).unwrap().len();
    let mut by_type: BTreeMap<String, usize> = BTreeMap::new();
    for r in rows.iter().filter_map(|r| r.motion_type.clone()) {
        *by_type.entry(r).or_default() += 1;
    }
    assert!(by_type.contains_key("wave"));
    for (t, n) in &by_type {
        let f = ClipFilter {
            motion_type: Some(t.clone()),
            ..ClipFilter::default()
        };
        assert_eq!(count(f), *n, "type {t}");
    }
    for split in ["train", "val", "test"] {
        let f = ClipFilter {
            split: Some(split.into()),
            ..ClipFilter::default()
        };
        assert_eq!(
            count(f),
            rows.iter().filter(|r| r.split == split).count(),
            "{split}"
        );
    }
    let synthetic = rows.iter().filter(|r| r.source_kind == "synthetic").count();
    assert!(synthetic > 0);
    let kind = |k: &str| ClipFilter {
        kind: Some(k.into()),
        ..ClipFilter::default()
    };
    assert_eq!(count(kind("synthetic")), synthetic);
    assert_eq!(
        count(kind("mirrored")),
        rows.iter().filter(|r| r.mirrored).count()
    );
    // Text matches the caption, any case.
    let f = ClipFilter {
        text: Some("BYEBYE".into()),
        ..ClipFilter::default()
    };
    let hits = dataset::find_clips(&ds, &f, None).unwrap();
    assert!(!hits.is_empty());
    assert!(hits.iter().all(|c| c.clip_id.contains("byebye")));

    // The command: a JSON array with the same rows, and --limit.
    let out = run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .arg("clips")
            .arg(&ds)
            .args(["--type", "wave", "--json"]),
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json.as_array().unwrap().len(), by_type["wave"]);
    let out = run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .arg("clips")
            .arg(&ds)
            .args(["--limit", "3"]),
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(text.starts_with("clip_id"));
}

#[test]
fn unknown_clip_is_a_typed_error_with_near_ids() {
    let (_dir, config) = demo();
    let err = dataset::read_clip(&config.dataset_dir(), "cmu/01_01").unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("no clip `cmu/01_01`"), "{msg}");
    assert!(msg.contains("did you mean cmu/01_01:"), "{msg}");
}

/// Largest angle (degrees) between two rotations.
fn angle(a: glam::DQuat, b: glam::DQuat) -> f64 {
    (a.dot(b).abs().min(1.0).acos() * 2.0).to_degrees()
}

#[test]
fn export_bvh_from_the_shards_matches_the_config_route_on_every_demo_clip() {
    // Both routes write the same file: the config route writes the clip as the dataset stores it
    // (its f32 row, `build::stored_motion`), the shard route reads that row back.
    let (_dir, config) = demo();
    let ds = config.dataset_dir();
    let skeletons = dataset::read_skeletons(&ds).unwrap();
    let listed = dataset::list_clips(&ds).unwrap();
    let (mut worst_angle, mut worst_move) = (0.0f64, 0.0f64);
    let mut kinds = std::collections::BTreeSet::new();
    for row in &listed {
        let id = &row.clip_id;
        let (found, _) = find_clip(&config, &BuildOptions::default(), id).unwrap();
        let (clip, profile) = found.unwrap_or_else(|| panic!("{id} is not in the build"));
        let frames = dataset::read_clip(&ds, id).unwrap();
        let from_shards =
            dataset::skeletons::clip_motion(&frames, &skeletons[&frames.info.skeleton]).unwrap();
        let (ours, theirs) = (
            write_bvh(&from_shards).unwrap(),
            write_bvh(&stored_motion(&clip, &profile)).unwrap(),
        );
        assert!(ours == theirs, "{id}: the two routes write different files");
        // And that file is the build's clip to f32 precision.
        let (a, b) = (
            read_bvh(&ours).unwrap().motion,
            read_bvh(&write_bvh(&clip.motion).unwrap()).unwrap().motion,
        );
        assert_eq!(a.rotations.len(), b.rotations.len());
        for (p, q) in a.rotations.iter().zip(&b.rotations) {
            worst_angle = worst_angle.max(angle(*p, *q));
        }
        let scale = skeletons[&frames.info.skeleton].unit_scale;
        for (p, q) in a.translations.iter().zip(&b.translations) {
            worst_move = worst_move.max((*p - *q).length() * scale);
        }
        kinds.insert((frames.info.source_kind.clone(), frames.info.mirrored));
    }
    eprintln!("worst rotation {worst_angle:.2e} degrees, worst translation {worst_move:.2e} m");
    assert!(worst_angle < 1e-3, "{worst_angle} degrees");
    assert!(worst_move < 1e-5, "{worst_move} m");
    // Originals, mirrors and synthetic pairs were all compared.
    assert!(kinds.contains(&("real_single".into(), false)));
    assert!(kinds.contains(&("real_single".into(), true)));
    assert!(kinds.iter().any(|(k, _)| k == "synthetic"));
}

#[test]
fn export_bvh_command_writes_the_clip_from_the_dataset_folder() {
    let (dir, config) = demo();
    let ds = config.dataset_dir();
    let out = dir.path().join("clip.bvh");
    run_ok(
        Command::new(env!("CARGO_BIN_EXE_motionforge"))
            .arg("export-bvh")
            .arg(&ds)
            .args(["--clip", "cmu/01_01:1207-2407:m", "-o"])
            .arg(&out),
    );
    let bvh = read_bvh(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(bvh.motion.num_frames(), 300);
    assert_eq!(bvh.skeleton.joints[0].name, "Hips");
    // The file is the typed value the readers get, written back: nothing in it goes unread.
    let path = ds.join("skeletons.json");
    let written = std::fs::read_to_string(&path).unwrap();
    let typed = dataset::read_skeletons(&ds).unwrap();
    assert_eq!(motionforge::io::skeletons::skeletons_json(&typed), written);
    assert!(typed.values().any(|s| s.mirror_of.is_some()));
    // Skeletons with fields this reader does not know still read.
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    for (_, s) in json.as_object_mut().unwrap() {
        s["mirrored_skeleton"] = serde_json::json!({"joints": []});
    }
    std::fs::write(&path, json.to_string()).unwrap();
    assert!(dataset::read_skeletons(Path::new(&ds)).is_ok());
}

#[test]
fn preview_gif_has_the_clip_frames_at_its_rate_and_they_differ() {
    use motionforge::dataset::preview::{Panel, PreviewOptions, render};
    let (_dir, config) = demo();
    let ds = config.dataset_dir();
    let skeletons = dataset::read_skeletons(&ds).unwrap();
    for id in [
        "bandai-namco-1/dataset-1_kick_normal_001:0-358",
        "cmu/01_01:1207-2407:m",
    ] {
        let clip = dataset::read_clip(&ds, id).unwrap();
        let panel = Panel {
            frames: &clip,
            skeleton: &skeletons[&clip.info.skeleton],
        };
        let options = PreviewOptions::default();
        let preview = render(&[panel], &options).unwrap();
        let gif = preview.gif().unwrap();
        // Decoded with the gif crate's reader: frame count, delay, and distinct frames.
        let mut decoder = gif::DecodeOptions::new();
        decoder.set_color_output(gif::ColorOutput::Indexed);
        let mut reader = decoder.read_info(gif.as_slice()).unwrap();
        let mut frames = Vec::new();
        while let Some(frame) = reader.read_next_frame().unwrap() {
            assert_eq!(frame.delay, 5, "20 fps is 5 centiseconds");
            frames.push(frame.buffer.to_vec());
        }
        let expected = motionforge::motion::Motion::resampled_frames(
            clip.info.frames,
            clip.info.fps,
            options.fps,
        );
        assert_eq!(frames.len(), expected, "{id}");
        assert_eq!(
            expected,
            (clip.info.frames - 1) * 2 / 3 + 1,
            "{id}: 30 -> 20 fps"
        );
        let distinct: std::collections::BTreeSet<&Vec<u8>> = frames.iter().collect();
        assert!(
            distinct.len() * 2 > frames.len(),
            "{id}: {} distinct of {}",
            distinct.len(),
            frames.len()
        );
        // Not blank: the bones' colours are drawn on every frame.
        for f in &frames {
            assert!(f.iter().filter(|&&i| (2..=7).contains(&i)).count() > 100);
        }
        let png = preview.png().unwrap();
        assert_eq!(&png[1..4], b"PNG");
    }
}

#[test]
fn mirrored_preview_is_the_reflection_of_its_original() {
    use motionforge::dataset::preview::projected_points;
    let (_dir, config) = demo();
    let ds = config.dataset_dir();
    let skeletons = dataset::read_skeletons(&ds).unwrap();
    let clips = dataset::list_clips(&ds).unwrap();
    let mut pairs = 0;
    for original in clips
        .iter()
        .filter(|c| !c.mirrored && c.source_kind != "synthetic")
    {
        let mirror_id = format!("{}:m", original.clip_id);
        let a = dataset::read_clip(&ds, &original.clip_id).unwrap();
        let b = dataset::read_clip(&ds, &mirror_id).unwrap();
        let (sa, sb) = (&skeletons[&a.info.skeleton], &skeletons[&b.info.skeleton]);
        let (pa, pb) = (projected_points(&a, sa), projected_points(&b, sb));
        assert_eq!(pa.len(), pb.len());
        let n = a.info.joints;
        // Joint j of the mirror is the reflection of its partner in the original.
        let partner: Vec<usize> = sb
            .joints
            .iter()
            .map(|j| {
                let name = j.mirror.as_deref().unwrap_or(&j.name);
                sa.joints.iter().position(|k| k.name == name).unwrap()
            })
            .collect();
        assert!(partner.iter().enumerate().any(|(j, p)| j != *p));
        let mut worst = 0.0f64;
        let mut moved = 0.0f64;
        for f in 0..a.info.frames {
            for j in 0..n {
                let m = pb[f * n + j];
                let o = pa[f * n + partner[j]];
                worst = worst.max((m[0] + o[0]).abs()).max((m[1] - o[1]).abs());
                // Not trivially symmetric: the original's left and right differ.
                let own = pa[f * n + j];
                moved = moved.max((o[0] + own[0]).abs()).max((o[1] - own[1]).abs());
            }
        }
        eprintln!("{}: worst reflection error {worst:.4} m", original.clip_id);
        // Mirroring keeps each skeleton's own bone offsets (docs/mirroring.md): the drawings agree
        // to a few centimetres, where the original's left and right sides differ by decimetres.
        assert!(worst < 0.05, "{}: {worst} m", original.clip_id);
        assert!(moved > 0.1, "{}: {moved} m", original.clip_id);
        pairs += 1;
    }
    assert!(pairs >= 8, "{pairs} pairs");
}

/// Rewrites `shard` with pyarrow in another layout: `flat` as schema version 8 wrote it (every
/// per-frame array one flat list, goals and parts variable-length lists), `float64` with
/// `joint_positions` as doubles (a layout no version wrote).
fn rewrite_shard(shard: &Path, layout: &str) {
    let script = r#"
import sys, numpy as np, pyarrow as pa, pyarrow.parquet as pq
path, layout = sys.argv[1], sys.argv[2]
t = pq.read_table(path)
def flat(name, item):
    rows = [None if x is None else np.array(x).ravel().tolist() for x in t[name].to_pylist()]
    return pa.array(rows, type=pa.list_(item))
if layout == 'flat':
    for name in ['joint_positions', 'canonical_positions', 'local_rotations', 'root_translation',
                 'rotations_6d', 'joint_velocities', 'future_root', 'goal_pelvis', 'goal_hand']:
        t = t.set_column(t.schema.get_field_index(name), name, flat(name, pa.float32()))
    for name in ['foot_contacts', 'parts']:
        t = t.set_column(t.schema.get_field_index(name), name, flat(name, pa.bool_()))
    parts = t['composed_parts'].cast(pa.list_(pa.list_(pa.bool_())))
    t = t.set_column(t.schema.get_field_index('composed_parts'), 'composed_parts', parts)
else:
    t = t.set_column(t.schema.get_field_index('joint_positions'), 'joint_positions', flat('joint_positions', pa.float64()))
pq.write_table(t, path, compression="zstd")
print(t.schema.field('joint_positions').type)
"#;
    run_python(script, &[shard.as_os_str(), layout.as_ref()]);
}

/// A version 8 table (flat lists) reads as the same frames; a layout no version wrote is refused
/// with an error naming the shard and the column.
#[test]
fn a_version_8_flat_shard_reads_the_same_and_an_unknown_layout_is_refused() {
    let (_dir, config) = demo();
    let ds = config.dataset_dir();
    let shard = ds.join("data/validation-00000-of-00001.parquet");
    let before = dataset::list_clips(&ds).unwrap();
    let ids: Vec<String> = before
        .iter()
        .filter(|c| c.split == "validation")
        .map(|c| c.clip_id.clone())
        .collect();
    assert!(!ids.is_empty());
    let shaped: Vec<_> = ids
        .iter()
        .map(|id| dataset::read_clip(&ds, id).unwrap())
        .collect();
    rewrite_shard(&shard, "flat");
    assert_eq!(
        dataset::list_clips(&ds).unwrap(),
        before,
        "metadata of a v8 shard"
    );
    for (id, frames) in ids.iter().zip(&shaped) {
        assert_eq!(&dataset::read_clip(&ds, id).unwrap(), frames, "{id}");
    }
    rewrite_shard(&shard, "float64");
    let err = dataset::read_clip(&ds, &ids[0]).unwrap_err().to_string();
    assert!(
        err.contains("validation-00000-of-00001.parquet")
            && err.contains("`joint_positions`")
            && err.contains("Float64"),
        "{err}"
    );
}

/// Rows of `rgb` (`w` wide) holding a bone's colour (a saturated pixel), per band of `band`
/// rows: the first and last such row in each.
fn coloured_rows(rgb: &[u8], w: usize, band: std::ops::Range<usize>) -> Option<(usize, usize)> {
    let hit = |y: usize| {
        rgb[y * w * 3..(y + 1) * w * 3].chunks_exact(3).any(|p| {
            let (mx, mn) = (p.iter().max().unwrap(), p.iter().min().unwrap());
            mx - mn > 80
        })
    };
    let rows: Vec<usize> = band.filter(|&y| hit(y)).collect();
    Some((*rows.first()?, *rows.last()?))
}

/// `motionforge preview --with sources` of a synthetic pair of mirrored sources: every title
/// shows its whole id (a synthetic id is over 100 characters) and the `mirrored` marker, in
/// lines that each hold text; each panel fits its own clip, so the source that stays in place
/// is drawn tall however far the other walks (before: one scale for all, about 80 px of 280).
#[test]
fn preview_titles_show_whole_ids_and_sources_fit_their_own_panels() {
    use motionforge::dataset::preview::{PreviewOptions, title_lines};
    let (dir, config) = demo();
    let ds = config.dataset_dir();
    let clips = dataset::list_clips(&ds).unwrap();
    let by_id = |id: &str| clips.iter().find(|c| c.clip_id == id).unwrap();
    let pair = clips
        .iter()
        .find(|c| c.source_kind == "synthetic" && c.composed_from.iter().all(|s| by_id(s).mirrored))
        .unwrap();
    assert!(pair.clip_id.len() > 100, "{}", pair.clip_id);
    let out = dir.path().join("previews");
    let status = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .arg("preview")
        .arg(&ds)
        .args([
            "--clip",
            &pair.clip_id,
            "--with",
            "sources",
            "--strip",
            "1",
            "-o",
        ])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let stem = dataset::preview::file_stem(&pair.clip_id);
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(out.join(format!("{stem}.png"))).unwrap(),
    ));
    let mut reader = decoder.read_info().unwrap();
    let mut rgb = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut rgb).unwrap();
    let (w, h) = (info.width as usize, info.height as usize);
    let size = PreviewOptions::default().size as usize;
    assert_eq!(w, size, "one pose per row");

    // One row per panel: the pair, then its sources; each title whole, in the row's width.
    let panels: Vec<&dataset::ClipInfo> = std::iter::once(pair)
        .chain(pair.composed_from.iter().map(|s| by_id(s)))
        .collect();
    let titles: Vec<_> = panels
        .iter()
        .map(|c| title_lines(c, size as u32 - 8))
        .collect();
    for (c, (caption, id)) in panels.iter().zip(&titles) {
        assert_eq!(id.concat(), c.clip_id, "the id is cut: {id:?}");
        assert!(!caption.concat().contains('…'), "{caption:?}");
        assert_eq!(
            caption[0].starts_with("mirrored: "),
            c.mirrored,
            "{caption:?}"
        );
    }
    let band = h / 3 - size;
    let lines = titles.iter().map(|(c, i)| c.len() + i.len()).max().unwrap();
    assert!(
        lines >= 4 && band >= lines * 15,
        "{lines} lines in a {band}-pixel band"
    );
    for r in 0..3 {
        let top = r * (size + band);
        // Text on every line of the title (dark pixels).
        let (caption, id) = &titles[r];
        let mut y = top + 5;
        for (k, height) in std::iter::repeat_n(16, caption.len())
            .chain(std::iter::repeat_n(15, id.len()))
            .enumerate()
        {
            let ink = (y..y + height)
                .flat_map(|yy| rgb[yy * w * 3..(yy + 1) * w * 3].chunks_exact(3))
                .filter(|p| p.iter().all(|&v| v < 120))
                .count();
            assert!(ink > 5, "row {r}, title line {k}: {ink} dark pixels");
            y += height;
        }
        // The figure: tall in its panel when its clip stays in place.
        let (first, last) = coloured_rows(&rgb, w, top + band..top + band + size).unwrap();
        let tall = last - first;
        eprintln!(
            "panel {r} ({}): figure {tall} px of {size}",
            panels[r].clip_id
        );
        let walks = panels[r].goal_pelvis.is_some() || panels[r].action.contains("walk");
        if !walks {
            assert!(tall * 2 > size, "panel {r}: figure {tall} px of {size}");
        }
    }
}
