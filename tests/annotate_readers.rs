//! Frame-range index and event-log readers, on real data: HumanML3D's `index.csv`, and event logs
//! written from a real BABEL record (sid 7536) and the BABEL action classes.

use crate::common;

use std::collections::{BTreeMap, BTreeSet};

use motionforge::annotate::event_log::{EventLogFormat, RowFault, read_event_log};
use motionforge::annotate::frame_index::{
    IndexRow, index_annotations, read_caption, read_frame_index, split_csv_line,
};
use motionforge::annotate::span::{AnnotationFault, CaptureAnnotation, Hand, Span, Time, stem_of};
use serde_json::Value;

// ---------------------------------------------------------------------------------------------
// HumanML3D index.csv
// ---------------------------------------------------------------------------------------------

fn real_index() -> (String, String) {
    let path = common::shared_data().join("humanml3d/index.csv");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (text, path.display().to_string())
}

/// The capture key the tests use: the file stem without AMASS's `_poses` suffix.
fn capture_key(source_path: &str) -> String {
    let stem = stem_of(source_path);
    stem.strip_suffix("_poses").unwrap_or(&stem).to_string()
}

#[test]
fn real_index_parses_every_row() {
    let (text, file) = real_index();
    let (rows, notes) = read_frame_index(&text, &file).unwrap();
    assert_eq!(rows.len(), 14_616);
    assert!(
        notes.is_empty(),
        "unexpected notes: {:?}",
        &notes[..notes.len().min(5)]
    );
    // Lines are 1-based and the header is line 1.
    assert_eq!(rows[0].line, 2);
    assert_eq!(
        rows[0].source_path,
        "./pose_data/KIT/3/kick_high_left02_poses.npy"
    );
    assert_eq!((rows[0].start_frame, rows[0].end_frame), (0, 117));
    assert_eq!(rows[0].new_name, "000000.npy");
    assert_eq!(rows.last().unwrap().line, 14_617);
    let sources: BTreeSet<&str> = rows.iter().map(|r| r.source_path.as_str()).collect();
    assert_eq!(sources.len(), 11_715);
    let names: BTreeSet<&str> = rows.iter().map(|r| r.new_name.as_str()).collect();
    assert_eq!(names.len(), rows.len(), "new_name is unique");
    assert!(rows.iter().all(|r| r.start_frame >= 0));
    assert!(
        rows.iter()
            .all(|r| r.end_frame == -1 || r.end_frame >= r.start_frame)
    );
}

#[test]
fn real_index_rows_of_cmu_01_01() {
    let (text, file) = real_index();
    let (rows, _) = read_frame_index(&text, &file).unwrap();
    let mut of: Vec<(i64, i64, &str)> = rows
        .iter()
        .filter(|r| r.source_path == "./pose_data/CMU/01/01_01_poses.npy")
        .map(|r| (r.start_frame, r.end_frame, r.new_name.as_str()))
        .collect();
    of.sort();
    assert_eq!(of, vec![(19, 219, "004041.npy"), (201, 401, "002510.npy")]);
}

#[test]
fn real_index_minus_one_means_end_of_capture() {
    let (text, file) = real_index();
    let (rows, _) = read_frame_index(&text, &file).unwrap();
    let to_end: Vec<&IndexRow> = rows.iter().filter(|r| r.end_frame == -1).collect();
    assert_eq!(to_end.len(), 1_191);
    let captures = index_annotations(&rows, 20.0, &file, capture_key, |_| None, "");
    let mut ends = 0;
    for a in captures.values() {
        for s in &a.spans {
            if s.end == Time::End {
                ends += 1;
            } else {
                assert!(matches!(s.end, Time::Frame { fps, .. } if fps == 20.0));
            }
        }
    }
    assert_eq!(ends, 1_191);
    // The second row of the file is a humanact12 crop to the end.
    let row = &rows[1];
    assert_eq!(row.end_frame, -1);
    let a = &captures[&capture_key(&row.source_path)];
    let span = a.spans.iter().find(|s| s.id == row.new_name).unwrap();
    assert_eq!(
        span.start,
        Time::Frame {
            frame: 0,
            fps: 20.0
        }
    );
    assert_eq!(span.end, Time::End);
}

#[test]
fn real_index_groups_by_capture_key() {
    let (text, file) = real_index();
    let (rows, _) = read_frame_index(&text, &file).unwrap();
    // A real caption-file line, HumanML3D's `caption#tokens#start#end`, with CMU's description
    // of take 01_01.
    let caption_file = "playground - forward jumps, turn around#playground/NOUN forward/ADV \
                        jump/NOUN turn/VERB around/ADV#0.0#0.0\nsecond caption#x#0.0#0.0\n";
    let captions: BTreeMap<&str, String> =
        BTreeMap::from([("004041", read_caption(caption_file).unwrap())]);
    let texts = |name: &str| captions.get(stem_of(name).as_str()).cloned();
    let captures = index_annotations(&rows, 20.0, &file, capture_key, texts, "unknown");
    let a = &captures["01_01"];
    assert!(!a.simultaneous);
    assert_eq!(a.spans.len(), 2);
    let s0 = &a.spans[0];
    assert_eq!(
        s0.start,
        Time::Frame {
            frame: 19,
            fps: 20.0
        }
    );
    assert_eq!(
        s0.end,
        Time::Frame {
            frame: 219,
            fps: 20.0
        }
    );
    assert_eq!(s0.id, "004041.npy");
    assert_eq!(s0.raw_text, "playground - forward jumps, turn around");
    assert_eq!(s0.label, s0.raw_text);
    let s1 = &a.spans[1];
    assert_eq!(
        s1.start,
        Time::Frame {
            frame: 201,
            fps: 20.0
        }
    );
    assert_eq!(
        s1.end,
        Time::Frame {
            frame: 401,
            fps: 20.0
        }
    );
    assert_eq!(s1.id, "002510.npy");
    assert_eq!(s1.raw_text, "unknown");
    assert!(s0.motion_type.is_none() && s0.hand.is_none() && s0.grasp.is_none());
    assert!(s0.categories.is_empty());
    assert!(a.origin.starts_with(&file));
    let kinds: Vec<&str> = a.notes.iter().map(|n| n.kind.as_str()).collect();
    assert_eq!(kinds, vec!["no_caption"]);
    assert!(a.notes[0].message.contains("002510.npy"));
    // Every row lands somewhere; stems repeat across KIT subject folders, which is flagged.
    assert_eq!(
        captures.values().map(|a| a.spans.len()).sum::<usize>(),
        14_616
    );
    assert_eq!(captures.len(), 9_150);
    let collisions = captures
        .values()
        .filter(|a| a.notes.iter().any(|n| n.kind == "key_collision"))
        .count();
    assert_eq!(collisions, 978);
    // A key that keeps the folder separates them again.
    let by_path = index_annotations(&rows, 20.0, &file, |p| p.to_string(), |_| None, "");
    assert_eq!(by_path.len(), 11_715);
    assert!(
        by_path
            .values()
            .all(|a| a.notes.iter().all(|n| n.kind != "key_collision"))
    );
}

#[test]
fn damaged_index_rows_become_notes() {
    let text = "source_path,start_frame,end_frame,new_name\r\n\
                ./pose_data/CMU/01/01_01_poses.npy,19,219,004041.npy\r\n\
                ./pose_data/CMU/01/01_01_poses.npy,201,002510.npy\r\n\
                ./pose_data/CMU/01/01_01_poses.npy,nineteen,219,004042.npy\r\n\
                \"./pose_data/CMU/01/01_01, take 2_poses.npy\",0,-1,004043.npy\r\n\
                \"./pose_data/say \"\"hi\"\"_poses.npy\", 5 , 10 ,004044.npy\r\n\
                ./pose_data/a_poses.npy,-3,10,004045.npy\r\n\
                ./pose_data/a_poses.npy,30,10,004046.npy\r\n\
                ./pose_data/a_poses.npy,0,-2,004047.npy\r\n\
                \"./pose_data/unclosed,0,10,004048.npy\r\n\
                ./pose_data/a_poses.npy,0,,004049.npy\r\n\
                ./pose_data/a_poses.npy,1.5,10,004050.npy\r\n\
                \r\n\
                ./pose_data/a_poses.npy,0,10,\r\n";
    let (rows, notes) = read_frame_index(text, "index.csv").unwrap();
    let kept: Vec<(&str, i64, i64, &str, u64)> = rows
        .iter()
        .map(|r| {
            (
                r.source_path.as_str(),
                r.start_frame,
                r.end_frame,
                r.new_name.as_str(),
                r.line,
            )
        })
        .collect();
    assert_eq!(
        kept,
        vec![
            (
                "./pose_data/CMU/01/01_01_poses.npy",
                19,
                219,
                "004041.npy",
                2
            ),
            (
                "./pose_data/CMU/01/01_01, take 2_poses.npy",
                0,
                -1,
                "004043.npy",
                5
            ),
            ("./pose_data/say \"hi\"_poses.npy", 5, 10, "004044.npy", 6),
        ]
    );
    assert!(notes.iter().all(|n| n.kind == "bad_row"));
    let lines: Vec<&str> = notes
        .iter()
        .map(|n| {
            n.message
                .strip_prefix("index.csv:")
                .and_then(|m| m.split(':').next())
                .unwrap()
        })
        .collect();
    assert_eq!(lines, vec!["3", "4", "7", "8", "9", "10", "11", "12", "14"]);
    assert!(
        notes[0].message.contains("expected 4 columns"),
        "{}",
        notes[0].message
    );
    assert!(notes[0].message.contains("found 3"), "{}", notes[0].message);
    assert!(
        notes[1]
            .message
            .contains("start_frame `nineteen` is not an integer")
    );
    assert!(notes[2].message.contains("negative"));
    assert!(notes[3].message.contains("after end_frame"));
    assert!(notes[4].message.contains("-1"));
    assert!(notes[5].message.contains("not closed"));
    assert!(notes[6].message.contains("end_frame ``"));
    assert!(notes[7].message.contains("`1.5`"));
    assert!(notes[8].message.contains("new_name is empty"));
    // The comma inside quotes stays in the path; the stem keeps it.
    let captures = index_annotations(&rows, 20.0, "index.csv", capture_key, |_| None, "");
    assert!(captures.contains_key("01_01, take 2"));
    assert_eq!(captures["01_01, take 2"].spans[0].end, Time::End);
}

#[test]
fn index_header_errors() {
    for text in [
        "",
        "\n\n",
        "./pose_data/CMU/01/01_01_poses.npy,19,219,004041.npy\n",
        "source_path,start_frame,end_frame\nx,1,2\n",
        "source_path,start_frame,end_frame,new_name,extra\nx,1,2,y,z\n",
        "source_path,start_frame,start_frame,new_name\n",
    ] {
        let err = read_frame_index(text, "index.csv").unwrap_err();
        assert_eq!(err.file, "index.csv");
        assert!(
            err.to_string()
                .contains("source_path,start_frame,end_frame,new_name"),
            "{err}"
        );
    }
    let err = read_frame_index("a,b\n", "index.csv").unwrap_err();
    assert_eq!(err.line, Some(1));
    assert!(
        err.to_string()
            .starts_with("index.csv:1: expected the header"),
        "{err}"
    );
    // Columns are found by name, in any order, with a byte-order mark tolerated.
    let (rows, notes) = read_frame_index(
        "\u{feff}new_name,source_path,end_frame,start_frame\n004041.npy,./a_poses.npy,219,19\n",
        "index.csv",
    )
    .unwrap();
    assert!(notes.is_empty());
    assert_eq!((rows[0].start_frame, rows[0].end_frame), (19, 219));
    assert_eq!(rows[0].new_name, "004041.npy");
}

#[test]
fn csv_splitter_and_captions() {
    assert_eq!(split_csv_line("a,b,,c\r").unwrap(), vec!["a", "b", "", "c"]);
    assert_eq!(
        split_csv_line("\"a,b\",\"say \"\"hi\"\"\"").unwrap(),
        vec!["a,b", "say \"hi\""]
    );
    assert_eq!(split_csv_line("").unwrap(), vec![""]);
    assert_eq!(split_csv_line("x,").unwrap(), vec!["x", ""]);
    assert!(split_csv_line("\"a\"b,c").is_err());
    assert!(split_csv_line("a\"b").is_err());
    assert!(split_csv_line("\"abc").is_err());
    assert_eq!(
        read_caption("\u{feff}a man kicks#a/DET man/NOUN kick/VERB#0.0#0.0\r\nother#x#0#0"),
        Some("a man kicks".into())
    );
    assert_eq!(
        read_caption("\n#tokens#0#0\nsecond#t#0#0\n"),
        Some("second".into())
    );
    assert_eq!(
        read_caption("no tokens here"),
        Some("no tokens here".into())
    );
    assert_eq!(read_caption(""), None);
    assert_eq!(read_caption("  \n#x#0#0\n"), None);
}

// ---------------------------------------------------------------------------------------------
// Event logs from a real BABEL record
// ---------------------------------------------------------------------------------------------

/// `[label, start_t, end_t]` rows of BABEL sid 7536 as saved in the notebook outputs.
fn babel_7536() -> Vec<(String, f64, f64)> {
    let path = common::shared_data().join("babel/babel_records_from_notebook_outputs.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let root: Value = serde_json::from_str(&text).unwrap();
    let rows = root["records"]["7536"]["frame_labels_raw_start_end"]
        .as_array()
        .expect("sid 7536 has frame_labels_raw_start_end");
    rows.iter()
        .map(|r| {
            (
                r[0].as_str().unwrap().to_string(),
                r[1].as_f64().unwrap(),
                r[2].as_f64().unwrap(),
            )
        })
        .collect()
}

/// The BABEL action class a label of 7536 belongs to (every one a real class name), if any.
fn motion_type(label: &str) -> Option<&'static str> {
    match label {
        "walk" | "walk back" => Some("walk"),
        "make a knocking gesture" => Some("knock"),
        "turn around" => Some("turn"),
        _ => None,
    }
}

fn csv_quote(s: &str) -> String {
    if s.contains([',', '"']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// One event row: (time, event, instruction, motion_type, hand, object).
type Row<'a> = (
    f64,
    &'a str,
    &'a str,
    Option<&'a str>,
    Option<&'a str>,
    Option<&'a str>,
);

fn csv_log(rows: &[Row]) -> String {
    // Columns in an unusual order, to check they are found by name.
    let mut out = String::from("instruction,time,event,motion_type,hand,object\r\n");
    for (t, event, instruction, mt, hand, object) in rows {
        out.push_str(&format!(
            "{},{t},{event},{},{},{}\r\n",
            csv_quote(instruction),
            mt.unwrap_or(""),
            hand.unwrap_or(""),
            object.map(csv_quote).unwrap_or_default()
        ));
    }
    out
}

fn json_log(rows: &[Row], capture: &str) -> String {
    let events: Vec<Value> = rows
        .iter()
        .map(|(t, event, instruction, mt, hand, object)| {
            let mut o = serde_json::Map::new();
            o.insert("time".into(), serde_json::json!(t));
            o.insert("event".into(), serde_json::json!(event));
            o.insert("instruction".into(), serde_json::json!(instruction));
            o.insert("motion_type".into(), serde_json::json!(mt));
            if let Some(h) = hand {
                o.insert("hand".into(), serde_json::json!(h));
            }
            if let Some(x) = object {
                o.insert("object".into(), serde_json::json!(x));
            }
            Value::Object(o)
        })
        .collect();
    serde_json::to_string_pretty(&serde_json::json!({"capture": capture, "events": events}))
        .unwrap()
}

/// The 7536 labels as instruction events at their BABEL start times.
fn rows_7536(labels: &[(String, f64, f64)]) -> Vec<Row<'_>> {
    labels
        .iter()
        .map(|(l, s, _)| (*s, "instruction", l.as_str(), motion_type(l), None, None))
        .collect()
}

fn only(map: BTreeMap<String, CaptureAnnotation>, key: &str) -> CaptureAnnotation {
    assert_eq!(map.keys().collect::<Vec<_>>(), vec![key]);
    map.into_values().next().unwrap()
}

fn secs(t: Time) -> f64 {
    match t {
        Time::Seconds(s) => s,
        other => panic!("expected seconds, found {other:?}"),
    }
}

#[test]
fn instructions_last_until_the_next() {
    let labels = babel_7536();
    assert_eq!(labels.len(), 6);
    assert_eq!(labels[0], ("walk".to_string(), 0.0, 2.106));
    assert_eq!(labels[2].0, "make a knocking gesture");
    let a = only(
        read_event_log(
            &csv_log(&rows_7536(&labels)),
            EventLogFormat::Csv,
            "logs/7536.csv",
            30.0,
        )
        .unwrap(),
        "7536",
    );
    assert!(a.simultaneous);
    assert!(a.notes.is_empty(), "{:?}", a.notes);
    assert_eq!(a.spans.len(), 6);
    for (i, (span, (label, start, _))) in a.spans.iter().zip(&labels).enumerate() {
        assert_eq!(span.raw_text, *label);
        assert_eq!(span.start, Time::Seconds(*start));
        assert_eq!(span.id, format!("row {}", i + 1));
        match labels.get(i + 1) {
            Some((_, next, _)) => assert_eq!(span.end, Time::Seconds(*next)),
            None => assert_eq!(span.end, Time::End),
        }
        assert_eq!(span.motion_type.as_deref(), motion_type(label));
        assert_eq!(span.label, motion_type(label).unwrap_or(label));
        assert!(span.hand.is_none() && span.grasp.is_none() && span.object.is_none());
    }
    // BABEL's overlapping segments (transition 3.466 inside the knocking gesture) become a
    // partition: the knocking gesture ends where the transition starts.
    assert_eq!(a.spans[2].end, Time::Seconds(3.466));
    assert_eq!(a.spans[3].end, Time::Seconds(4.519));
    // The motion types are real BABEL action classes.
    let classes: Value = serde_json::from_str(
        &std::fs::read_to_string(common::shared_data().join("babel/action_label_2_idx.json"))
            .unwrap(),
    )
    .unwrap();
    for s in &a.spans {
        if let Some(mt) = &s.motion_type {
            assert!(classes.get(mt).is_some(), "{mt} is not a BABEL class");
        }
    }
}

#[test]
fn csv_and_json_logs_agree() {
    let labels = babel_7536();
    let mut rows = rows_7536(&labels);
    // A grasp during the knocking gesture, and a release after it, as a planner would log them.
    rows.push((3.1, "grasp", "", None, Some("right"), Some("door, front")));
    rows.push((3.4, "release", "", None, Some("right"), None));
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let csv = read_event_log(&csv_log(&rows), EventLogFormat::Csv, "logs/7536.csv", 30.0).unwrap();
    let json = read_event_log(
        &json_log(&rows, "7536"),
        EventLogFormat::Json,
        "logs/planner.json",
        30.0,
    )
    .unwrap();
    // A bare array works too (the key then comes from the file name).
    let bare: Value = serde_json::from_str(&json_log(&rows, "7536")).unwrap();
    let bare = read_event_log(
        &serde_json::to_string_pretty(&bare["events"]).unwrap(),
        EventLogFormat::Json,
        "logs/7536.json",
        30.0,
    )
    .unwrap();
    let strip = |m: BTreeMap<String, CaptureAnnotation>| -> BTreeMap<String, CaptureAnnotation> {
        m.into_iter()
            .map(|(k, mut a)| {
                a.origin.clear();
                (k, a)
            })
            .collect()
    };
    let (csv, json, bare) = (strip(csv), strip(json), strip(bare));
    assert_eq!(csv, json);
    assert_eq!(csv, bare);
    let a = &csv["7536"];
    assert_eq!(a.spans.len(), 6);
    let knock = &a.spans[2];
    assert_eq!(knock.grasp, Some(Time::Seconds(3.1)));
    assert_eq!(knock.hand, Some(Hand::Right));
    assert_eq!(knock.object.as_deref(), Some("door, front"));
    assert!(a.spans.iter().filter(|s| s.grasp.is_some()).count() == 1);
    assert!(a.notes.is_empty(), "{:?}", a.notes);
}

#[test]
fn concurrent_instructions_span_to_the_next_later_one() {
    let labels = babel_7536();
    let mut rows = rows_7536(&labels);
    // The sequence label of 7536 ("pace and shake hand") given at the same time as the knocking
    // gesture, and before it in the file; the knocking gesture is done with the right hand.
    rows[2].4 = Some("right");
    rows.insert(
        2,
        (
            2.845,
            "instruction",
            "pace and shake hand",
            None,
            None,
            None,
        ),
    );
    rows.push((3.2, "grasp", "", None, Some("right"), None));
    rows.push((2.9, "grasp", "", None, None, None));
    let a = only(
        read_event_log(&csv_log(&rows), EventLogFormat::Csv, "7536.csv", 30.0).unwrap(),
        "7536",
    );
    assert_eq!(a.spans.len(), 7);
    let (pace, knock) = (&a.spans[2], &a.spans[3]);
    assert_eq!(pace.raw_text, "pace and shake hand");
    assert_eq!(knock.raw_text, "make a knocking gesture");
    assert_eq!(pace.start, Time::Seconds(2.845));
    assert_eq!(knock.start, Time::Seconds(2.845));
    assert_eq!(pace.end, Time::Seconds(3.466));
    assert_eq!(knock.end, Time::Seconds(3.466));
    // The previous instruction ends where both start.
    assert_eq!(a.spans[1].end, Time::Seconds(2.845));
    // The right-hand grasp goes to the right-hand instruction, the handless one to the first.
    assert_eq!(knock.grasp, Some(Time::Seconds(3.2)));
    assert_eq!(knock.hand, Some(Hand::Right));
    assert_eq!(pace.grasp, Some(Time::Seconds(2.9)));
    assert_eq!(pace.hand, None);
    // Events out of order are sorted, with a note.
    assert_eq!(
        a.notes.iter().map(|n| n.kind.as_str()).collect::<Vec<_>>(),
        vec!["unsorted"]
    );
}

#[test]
fn grasp_sets_hand_when_unset_and_events_before_instructions_are_noted() {
    let labels = babel_7536();
    let mut rows = rows_7536(&labels);
    // Instructions start later than 0 here: shift everything by one second.
    for r in &mut rows {
        r.0 += 1.0;
    }
    rows.insert(0, (0.5, "release", "", None, Some("left"), None));
    rows.insert(0, (0.25, "grasp", "", None, Some("left"), None));
    rows.push((5.0, "grasp", "", None, Some("left"), None));
    rows.push((5.1, "grasp", "", None, Some("left"), None));
    rows.push((6.0, "release", "", None, Some("left"), None));
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let map = read_event_log(&csv_log(&rows), EventLogFormat::Csv, "7536.csv", 30.0).unwrap();
    let a = only(map, "7536");
    // 5.0 falls in "transition" [4.466, 5.519).
    let t = a.spans.iter().find(|s| s.grasp.is_some()).unwrap();
    assert_eq!(t.raw_text, "transition");
    assert!((secs(t.start) - 4.466).abs() < 1e-9);
    assert_eq!(t.grasp, Some(Time::Seconds(5.0)));
    assert_eq!(t.hand, Some(Hand::Left));
    let kinds: Vec<&str> = a.notes.iter().map(|n| n.kind.as_str()).collect();
    assert_eq!(
        kinds,
        vec![
            "event_before_instruction",
            "event_before_instruction",
            "second_grasp"
        ]
    );
    assert!(a.notes[0].message.contains("grasp"));
    assert!(a.notes[1].message.contains("release"));
}

#[test]
fn frame_rows_keep_frames() {
    let labels = babel_7536();
    // The same log at 30 fps frames, as SINC/TEACH place seconds: floor(t * fps).
    let mut csv = String::from("frame,instruction,motion_type,event,capture\n");
    for (label, start, _) in &labels {
        let frame = Time::Seconds(*start).to_frame(30.0, u64::MAX);
        csv.push_str(&format!(
            "{frame},{label},{},,CMU/86/86_08\n",
            motion_type(label).unwrap_or("")
        ));
    }
    csv.push_str("95,,,grasp,CMU/86/86_08\n");
    let a = only(
        read_event_log(&csv, EventLogFormat::Csv, "planner_log.csv", 30.0).unwrap(),
        "CMU/86/86_08",
    );
    let frames: Vec<i64> = a
        .spans
        .iter()
        .map(|s| match s.start {
            Time::Frame { frame, fps } => {
                assert_eq!(fps, 30.0);
                frame
            }
            other => panic!("expected a frame, found {other:?}"),
        })
        .collect();
    assert_eq!(frames, vec![0, 63, 85, 103, 135, 162]);
    assert_eq!(
        a.spans[0].end,
        Time::Frame {
            frame: 63,
            fps: 30.0
        }
    );
    assert_eq!(a.spans[5].end, Time::End);
    assert_eq!(
        a.spans[2].grasp,
        Some(Time::Frame {
            frame: 95,
            fps: 30.0
        })
    );
    // Frames and seconds mix on one timeline: 3.2 s comes after frame 95 (3.1667 s).
    let mixed = "frame,time,instruction\n0,,walk\n,3.2,turn around\n95,,make a knocking gesture\n";
    let a = only(
        read_event_log(mixed, EventLogFormat::Csv, "x.csv", 30.0).unwrap(),
        "x",
    );
    let texts: Vec<&str> = a.spans.iter().map(|s| s.raw_text.as_str()).collect();
    assert_eq!(
        texts,
        vec!["walk", "make a knocking gesture", "turn around"]
    );
    assert_eq!(a.spans[1].end, Time::Seconds(3.2));
    // A row with both frame and time is kept as the frame when they agree.
    let both = "frame,time,instruction\n63,2.106,walk\n";
    let a = only(
        read_event_log(both, EventLogFormat::Csv, "x.csv", 30.0).unwrap(),
        "x",
    );
    assert_eq!(
        a.spans[0].start,
        Time::Frame {
            frame: 63,
            fps: 30.0
        }
    );
}

#[test]
fn several_captures_in_one_log() {
    let json = r#"{"capture": "7536", "events": [
        {"time": 0, "instruction": "walk", "motion_type": "walk"},
        {"time": 1, "instruction": "hopping left", "motion_type": "hop", "capture": "7692"},
        {"time": 2.106, "instruction": "transition", "motion_type": null}
    ]}"#;
    let map = read_event_log(json, EventLogFormat::Json, "x.json", 30.0).unwrap();
    assert_eq!(map.keys().collect::<Vec<_>>(), vec!["7536", "7692"]);
    assert_eq!(map["7536"].spans.len(), 2);
    assert_eq!(map["7536"].spans[0].end, Time::Seconds(2.106));
    assert_eq!(map["7692"].spans[0].end, Time::End);
    assert_eq!(map["7692"].spans[0].id, "row 2");
    assert_eq!(map["7536"].origin, "x.json#7536");
}

#[test]
fn event_log_errors_name_the_line() {
    let err = |text: &str, format| read_event_log(text, format, "log.csv", 30.0).unwrap_err();
    // Missing instruction column.
    let e = err("time,motion_type\n0,walk\n", EventLogFormat::Csv);
    assert_eq!(e.line, Some(1));
    assert!(
        matches!(e.fault, AnnotationFault::NoInstructionColumn { .. }),
        "{e}"
    );
    // Text in the time column.
    let e = err(
        "time,instruction\n0,walk\n2.106,transition\nabout three,make a knocking gesture\n",
        EventLogFormat::Csv,
    );
    assert_eq!(e.line, Some(4));
    assert!(
        e.to_string()
            .starts_with("log.csv:4: row 3: time `about three`"),
        "{e}"
    );
    // Both frame and time missing: in the header, and in a row.
    let e = err("instruction,motion_type\nwalk,walk\n", EventLogFormat::Csv);
    assert!(
        matches!(e.fault, AnnotationFault::NoTimeColumn { .. }),
        "{e}"
    );
    let e = err(
        "frame,time,instruction\n0,,walk\n\n,,transition\n",
        EventLogFormat::Csv,
    );
    assert_eq!(e.line, Some(4));
    assert!(
        matches!(
            e.fault,
            AnnotationFault::Row {
                row: 2,
                fault: RowFault::NoTime
            }
        ),
        "{e}"
    );
    // Others.
    for (text, line, what) in [
        ("time,instruction\n0,walk,extra\n", 2, "expected 2 columns"),
        ("time,instruction,hand\n0,walk,up\n", 2, "hand `up`"),
        ("time,instruction,event\n0,walk,wave\n", 2, "event `wave`"),
        ("time,instruction\n0,\n", 2, "no instruction text"),
        ("time,instruction\n-1,walk\n", 2, "non-negative"),
        ("time,instruction\nNaN,walk\n", 2, "finite"),
        ("frame,instruction\n2.5,walk\n", 2, "whole frame number"),
        ("frame,instruction\n-2,walk\n", 2, "negative"),
        ("frame,time,instruction\n63,5.0,walk\n", 2, "disagree"),
        ("time,instruction\n0,\"walk\n", 2, "not closed"),
        ("time,time,instruction\n", 1, "twice"),
    ] {
        let e = err(text, EventLogFormat::Csv);
        assert_eq!(e.line, Some(line), "{text}: {e}");
        assert!(e.fault.to_string().contains(what), "{text}: {e}");
    }
    let e =
        read_event_log("frame,instruction\n0,walk\n", EventLogFormat::Csv, "x", 0.0).unwrap_err();
    assert!(
        matches!(
            e.fault,
            AnnotationFault::Row {
                fault: RowFault::NoFrameRate { .. },
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(
        err("", EventLogFormat::Csv).fault,
        AnnotationFault::EmptyEventLog
    );
    // JSON errors point at the event's line.
    let json = "[\n  {\"time\": 0, \"instruction\": \"walk\"},\n  {\"time\": 2.106,\n   \
                \"instruction\": \"transition\"},\n  {\"time\": \"soon\", \"instruction\": \"x\"}\n]";
    let e = err(json, EventLogFormat::Json);
    assert_eq!(e.line, Some(5), "{e}");
    assert!(
        matches!(
            e.fault,
            AnnotationFault::Row {
                row: 3,
                fault: RowFault::TimeNotNumber { ref raw }
            } if raw == "soon"
        ),
        "{e}"
    );
    let json = "{\"capture\": \"a\",\n \"events\": [\n {\"time\": 0, \"instruction\": \"walk\"},\n \
                {\"instruction\": \"turn\"}]}";
    let e = err(json, EventLogFormat::Json);
    assert_eq!(e.line, Some(4), "{e}");
    assert!(
        matches!(
            e.fault,
            AnnotationFault::Row {
                fault: RowFault::NoTime,
                ..
            }
        ),
        "{e}"
    );
    let e = err(
        "[{\"time\": 0, \"instruction\": \"walk\"}, 5]",
        EventLogFormat::Json,
    );
    assert!(
        matches!(e.fault, AnnotationFault::EventNotObject { event: 2, .. }),
        "{e}"
    );
    let e = err(
        "[{\"time\": true, \"instruction\": \"walk\"}]",
        EventLogFormat::Json,
    );
    assert!(
        matches!(e.fault, AnnotationFault::CellNotText { .. }),
        "{e}"
    );
    let e = err("{\"events\": 3}", EventLogFormat::Json);
    assert_eq!(e.fault, AnnotationFault::NotEvents, "{e}");
    let e = err("[{\"time\": 0,", EventLogFormat::Json);
    assert!(matches!(e.fault, AnnotationFault::Json(_)), "{e}");
    // Unknown columns are ignored with a note.
    let a = only(
        read_event_log(
            "time,instruction,speed\n0,walk,fast\n",
            EventLogFormat::Csv,
            "a.csv",
            30.0,
        )
        .unwrap(),
        "a",
    );
    assert_eq!(a.notes[0].kind, "unknown_column");
    assert_eq!(a.spans.len(), 1);
}

#[test]
fn readers_do_not_panic_on_garbage() {
    let inputs = [
        "\"",
        "\"\"\"",
        ",,,",
        "\r\n\r\n",
        "\u{feff}",
        "{",
        "[",
        "]",
        "[[]]",
        "[{}]",
        "{\"events\":[]}",
        "time,instruction\n\"",
        "frame,instruction\n99999999999999999999,x\n",
        "frame,instruction\n9223372036854775807,x\n",
        "source_path,start_frame,end_frame,new_name\n\"",
        "source_path,start_frame,end_frame,new_name\na,9223372036854775807,-1,b\n",
        "[{\"time\": 1e400, \"instruction\": \"x\"}]",
        "{\"events\": [{\"time\": 0, \"instruction\": \"é\"}], \"events\": []}",
    ];
    for text in inputs {
        let _ = read_frame_index(text, "f");
        let _ = read_event_log(text, EventLogFormat::Csv, "f", 30.0);
        let _ = read_event_log(text, EventLogFormat::Json, "f", 30.0);
        let _ = read_caption(text);
        if let Ok((rows, _)) = read_frame_index(text, "f") {
            let _ = index_annotations(&rows, 20.0, "f", |p| p.to_string(), |_| None, "");
        }
    }
    // Every span's end is not before its start in a well-formed log.
    let labels = babel_7536();
    let a = only(
        read_event_log(
            &csv_log(&rows_7536(&labels)),
            EventLogFormat::Csv,
            "7536.csv",
            30.0,
        )
        .unwrap(),
        "7536",
    );
    let ordered = |s: &Span| s.end == Time::End || secs(s.end) > secs(s.start);
    assert!(a.spans.iter().all(ordered));
}

/// The fenced blocks of a schema document after its `## Example` heading.
fn example_blocks(doc: &str) -> Vec<String> {
    let path = common::repo().join("schemas").join(doc);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let example = text.split("## Example").nth(1).expect("an Example section");
    example
        .split("```")
        .skip(1)
        .step_by(2)
        .map(|b| {
            b.split_once('\n')
                .map(|(_, body)| body.to_string())
                .unwrap()
        })
        .collect()
}

#[test]
fn schema_examples_read_as_documented() {
    let blocks = example_blocks("event-log.md");
    let csv = read_event_log(&blocks[0], EventLogFormat::Csv, "7536.csv", 30.0).unwrap();
    let json = read_event_log(&blocks[1], EventLogFormat::Json, "log.json", 30.0).unwrap();
    let strip = |m: BTreeMap<String, CaptureAnnotation>| -> Vec<Span> { only(m, "7536").spans };
    let (csv, json) = (strip(csv), strip(json));
    assert_eq!(csv, json);
    let ends: Vec<Time> = csv.iter().map(|s| s.end).collect();
    assert_eq!(
        ends,
        [2.106, 2.845, 3.466, 4.519, 5.424]
            .map(Time::Seconds)
            .into_iter()
            .chain([Time::End])
            .collect::<Vec<_>>()
    );
    assert_eq!(csv[2].label, "knock");
    assert_eq!(csv[2].grasp, Some(Time::Seconds(3.1)));
    assert_eq!(csv[2].object.as_deref(), Some("door, front"));
    let ids: Vec<&str> = csv.iter().map(|s| s.id.as_str()).collect();
    assert_eq!(ids, ["row 1", "row 2", "row 3", "row 5", "row 6", "row 7"]);

    let blocks = example_blocks("frame-index.md");
    let (rows, notes) = read_frame_index(&blocks[0], "index.csv").unwrap();
    assert_eq!(rows.len(), 4);
    assert_eq!(notes.len(), 1);
    assert!(
        notes[0]
            .message
            .starts_with("index.csv:6: expected 4 columns")
    );
    let caps = index_annotations(&rows, 20.0, "index.csv", capture_key, |_| None, "");
    let keys: Vec<&str> = caps.keys().map(String::as_str).collect();
    assert_eq!(keys, ["01_01", "01_01, take 2", "P11G01R02F1812T1847A0402"]);
    assert_eq!(caps["01_01"].spans[0].id, "004041.npy");
    assert_eq!(caps["P11G01R02F1812T1847A0402"].spans[0].end, Time::End);
}
