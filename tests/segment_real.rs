//! Segmentation on real captures and annotations (issue: segment captures by action).
use crate::common;

use std::path::Path;

use common::*;
use motionforge::annotate::babel::read_babel;
use motionforge::annotate::filename::filename_annotation;
use motionforge::annotate::frame_index::{index_annotations, read_frame_index};
use motionforge::annotate::span::{CaptureAnnotation, Span, Time};
use motionforge::annotate::taxonomy::{Taxonomy, TypeMap};
use motionforge::clip::{Capture, Clip, SourceKind};
use motionforge::config::SegmentConfig;
use motionforge::motion::{MirrorPlan, ProfileSpec};
use motionforge::source::{CaptureFile, capture_key};
use motionforge::stages::{ingest, mirror, segment};
use proptest::prelude::*;

fn capture(path: &Path, profile: &str) -> Capture {
    let bytes = std::fs::read(path).unwrap();
    let file = CaptureFile {
        source: 0,
        path: path.to_path_buf(),
        display: path.file_name().unwrap().to_string_lossy().into_owned(),
    };
    let spec = ProfileSpec::bundled(profile).unwrap();
    let sha256 = motionforge::base::sha256_hex(&bytes);
    let out = ingest::run(&ingest::CaptureInput {
        file: &file,
        bytes: &bytes,
        sha256: &sha256,
        source: "test",
        profile: &spec,
        fps_override: None,
        format: &ingest::Bvh,
    });
    out.capture.unwrap_or_else(|| panic!("{:?}", out.rejects))
}

fn demo_types() -> TypeMap {
    let text = std::fs::read_to_string(repo().join("fixtures/demo.toml")).unwrap();
    let config =
        motionforge::config::Config::parse(&text, &repo().join("fixtures/demo.toml")).unwrap();
    let cfg = config.motion_types.clone();
    TypeMap::new(
        Taxonomy::bundled()
            .unwrap()
            .with_extra(cfg.extra.clone())
            .unwrap(),
        &cfg,
    )
    .unwrap()
}

fn segment_with(
    capture: &Capture,
    annotation: &CaptureAnnotation,
    kind: &str,
    config: &SegmentConfig,
    types: &TypeMap,
) -> segment::SegmentOutput {
    segment_loaded(capture, annotation, kind, config, types).0
}

/// [`segment_with`], with the frames of every clip.
fn segment_loaded(
    capture: &Capture,
    annotation: &CaptureAnnotation,
    kind: &str,
    config: &SegmentConfig,
    types: &TypeMap,
) -> (segment::SegmentOutput, Vec<motionforge::motion::Motion>) {
    let profile = ProfileSpec::bundled(&capture.profile)
        .unwrap()
        .bind(&capture.motion.skeleton)
        .unwrap();
    segment::run_loaded(&segment::SegmentInput {
        capture,
        annotation,
        kind,
        config,
        types,
        profile: &profile,
        fps: 30.0,
    })
}

fn cmu_config() -> SegmentConfig {
    SegmentConfig {
        timeline_offset_frames: 1,
        ..SegmentConfig::default()
    }
}

fn ranges(clips: &[Clip], kind: SourceKind) -> Vec<(u64, u64)> {
    let mut r: Vec<(u64, u64)> = clips
        .iter()
        .filter(|c| c.kind == kind)
        .map(|c| c.frame_range)
        .collect();
    r.sort();
    r
}

#[test]
fn humanml3d_index_rows_cut_cmu_01_01_as_two_independent_clips() {
    let text = std::fs::read_to_string(shared_data().join("humanml3d/index.csv")).unwrap();
    let (rows, notes) = read_frame_index(&text, "index.csv").unwrap();
    assert!(notes.is_empty());
    let by_key = index_annotations(
        &rows,
        20.0,
        "index.csv",
        |p| capture_key(p, None),
        |_| None,
        "playground",
    );
    let annotation = &by_key["01_01"];
    let cmu = capture(&shared_data().join("cmu/01_01.bvh"), "cmu");
    let (out, motions) = segment_loaded(
        &cmu,
        annotation,
        "frame_index",
        &cmu_config(),
        &demo_types(),
    );
    // 19-219 and 201-401 at 20 fps are AMASS frames 114-1314 and 1206-2406 at 120 fps; the BVH's
    // added T-pose frame 0 shifts both by one.
    assert_eq!(
        ranges(&out.clips, SourceKind::RealSingle),
        vec![(115, 1315), (1207, 2407)]
    );
    assert!(
        ranges(&out.clips, SourceKind::RealPair).is_empty(),
        "index rows are independent crops"
    );
    assert_eq!(motions.len(), out.clips.len());
    for (clip, motion) in out.clips.iter().zip(&motions) {
        assert_eq!(motion.num_frames(), 300, "10 s at 30 fps");
        // The clip's first frame is the capture's frame `start`, resampled exactly (120 = 4 x 30).
        let first = motion.rotation(0, 3);
        assert!(first.abs_diff_eq(cmu.motion.rotation(clip.frame_range.0 as usize, 3), 1e-12));
    }
}

/// BABEL frame labels with the same spans as the HumanML3D rows, in seconds.
fn babel_like_index_rows() -> String {
    r#"{"9999": {"babel_sid": 9999, "dur": 22.93, "feat_p": "CMU/CMU/01/01_01_poses.npz",
        "frame_ann": {"labels": [
          {"raw_label": "jump forward", "proc_label": "jump forward", "act_cat": ["jump"], "seg_id": "b", "start_t": 10.05, "end_t": 20.05},
          {"raw_label": "walk", "proc_label": "walk", "act_cat": ["walk"], "seg_id": "a", "start_t": 0.95, "end_t": 10.95}
        ]}, "seq_ann": null}}"#
        .to_string()
}

#[test]
fn the_same_spans_as_babel_labels_also_give_their_overlap_as_a_real_pair() {
    let records = read_babel(&babel_like_index_rows(), "test.json").unwrap();
    let cmu = capture(&shared_data().join("cmu/01_01.bvh"), "cmu");
    let out = segment_with(
        &cmu,
        &records[0].annotation,
        "babel",
        &cmu_config(),
        &demo_types(),
    );
    assert_eq!(
        ranges(&out.clips, SourceKind::RealSingle),
        vec![(115, 1315), (1207, 2407)]
    );
    assert_eq!(ranges(&out.clips, SourceKind::RealPair), vec![(1207, 1315)]);
    let pair = out
        .clips
        .iter()
        .find(|c| c.kind == SourceKind::RealPair)
        .unwrap();
    assert_eq!(pair.texts, vec!["walk", "jump forward"]);
    assert_eq!(pair.text, "walk and jump forward at the same time");
}

#[test]
fn real_babel_records_parse_with_every_quirk_reported() {
    let path = shared_data().join("babel/babel_records_from_notebook_outputs.json");
    let records = read_babel(&std::fs::read_to_string(path).unwrap(), "babel.json").unwrap();
    assert_eq!(records.len(), 3);
    let by_sid = |sid: &str| records.iter().find(|r| r.sid == sid).unwrap();
    let kinds = |sid: &str| {
        by_sid(sid)
            .annotation
            .notes
            .iter()
            .map(|n| n.kind)
            .collect::<Vec<_>>()
    };
    // 7692: integer times, unsorted labels, `end_t` 3.834 past the 3.83 s duration.
    let k = kinds("7692");
    for expected in ["integer_times", "unsorted", "end_past_duration"] {
        assert!(
            k.iter().any(|x| x == expected),
            "7692 lacks {expected}: {k:?}"
        );
    }
    let hop = &by_sid("7692").annotation;
    assert_eq!(hop.spans.len(), 4);
    assert_eq!(
        hop.spans.last().unwrap().end,
        Time::Seconds(3.83),
        "clamped to the duration"
    );
    // 3312: every frame label is null; skipped and counted, none kept.
    assert!(kinds("3312").iter().any(|x| x == "null_label"));
    assert!(by_sid("3312").annotation.spans.is_empty());
    // 7536: a notebook row list with overlapping labels and no feat_p.
    let k = kinds("7536");
    assert!(k.iter().any(|x| x == "no_feat_p"), "{k:?}");
    let spans: Vec<&Span> = by_sid("7536").annotation.spans.iter().collect();
    assert_eq!(spans.len(), 6);
    let overlapping = spans
        .windows(2)
        .filter(|w| secs(w[1].start) < secs(w[0].end))
        .count();
    assert!(
        overlapping >= 2,
        "overlapping segments are kept as they are"
    );
}

fn secs(t: Time) -> f64 {
    match t {
        Time::Seconds(s) => s,
        _ => f64::NAN,
    }
}

#[test]
fn transition_labels_are_dropped_and_counted() {
    // 7536's rows with transitions, applied to CMU 01_01 (its own capture is not bundled).
    let path = shared_data().join("babel/babel_records_from_notebook_outputs.json");
    let records = read_babel(&std::fs::read_to_string(path).unwrap(), "babel.json").unwrap();
    let annotation = &records.iter().find(|r| r.sid == "7536").unwrap().annotation;
    let cmu = capture(&shared_data().join("cmu/01_01.bvh"), "cmu");
    let out = segment_with(&cmu, annotation, "babel", &cmu_config(), &demo_types());
    assert_eq!(out.drops.get("dropped_label"), Some(&2));
    let texts: Vec<&str> = out
        .clips
        .iter()
        .filter(|c| c.kind == SourceKind::RealSingle)
        .map(|c| c.text.as_str())
        .collect();
    assert_eq!(
        texts,
        vec![
            "walk",
            "make a knocking gesture",
            "turn around",
            "walk back"
        ]
    );
    // turn around (4.519-5.519) and walk back (5.424-7.734) overlap by 0.095 s: too short a pair.
    assert_eq!(out.drops.get("too_short"), Some(&1));
}

#[test]
fn fps_table_overrides_a_wrong_bvh_header() {
    let text = std::fs::read_to_string(shared_data().join("babel/featp_2_fps.json")).unwrap();
    let table: std::collections::BTreeMap<String, f64> = serde_json::from_str(&text).unwrap();
    let by_key: std::collections::BTreeMap<String, f64> = table
        .iter()
        .map(|(p, f)| (capture_key(p, None), *f))
        .collect();
    assert_eq!(
        by_key["141_05"], 60.0,
        "CMU 141_05 is 60 fps although its BVH says 120"
    );
    assert_eq!(by_key["01_01"], 120.0);
}

fn goal_of(content: &str, style: &str, mirrored: bool) -> [f64; 2] {
    let path = bandai1(content, style);
    let cap = capture(&path, "bandai-namco");
    let ann = filename_annotation(
        "dataset-1_{content}_{style}_{take}",
        "{content}",
        "{content}",
        &cap.stem,
        None,
    )
    .unwrap();
    let types = demo_types();
    let out = segment_with(&cap, &ann, "filename", &SegmentConfig::default(), &types);
    let clip = &out.clips[0];
    let clip = if mirrored {
        let spec = ProfileSpec::bundled("bandai-namco").unwrap();
        mirror::run(std::slice::from_ref(clip), &spec, types.taxonomy()).clips[0].clone()
    } else {
        clip.clone()
    };
    clip.goal_pelvis
        .unwrap_or_else(|| panic!("{content}: no pelvis goal ({:?})", clip.motion_type))
}

const STYLES: [&str; 15] = [
    "active",
    "angry",
    "childish",
    "chimpira",
    "feminine",
    "giant",
    "happy",
    "masculinity",
    "musical",
    "normal",
    "not-confident",
    "old",
    "proud",
    "sad",
    "tired",
];

/// Over all 15 styles: walk goes forward (+y); walk-left ends to the left (-x) and walk-right to
/// the right (+x) of where the character first faced; mirrored walk-left ends to the right.
/// Bandai's walk-left/right takes turn the pelvis 46-79 degrees toward the direction of travel, so
/// their goals also have a large forward part; the lateral sign is what separates them.
#[test]
fn locomotion_goals_point_where_the_character_walks() {
    for style in STYLES {
        let forward = goal_of("walk", style, false);
        let left = goal_of("walk-left", style, false);
        let right = goal_of("walk-right", style, false);
        let mirrored_left = goal_of("walk-left", style, true);
        println!(
            "{style}: walk {forward:.2?}, walk-left {left:.2?}, walk-right {right:.2?}, mirrored walk-left {mirrored_left:.2?}"
        );
        assert!(
            forward[1] > 4.0 && forward[0].abs() < 0.25 * forward[1],
            "{style}: walk goes forward: {forward:?}"
        );
        assert!(
            left[0] < -0.5 && left[1] > 0.0,
            "{style}: walk-left ends front-left: {left:?}"
        );
        assert!(
            right[0] > 0.5 && right[1] > 0.0,
            "{style}: walk-right ends front-right: {right:?}"
        );
        assert!(
            mirrored_left[0] > 0.5,
            "{style}: mirrored walk-left ends to the right: {mirrored_left:?}"
        );
        assert!(
            (mirrored_left[0] + left[0]).abs() < 1e-9 && (mirrored_left[1] - left[1]).abs() < 1e-9
        );
    }
}

#[test]
fn mirrored_goals_equal_goals_computed_from_the_mirrored_motion() {
    let path = bandai1("walk-left", "normal");
    let cap = capture(&path, "bandai-namco");
    let spec = ProfileSpec::bundled("bandai-namco").unwrap();
    let profile = spec.bind(&cap.motion.skeleton).unwrap();
    let plan = MirrorPlan::from_profile(&cap.motion.skeleton, &profile).unwrap();
    let ann = filename_annotation(
        "dataset-1_{content}_{style}_{take}",
        "{content}",
        "{content}",
        &cap.stem,
        None,
    )
    .unwrap();
    let types = demo_types();
    let direct =
        segment_with(&cap, &ann, "filename", &SegmentConfig::default(), &types).clips[0].clone();
    let by_negation =
        mirror::run(std::slice::from_ref(&direct), &spec, types.taxonomy()).clips[0].clone();
    // Segment the mirrored capture itself, labelled with the mirrored label.
    let mirrored_capture = Capture {
        motion: plan.mirror(&cap.motion, motionforge::motion::OffsetPolicy::Keep),
        ..cap.clone()
    };
    let ann_m = filename_annotation(
        "dataset-1_{content}_{style}_{take}",
        "walk-right",
        "walk right",
        &cap.stem,
        None,
    )
    .unwrap();
    let computed = segment_with(
        &mirrored_capture,
        &ann_m,
        "filename",
        &SegmentConfig::default(),
        &types,
    )
    .clips[0]
        .clone();
    let (a, b) = (
        by_negation.goal_pelvis.unwrap(),
        computed.goal_pelvis.unwrap(),
    );
    assert!(
        (a[0] - b[0]).abs() < 1e-3 && (a[1] - b[1]).abs() < 1e-3,
        "{a:?} vs {b:?}"
    );
    assert_eq!(by_negation.motion_type.as_deref(), Some("walk front right"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Random annotations, including times past the end, negative and `End`: no clip leaves its
    /// capture, and every span is either a clip or a counted drop.
    #[test]
    fn segments_never_extend_past_their_capture(spans in prop::collection::vec((-2.0f64..6.0, 0.0f64..5.0, any::<bool>()), 1..7)) {
        let cap = capture(&bandai1("walk", "normal"), "bandai-namco");
        let len = cap.motion.num_frames() as u64;
        let annotation = CaptureAnnotation {
            spans: spans.iter().enumerate().map(|(i, (s, d, to_end))| Span {
                start: Time::Seconds(*s),
                end: if *to_end { Time::End } else { Time::Seconds(s + d) },
                raw_text: format!("action {i}"),
                label: format!("action {i}"),
                categories: vec![], motion_type: None, hand: None, object: None, grasp: None,
                id: i.to_string(),
                alternatives: Vec::new(),
            }).collect(),
            simultaneous: true,
            ..CaptureAnnotation::default()
        };
        let out = segment_with(&cap, &annotation, "babel", &SegmentConfig::default(), &demo_types());
        for clip in &out.clips {
            prop_assert!(clip.frame_range.0 < clip.frame_range.1 && clip.frame_range.1 <= len, "{:?} of {len}", clip.frame_range);
        }
        let singles = out.clips.iter().filter(|c| c.kind == SourceKind::RealSingle).count();
        let single_drops: usize = ["dropped_label", "past_end", "empty_range", "trimmed"].iter().map(|r| out.drops.get(*r).copied().unwrap_or(0)).sum();
        // Length-filter drops are shared with pairs, so singles + their drops bound the span count.
        let length_drops = out.drops.get("too_short").copied().unwrap_or(0) + out.drops.get("too_long").copied().unwrap_or(0);
        prop_assert!(singles + single_drops <= spans.len() && spans.len() <= singles + single_drops + length_drops);
    }
}

#[test]
fn hand_goals_sit_at_the_grasp_frame_and_mirror_with_the_hand() {
    use motionforge::annotate::span::Hand;
    use motionforge::motion::canonical::{canonical_frame, dataset_positions};
    let cap = capture(&bandai2("raise-up-right-hand", 1), "bandai-namco");
    let annotation = CaptureAnnotation {
        spans: vec![Span {
            start: Time::Seconds(0.0),
            end: Time::End,
            raw_text: "raise the right hand and take the cup".into(),
            label: "pick up".into(),
            categories: vec![],
            motion_type: Some("pick up".into()),
            hand: Some(Hand::Right),
            object: Some("cup".into()),
            grasp: Some(Time::Seconds(1.0)),
            id: "row 1".into(),
            alternatives: Vec::new(),
        }],
        simultaneous: true,
        ..CaptureAnnotation::default()
    };
    let types = demo_types();
    let (out, motions) = segment_loaded(
        &cap,
        &annotation,
        "event_log",
        &SegmentConfig::default(),
        &types,
    );
    let (clip, motion) = (&out.clips[0], &motions[0]);
    assert_eq!(clip.motion_type.as_deref(), Some("pick up"));
    assert!(clip.goal_pelvis.is_none(), "pick up is not locomotion");
    let goal = clip
        .goal_hand
        .expect("pick up with a hand gets a hand goal");
    // Independently: the right hand at 1.0 s (frame 30 at 30 fps) in the first-frame frame.
    let profile = ProfileSpec::bundled("bandai-namco")
        .unwrap()
        .bind(&cap.motion.skeleton)
        .unwrap();
    let positions = dataset_positions(motion, &profile);
    let n = motion.num_joints();
    let frame = canonical_frame(&positions[..n], &profile).unwrap();
    let hand = cap.motion.skeleton.index_of("Hand_R").unwrap();
    let expected = frame.apply(positions[30 * n + hand]);
    assert!(
        (expected - glam::DVec3::from(goal)).length() < 1e-9,
        "{goal:?} vs {expected:?}"
    );
    assert!(
        goal[2] > 0.5,
        "a raised hand is well above the floor: {goal:?}"
    );
    let spec = ProfileSpec::bundled("bandai-namco").unwrap();
    let mirrored = &mirror::run(std::slice::from_ref(clip), &spec, types.taxonomy()).clips[0];
    assert_eq!(mirrored.hand, Some(Hand::Left));
    assert_eq!(mirrored.goal_hand, Some([-goal[0], goal[1], goal[2]]));
    assert_eq!(mirrored.texts, vec!["raise the left hand and take the cup"]);
}

#[test]
fn leading_trim_and_pair_exclusions_drop_what_they_should_and_count_it() {
    let records = read_babel(&babel_like_index_rows(), "test.json").unwrap();
    let cmu = capture(&shared_data().join("cmu/01_01.bvh"), "cmu");
    // A 1 s trim cuts the first label's start (frame 115) to frame 120; the second is untouched.
    let trimmed = SegmentConfig {
        trim_start_seconds: 1.0,
        ..cmu_config()
    };
    let out = segment_with(
        &cmu,
        &records[0].annotation,
        "babel",
        &trimmed,
        &demo_types(),
    );
    assert_eq!(
        ranges(&out.clips, SourceKind::RealSingle),
        vec![(120, 1315), (1207, 2407)]
    );
    // A trim past a label's end drops it, counted as trimmed.
    let long_trim = SegmentConfig {
        trim_start_seconds: 11.0,
        ..cmu_config()
    };
    let out = segment_with(
        &cmu,
        &records[0].annotation,
        "babel",
        &long_trim,
        &demo_types(),
    );
    assert_eq!(out.drops.get("trimmed"), Some(&1), "{:?}", out.drops);
    // Pairs that involve an excluded word are dropped (SINC drops pairs with `stand`).
    let exclude = SegmentConfig {
        pair_exclude: vec!["walk".into()],
        ..cmu_config()
    };
    let out = segment_with(
        &cmu,
        &records[0].annotation,
        "babel",
        &exclude,
        &demo_types(),
    );
    assert!(ranges(&out.clips, SourceKind::RealPair).is_empty());
    assert_eq!(out.drops.get("excluded_pair"), Some(&1));
    assert_eq!(
        ranges(&out.clips, SourceKind::RealSingle).len(),
        2,
        "singles are kept"
    );
}

#[test]
fn babel_extra_files_cut_the_first_annotation_and_keep_every_annotators_texts() {
    // The real record 7692, rewritten in the shape of BABEL's extra files: lists of annotations
    // (`frame_anns`, `seq_anns`) instead of one `frame_ann` and `seq_ann`. The second annotator
    // segments the same motion a little differently, as BABEL's do.
    let path = common::shared_data().join("babel/babel_records_from_notebook_outputs.json");
    let text = std::fs::read_to_string(path).unwrap();
    let main = read_babel(&text, "babel.json").unwrap();
    let root: serde_json::Value = serde_json::from_str(&text).unwrap();
    let records = root.get("records").unwrap_or(&root);
    let record = records["7692"].get("record").unwrap_or(&records["7692"]);
    let mut extra = record.clone();
    let object = extra.as_object_mut().unwrap();
    let frame_ann = object.remove("frame_ann").unwrap();
    let seq_ann = object.remove("seq_ann").unwrap();
    let mut second = frame_ann.clone();
    let label = |text: &str, start: f64, end: f64| serde_json::json!({"raw_label": text, "proc_label": text, "start_t": start, "end_t": end});
    second["labels"] = serde_json::json!([
        label("hop to the left", 1.1, 2.05),
        label("hopping right", 2.0, 3.0),
        label("stand still", 0.0, 0.8),
        label("wave", 0.2, 3.6),
    ]);
    object.insert("frame_anns".into(), serde_json::json!([frame_ann, second]));
    object.insert("seq_anns".into(), serde_json::json!([seq_ann]));
    let extra_text = serde_json::json!({ "7692": extra }).to_string();
    let read = read_babel(&extra_text, "extra.json").unwrap();
    let original = main.iter().find(|r| r.sid == "7692").unwrap();
    assert_eq!(read[0].feat_p, original.feat_p);
    // The first annotation's spans are the clips, each with the texts of the spans that cover it
    // by at least half (intersection over union); a text already there is not repeated.
    let spans = &read[0].annotation.spans;
    assert_eq!(spans.len(), original.annotation.spans.len());
    for (span, first) in spans.iter().zip(&original.annotation.spans) {
        assert_eq!(
            (&span.raw_text, span.start, span.end),
            (&first.raw_text, first.start, first.end)
        );
    }
    let captions: Vec<(&str, Vec<&str>)> = spans
        .iter()
        .map(|s| {
            (
                s.raw_text.as_str(),
                s.alternatives.iter().map(String::as_str).collect(),
            )
        })
        .collect();
    assert_eq!(
        captions,
        [
            ("standing", vec!["stand still"]),
            ("hopping left", vec!["hop to the left"]),
            ("hopping right", vec![]),
            ("standing", vec![]),
        ]
    );
    let notes = |kind: &str| -> Vec<String> {
        read[0]
            .annotation
            .notes
            .iter()
            .filter(|n| n.kind == kind)
            .map(|n| n.message.clone())
            .collect()
    };
    assert_eq!(
        notes("several_annotations"),
        [
            "sid 7692: 2 annotations in `frame_anns`; the first's spans are cut, the others' texts added to the spans they cover"
        ]
    );
    assert_eq!(
        notes("unmatched_annotation"),
        [
            "sid 7692: annotation 2's `wave` (0.2 to 3.6 s) covers no span of the first annotation; not cut"
        ]
    );
    // Only sequence labels: the first of `seq_anns` covers the capture.
    let object = extra.as_object_mut().unwrap();
    object.remove("frame_anns");
    let only_seq = serde_json::json!({ "7692": extra }).to_string();
    let read = read_babel(&only_seq, "extra.json").unwrap();
    let texts: Vec<&str> = read[0]
        .annotation
        .spans
        .iter()
        .map(|s| s.raw_text.as_str())
        .collect();
    assert_eq!(texts, ["jump"]);
}
