//! Damaged BVH input never panics and gets a clear error with the right line: specific damage to a
//! real Bandai Namco capture (each error kind and line asserted), then random damage and arbitrary
//! strings (proptest).
use crate::common;

use std::sync::OnceLock;

use common::*;
use motionforge::motion::bvh::MAX_JOINTS;
use motionforge::motion::*;
use proptest::prelude::*;

/// Frames kept from the real capture, so every case stays fast.
const FRAMES: usize = 20;

/// `dataset-1_walk_normal_001.bvh`: its hierarchy and first 20 frames, `Frames:` set to 20, LF.
fn walk20() -> &'static str {
    static TEXT: OnceLock<String> = OnceLock::new();
    TEXT.get_or_init(|| {
        let path = bandai1("walk", "normal");
        let full =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut out = String::new();
        let mut frames = None;
        for line in full.lines() {
            match frames {
                None if line.starts_with("Frames:") => {
                    out.push_str(&format!("Frames:\t{FRAMES}\n"))
                }
                None => {
                    out.push_str(line);
                    out.push('\n');
                    if line.starts_with("Frame Time:") {
                        frames = Some(0);
                    }
                }
                Some(n) if n < FRAMES => {
                    out.push_str(line);
                    out.push('\n');
                    frames = Some(n + 1);
                }
                Some(_) => break,
            }
        }
        out
    })
}

// Line numbers in walk20 (1-based), checked by `walk20_is_what_the_cases_assume`.
const ROOT_LINE: usize = 2;
const FIRST_CHANNELS_LINE: usize = 5;
const LAST_BRACE_LINE: usize = 131;
const MOTION_LINE: usize = 132;
const FRAMES_LINE: usize = 133;
const FRAME_TIME_LINE: usize = 134;
const FIRST_FRAME_LINE: usize = 135;
const CHANNELS: usize = 22 * 6;

fn lines() -> Vec<&'static str> {
    walk20().lines().collect()
}

fn join(lines: &[&str]) -> String {
    let mut s = lines.join("\n");
    s.push('\n');
    s
}

/// walk20 with line `n` (1-based) replaced.
fn with_line(n: usize, new: &str) -> String {
    let mut l = lines();
    l[n - 1] = new;
    join(&l)
}

fn err(text: &str) -> BvhError {
    match read_bvh(text) {
        Ok(bvh) => panic!(
            "expected an error, read {} frames of {} joints",
            bvh.motion.num_frames(),
            bvh.skeleton.len()
        ),
        Err(e) => e,
    }
}

#[test]
fn walk20_is_what_the_cases_assume() {
    let l = lines();
    assert_eq!(l.len(), FIRST_FRAME_LINE - 1 + FRAMES);
    assert_eq!(l[ROOT_LINE - 1], "ROOT joint_Root");
    assert!(
        l[FIRST_CHANNELS_LINE - 1]
            .trim_start()
            .starts_with("CHANNELS 6 Xposition")
    );
    assert_eq!(l[LAST_BRACE_LINE - 1], "}");
    assert_eq!(l[MOTION_LINE - 1], "MOTION");
    assert_eq!(l[FRAMES_LINE - 1], "Frames:\t20");
    assert_eq!(l[FRAME_TIME_LINE - 1], "Frame Time:\t0.0333333");
    let bvh = read_bvh(walk20()).unwrap();
    assert_eq!(bvh.motion.num_frames(), FRAMES);
    assert_eq!(bvh.skeleton.channel_count(), CHANNELS);
}

#[test]
fn truncated_file_is_truncated_at_its_last_line() {
    // Whole frame lines missing: 15 of 20.
    let l = lines();
    let text = join(&l[..FIRST_FRAME_LINE - 1 + 15]);
    let e = err(&text);
    assert_eq!(
        e.kind,
        BvhErrorKind::Truncated {
            declared: 20,
            found: 15
        }
    );
    assert_eq!(e.line, FIRST_FRAME_LINE + 14);
    assert_eq!(e.line, text.lines().count());
    assert_eq!(e.frame, Some(15));
    assert!(
        e.to_string().starts_with("line 149 (frame 15): truncated"),
        "{e}"
    );

    // Cut in the middle of frame 15's line: that line has too few values.
    let start: usize = l[..FIRST_FRAME_LINE - 1 + 15]
        .iter()
        .map(|s| s.len() + 1)
        .sum();
    let cut = start + l[FIRST_FRAME_LINE - 1 + 15].len() / 2;
    let e = err(&walk20()[..cut]);
    assert!(
        matches!(e.kind, BvhErrorKind::ValueCount { expected: CHANNELS, found } if found < CHANNELS),
        "{e}"
    );
    assert_eq!((e.line, e.frame), (FIRST_FRAME_LINE + 15, Some(15)));

    // No motion line at all, with and without the final newline: the Frame Time line.
    let text = join(&l[..FRAME_TIME_LINE]);
    for t in [text.as_str(), text.trim_end()] {
        let e = err(t);
        assert_eq!(
            e.kind,
            BvhErrorKind::Truncated {
                declared: 20,
                found: 0
            }
        );
        assert_eq!((e.line, e.frame), (FRAME_TIME_LINE, Some(0)));
    }
}

#[test]
fn every_line_prefix_fails_on_a_line_it_has() {
    for crlf in [false, true] {
        let base = if crlf {
            walk20().replace('\n', "\r\n")
        } else {
            walk20().to_string()
        };
        let lines: Vec<&str> = base.split_inclusive('\n').collect();
        for keep in 0..lines.len() {
            let with_newline = lines[..keep].concat();
            let without = with_newline.trim_end_matches(['\r', '\n']);
            for text in [with_newline.as_str(), without] {
                let e = err(text);
                assert!(
                    (1..=keep.max(1)).contains(&e.line),
                    "first {keep} lines: {e}"
                );
                if keep >= FRAME_TIME_LINE {
                    let found = keep - FRAME_TIME_LINE;
                    assert_eq!(
                        e.kind,
                        BvhErrorKind::Truncated {
                            declared: FRAMES,
                            found
                        }
                    );
                    assert_eq!((e.line, e.frame), (keep, Some(found)));
                }
            }
        }
    }
}

#[test]
fn every_byte_prefix_up_to_the_second_frame_fails_on_a_line_it_has() {
    let text = walk20();
    let end: usize = lines()[..FIRST_FRAME_LINE + 1]
        .iter()
        .map(|l| l.len() + 1)
        .sum();
    for cut in 0..end {
        let prefix = &text[..cut];
        let e = err(prefix);
        assert!(
            (1..=prefix.lines().count().max(1)).contains(&e.line),
            "{cut} bytes: {e}"
        );
    }
}

#[test]
fn wrong_value_count_names_line_and_frame() {
    // One value short on frame 7.
    let n = FIRST_FRAME_LINE + 7;
    let line = lines()[n - 1];
    let short = line.trim_end().rsplit_once(' ').unwrap().0;
    let e = err(&with_line(n, short));
    assert_eq!(
        e.kind,
        BvhErrorKind::ValueCount {
            expected: CHANNELS,
            found: CHANNELS - 1
        }
    );
    assert_eq!((e.line, e.frame), (n, Some(7)));

    // One value too many on frame 0.
    let long = format!("{line} 1.0");
    let e = err(&with_line(FIRST_FRAME_LINE, &long));
    assert_eq!(
        e.kind,
        BvhErrorKind::ValueCount {
            expected: CHANNELS,
            found: CHANNELS + 1
        }
    );
    assert_eq!((e.line, e.frame), (FIRST_FRAME_LINE, Some(0)));
}

#[test]
fn text_where_numbers_belong_is_a_bad_number() {
    // A motion value.
    let n = FIRST_FRAME_LINE + 3;
    let mut values: Vec<&str> = lines()[n - 1].split_ascii_whitespace().collect();
    for word in ["abc", "nan", "inf", "-inf", "1.2.3", "1e", "0x10", "1,5"] {
        values[10] = word;
        let e = err(&with_line(n, &values.join(" ")));
        assert_eq!(
            e.kind,
            BvhErrorKind::BadNumber {
                what: "a channel value",
                found: word.to_string()
            },
            "{word}"
        );
        assert_eq!((e.line, e.frame), (n, Some(3)), "{word}");
    }
    // An OFFSET coordinate (line 4 is the root's OFFSET).
    let e = err(&with_line(4, "  OFFSET 0 zero 0"));
    assert_eq!(
        e.kind,
        BvhErrorKind::BadNumber {
            what: "OFFSET y",
            found: "zero".into()
        }
    );
    assert_eq!((e.line, e.frame), (4, None));
    // The frame count and the frame time.
    let e = err(&with_line(FRAMES_LINE, "Frames: twenty"));
    assert!(
        matches!(
            e.kind,
            BvhErrorKind::BadNumber {
                what: "the frame count",
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.line, FRAMES_LINE);
    for bad in ["Frames: -3", "Frames: 2.5"] {
        let e = err(&with_line(FRAMES_LINE, bad));
        assert!(
            matches!(
                e.kind,
                BvhErrorKind::BadNumber {
                    what: "the frame count",
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(e.line, FRAMES_LINE);
    }
    let e = err(&with_line(FRAME_TIME_LINE, "Frame Time: fast"));
    assert!(
        matches!(
            e.kind,
            BvhErrorKind::BadNumber {
                what: "the frame time",
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.line, FRAME_TIME_LINE);
}

#[test]
fn missing_motion_section() {
    let l = lines();
    // The file ends after the hierarchy.
    let e = err(&join(&l[..LAST_BRACE_LINE]));
    assert_eq!(e.kind, BvhErrorKind::UnexpectedEnd { expected: "MOTION" });
    assert_eq!(e.line, LAST_BRACE_LINE);
    // The MOTION keyword alone is missing.
    let mut without = l.clone();
    without.remove(MOTION_LINE - 1);
    let e = err(&join(&without));
    assert_eq!(
        e.kind,
        BvhErrorKind::Unexpected {
            expected: "MOTION",
            found: "Frames:".into()
        }
    );
    assert_eq!(e.line, MOTION_LINE);
    // A second ROOT hierarchy where MOTION belongs.
    let mut two = l[..LAST_BRACE_LINE].to_vec();
    two.extend_from_slice(&l[1..]);
    let e = err(&join(&two));
    assert!(
        matches!(&e.kind, BvhErrorKind::Unexpected { expected, found }
            if expected.starts_with("MOTION (files with several ROOT") && found == "ROOT"),
        "{e}"
    );
    assert_eq!(e.line, LAST_BRACE_LINE + 1);
}

#[test]
fn root_without_name() {
    let e = err(&with_line(ROOT_LINE, "ROOT"));
    assert_eq!(
        e.kind,
        BvhErrorKind::Unexpected {
            expected: "a joint name",
            found: "{".into()
        }
    );
    // The `{` found where the name belongs, on the next line.
    assert_eq!(e.line, ROOT_LINE + 1);
    let e = err("HIERARCHY\nROOT\n{\n  OFFSET 0 0 0\n");
    assert_eq!(e.line, 3);
    assert!(matches!(
        e.kind,
        BvhErrorKind::Unexpected {
            expected: "a joint name",
            ..
        }
    ));
    // A JOINT without name: `}` where the name belongs.
    let e = err("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\nJOINT\n}\n");
    assert_eq!(e.line, 7);
    assert!(matches!(
        e.kind,
        BvhErrorKind::Unexpected {
            expected: "a joint name",
            ..
        }
    ));
}

#[test]
fn unknown_channel_name() {
    let line = lines()[FIRST_CHANNELS_LINE - 1].replacen("Zrotation", "Wrotation", 1);
    let e = err(&with_line(FIRST_CHANNELS_LINE, &line));
    assert_eq!(e.kind, BvhErrorKind::UnknownChannel("Wrotation".into()));
    assert_eq!((e.line, e.frame), (FIRST_CHANNELS_LINE, None));
    // Fewer channel names than the count: the next keyword is read as a channel name.
    let e = err(&with_line(
        FIRST_CHANNELS_LINE,
        "CHANNELS 6 Xposition Yposition",
    ));
    assert_eq!(e.kind, BvhErrorKind::UnknownChannel("JOINT".into()));
    assert_eq!(e.line, FIRST_CHANNELS_LINE + 1);
}

#[test]
fn channel_count_out_of_range() {
    for (count, found) in [
        ("7", "7"),
        ("-1", "-1"),
        ("2.5", "2.5"),
        ("1e9", "1000000000"),
    ] {
        let line = lines()[FIRST_CHANNELS_LINE - 1].replacen("6", count, 1);
        let e = err(&with_line(FIRST_CHANNELS_LINE, &line));
        assert_eq!(
            e.kind,
            BvhErrorKind::BadNumber {
                what: "the channel count (0 to 6)",
                found: found.into()
            },
            "{count}"
        );
        assert_eq!(e.line, FIRST_CHANNELS_LINE);
    }
}

#[test]
fn zero_negative_or_absurd_frame_time() {
    for (time, value) in [
        ("-0.0333333", -0.0333333),
        ("0", 0.0),
        ("-0", -0.0),
        ("0.0e0", 0.0),
        // Positive but subnormal: 1 / t is infinite.
        ("1e-320", 1e-320),
        // Outside the plausible capture rates (1 to 10,000 fps): a damaged header, which would
        // otherwise size resampling by the duration it implies (1000 s per frame: 7 GB).
        ("1000", 1000.0),
        ("1000000", 1e6),
        ("1e20", 1e20),
        ("1.5", 1.5),
        ("0.00001", 1e-5),
    ] {
        let e = err(&with_line(FRAME_TIME_LINE, &format!("Frame Time:\t{time}")));
        assert_eq!(e.kind, BvhErrorKind::FrameTime(value), "{time}");
        assert_eq!(e.line, FRAME_TIME_LINE, "{time}");
        assert!(e.to_string().contains("1 to 10000 fps"), "{e}");
    }
    // The ends of the range are accepted; a slow rate is kept, not snapped.
    let bvh = read_bvh(&with_line(FRAME_TIME_LINE, "Frame Time: 1")).unwrap();
    assert_eq!(bvh.header_fps, 1.0);
    let bvh = read_bvh(&with_line(FRAME_TIME_LINE, "Frame Time: 0.0001")).unwrap();
    assert_eq!(bvh.header_fps, 10_000.0);
    let bvh = read_bvh(&with_line(FRAME_TIME_LINE, "Frame Time: 0.7")).unwrap();
    assert!((bvh.header_fps - 1.0 / 0.7).abs() < 1e-12);
    // Anything after the frame time on its line.
    let e = err(&with_line(FRAME_TIME_LINE, "Frame Time: 0.0333333 0.5"));
    assert_eq!(
        e.kind,
        BvhErrorKind::Unexpected {
            expected: "end of line after Frame Time",
            found: "0.5".into()
        }
    );
    assert_eq!(e.line, FRAME_TIME_LINE);
}

#[test]
fn extra_frames() {
    // One more frame line than declared.
    let mut l = lines();
    let last = *l.last().unwrap();
    l.push(last);
    let e = err(&join(&l));
    assert_eq!(
        e.kind,
        BvhErrorKind::ExtraFrames {
            declared: 20,
            header_line: FRAMES_LINE,
            found: 21
        }
    );
    assert_eq!((e.line, e.frame), (FIRST_FRAME_LINE + 20, Some(20)));
    // Header says 19, or far fewer: the reject gives both numbers.
    let e = err(&with_line(FRAMES_LINE, "Frames: 19"));
    assert_eq!(
        e.kind,
        BvhErrorKind::ExtraFrames {
            declared: 19,
            header_line: FRAMES_LINE,
            found: 20
        }
    );
    assert_eq!((e.line, e.frame), (FIRST_FRAME_LINE + 19, Some(19)));
    let e = err(&with_line(FRAMES_LINE, "Frames: 2"));
    assert_eq!(
        e.to_string(),
        format!(
            "line {} (frame 2): header declares 2 frames (line {FRAMES_LINE}), file has 20",
            FIRST_FRAME_LINE + 2
        )
    );
    // Blank lines after the last frame are not frames.
    let text = format!("{}\n\n  \t\n", walk20());
    assert_eq!(read_bvh(&text).unwrap().motion.num_frames(), FRAMES);
}

#[test]
fn empty_or_blank_file() {
    for text in ["", "\n", "  \n\t\n\n", "\u{feff}", "\r\n\r\n"] {
        let e = err(text);
        assert_eq!(
            e.kind,
            BvhErrorKind::UnexpectedEnd {
                expected: "HIERARCHY"
            },
            "{text:?}"
        );
        assert_eq!((e.line, e.frame), (1, None), "{text:?}");
    }
    let e = err("MOTION\nFrames: 0\n");
    assert_eq!(
        e.kind,
        BvhErrorKind::Unexpected {
            expected: "HIERARCHY",
            found: "MOTION".into()
        }
    );
    let e = err("HIERARCHY\n");
    assert_eq!(e.kind, BvhErrorKind::UnexpectedEnd { expected: "ROOT" });
    assert_eq!(e.line, 1);
}

#[test]
fn crlf_errors_report_the_same_lines() {
    let n = FIRST_FRAME_LINE + 5;
    let mut values: Vec<&str> = lines()[n - 1].split_ascii_whitespace().collect();
    values[3] = "oops";
    let lf = with_line(n, &values.join(" "));
    let crlf = lf.replace('\n', "\r\n");
    assert_eq!(err(&lf), err(&crlf));
    assert_eq!(err(&crlf).line, n);
    let short = join(&lines()[..FIRST_FRAME_LINE + 3]).replace('\n', "\r\n");
    let e = err(&short);
    assert_eq!((e.line, e.frame), (FIRST_FRAME_LINE + 3, Some(4)));
    let e = err(&format!("\u{feff}{short}"));
    assert_eq!((e.line, e.frame), (FIRST_FRAME_LINE + 3, Some(4)));
}

#[test]
fn deeply_nested_hierarchy_does_not_overflow_the_stack() {
    // Was a recursive descent: about 1,000 nested joints overflowed a test thread's 2 MB stack
    // (an abort, not a panic). 999 joints under the root: the most a hierarchy may have.
    for depth in [MAX_JOINTS - 1] {
        let mut s = String::from("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\n");
        for _ in 0..depth {
            s.push_str("JOINT b\n{\nOFFSET 0 0 0\nCHANNELS 0\n");
        }
        let e = err(&s);
        assert_eq!(
            e.kind,
            BvhErrorKind::UnexpectedEnd {
                expected: "JOINT, End Site or }"
            }
        );
        assert_eq!(e.line, s.lines().count());
        // Closed properly, it reads.
        s.push_str(&"}\n".repeat(depth + 1));
        s.push_str("MOTION\nFrames: 0\nFrame Time: 0.04\n");
        let bvh = read_bvh(&s).unwrap();
        assert_eq!(bvh.skeleton.len(), depth + 1);
        assert_eq!(bvh.skeleton.joints[depth].parent, Some(depth - 1));
    }
    // Deeper than that is refused at the first joint too many, not read into memory.
    let mut s = String::from("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\n");
    for _ in 0..100_000 {
        s.push_str("JOINT b\n{\nOFFSET 0 0 0\nCHANNELS 0\n");
    }
    let e = err(&s);
    assert_eq!(e.kind, BvhErrorKind::TooManyJoints);
    assert_eq!(e.line, 5 + 4 * (MAX_JOINTS - 1) + 1);
}

#[test]
fn huge_frame_count_is_truncated_not_an_allocation_failure() {
    // Was `Vec::with_capacity(declared * joints)`: 1e12 frames aborted on allocation, 1e18
    // overflowed the multiplication.
    for count in ["1000000000000", "1e18", "1e300"] {
        let e = err(&with_line(FRAMES_LINE, &format!("Frames: {count}")));
        assert!(
            matches!(e.kind, BvhErrorKind::Truncated { found: 20, .. }),
            "{count}: {e}"
        );
        assert_eq!(e.line, walk20().lines().count());
    }
}

#[test]
fn cr_only_line_endings_read_like_lf() {
    // Classic Mac exports end lines with a lone CR. Read whole, not as one line (which once put
    // the whole motion body into a reject message).
    let lf = read_bvh(walk20()).unwrap();
    let cr = read_bvh(&walk20().replace('\n', "\r")).unwrap();
    assert_eq!(cr.motion.rotations, lf.motion.rotations);
    assert_eq!(cr.motion.translations, lf.motion.translations);
    assert_eq!(cr.channels, lf.channels);
    // And damage in a CR-only file is reported on its own line, quoting only a short excerpt.
    let n = FIRST_FRAME_LINE + 5;
    let mut values: Vec<&str> = lines()[n - 1].split_ascii_whitespace().collect();
    values[3] = "oops";
    let damaged = with_line(n, &values.join(" ")).replace('\n', "\r");
    let e = err(&damaged);
    assert_eq!((e.line, e.frame), (n, Some(5)));
}

#[test]
fn errors_quote_a_short_excerpt_of_the_offending_text() {
    // A 100 kB token where a number belongs, and a whole frame line after `Frame Time`.
    let long = "x".repeat(100_000);
    let e = err(&with_line(FIRST_FRAME_LINE + 1, &long));
    assert!(e.to_string().len() < 200, "{} bytes", e.to_string().len());
    assert!(e.to_string().contains('…'));
    let frame_line = lines()[FIRST_FRAME_LINE - 1];
    let glued = with_line(
        FRAME_TIME_LINE,
        &format!("Frame Time: 0.0333333 {}", frame_line.repeat(50)),
    );
    let e = err(&glued);
    assert_eq!(e.line, FRAME_TIME_LINE);
    assert!(e.to_string().len() < 200, "{}", e);
}

#[test]
fn a_value_beyond_any_real_capture_is_rejected_with_its_joint_and_channel() {
    // A root position of 1e300 is finite, but positions, velocities and statistics computed from
    // it overflow to infinity: rejected at read, with line, frame, joint and channel.
    let n = FIRST_FRAME_LINE + 7;
    let mut values: Vec<String> = lines()[n - 1]
        .split_ascii_whitespace()
        .map(String::from)
        .collect();
    values[0] = "1e300".into();
    let e = err(&with_line(n, &values.join(" ")));
    assert_eq!((e.line, e.frame), (n, Some(7)));
    let root = read_bvh(walk20()).unwrap().skeleton.joints[0].name.clone();
    assert_eq!(
        e.kind,
        BvhErrorKind::OutOfRange {
            what: format!("joint `{root}` channel Xposition"),
            value: 1e300
        }
    );
    // Offsets too.
    let e = err(&with_line(FIRST_CHANNELS_LINE - 1, "\tOFFSET 0 -1e9 0"));
    assert!(matches!(e.kind, BvhErrorKind::OutOfRange { .. }), "{e}");
    // The bound itself is accepted.
    values[0] = format!("{}", motionforge::motion::bvh::MAX_MAGNITUDE);
    assert!(read_bvh(&with_line(n, &values.join(" "))).is_ok());
}

/// A hierarchy of `joints` joints without channels under a root with one, and `frames` frame
/// lines of one value each: frame lines that cost two bytes of text but a pose of every joint.
fn zero_channel_rig(joints: usize, declared: &str, frames: usize) -> String {
    let mut text = String::from("HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 1 Xposition\n");
    for i in 0..joints {
        text.push_str(&format!("JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n}}\n"));
    }
    text.push_str(&format!(
        "}}\nMOTION\nFrames: {declared}\nFrame Time: 0.0333333\n"
    ));
    text.push_str(&"0\n".repeat(frames));
    text
}

#[test]
fn claimed_and_real_sizes_are_bounded_before_anything_is_allocated() {
    // Once `Frames: 1e12` with 2,000 joints reserved (body length / 2) x joints poses: 64 GB.
    let e = err(&zero_channel_rig(2_000, "1000000000000", 10));
    assert_eq!(e.kind, BvhErrorKind::TooManyJoints);
    let text = zero_channel_rig(900, "1000000000000", 20_000);
    let (result, peak) = peak_allocation(|| read_bvh(&text));
    let e = result.unwrap_err();
    assert!(matches!(e.kind, BvhErrorKind::TooLarge { .. }), "{e}");
    assert!(
        peak < 1_000_000_000,
        "peak {peak} bytes for {} bytes",
        text.len()
    );
    // A capture inside the bound, with more frames than declared: both numbers in the reject.
    let e = err(&zero_channel_rig(10, "3", 8));
    assert!(
        matches!(
            e.kind,
            BvhErrorKind::ExtraFrames {
                declared: 3,
                found: 8,
                ..
            }
        ),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------------
// Allocation accounting: the bytes this thread holds, and their peak.
// ---------------------------------------------------------------------------------------------

struct Counting;

thread_local! {
    static HELD: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    static PEAK: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn note_alloc(size: usize) {
    let _ = HELD.try_with(|h| {
        let now = h.get().saturating_add(size);
        h.set(now);
        let _ = PEAK.try_with(|p| p.set(p.get().max(now)));
    });
}

fn note_free(size: usize) {
    let _ = HELD.try_with(|h| h.set(h.get().saturating_sub(size)));
}

// SAFETY: forwards every call to the system allocator unchanged; only counts sizes.
unsafe impl std::alloc::GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        let p = unsafe { std::alloc::System.alloc(layout) };
        if !p.is_null() {
            note_alloc(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) };
        note_free(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { std::alloc::System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            note_free(layout.size());
            note_alloc(new_size);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// What `f` returns, and the most bytes this thread held beyond what it held before, while `f` ran.
fn peak_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = HELD.with(|h| h.get());
    PEAK.with(|p| p.set(before));
    let out = f();
    let peak = PEAK.with(|p| p.get());
    (out, peak - before)
}

// ---------------------------------------------------------------------------------------------
// Random damage.
// ---------------------------------------------------------------------------------------------

/// Extreme header numbers: absurd frame counts, frame times and channel counts.
const EXTREMES: &[&str] = &[
    "1000000000000",
    "18446744073709551615",
    "1e18",
    "1e300",
    "1000000",
    "1000",
    "0.001",
    "0.0000001",
    "1e-300",
    "-1",
    "7",
    "2147483648",
];

/// Tokens worth inserting: BVH keywords, braces, odd numbers and characters.
const TOKENS: &[&str] = &[
    "{",
    "}",
    "ROOT",
    "ROOT x",
    "JOINT",
    "JOINT j",
    "End",
    "End Site",
    "Site",
    "OFFSET",
    "OFFSET 1 2 3",
    "CHANNELS",
    "CHANNELS 7",
    "CHANNELS 3 Zrotation Xrotation Yrotation",
    "Xrotation",
    "HIERARCHY",
    "MOTION",
    "Frames:",
    "Frames: 99999999999",
    "Frame Time:",
    "Frame Time: 0",
    "nan",
    "inf",
    "-1e400",
    "1e-320",
    "-0",
    "1.5e-05",
    "2E+01",
    "\u{feff}",
    "é",
    "日本",
    "\r",
    "\n",
    "\r\n",
    "\t",
    "\0",
    " ",
];

#[derive(Debug, Clone)]
enum Damage {
    /// Cut the text at this byte (modulo length, moved back to a char boundary).
    Truncate(usize),
    /// Keep the first n lines (modulo the line count), with or without the last line's newline.
    TruncateLines(usize, bool),
    /// Replace the value after `Frames:` (false) or `Frame Time:` (true) with this text.
    SetHeader(bool, String),
    /// Delete this many bytes from this position.
    DeleteRange(usize, usize),
    /// Insert text at this position.
    Insert(usize, String),
    /// Replace the n-th numeric token with this text.
    ReplaceNumber(usize, String),
    /// Duplicate the n-th line.
    DuplicateLine(usize),
    /// Delete the n-th line.
    DeleteLine(usize),
    /// Flip the n-th brace (`{` <-> `}`).
    SwapBrace(usize),
    /// Set the n-th `CHANNELS` count to this text (the names after it stay).
    SetChannels(usize, String),
    /// Turn every line end into this one (LF, CRLF or a lone CR).
    LineEnds(&'static str),
}

fn boundary(text: &str, pos: usize) -> usize {
    let mut p = pos % (text.len() + 1);
    while !text.is_char_boundary(p) {
        p -= 1;
    }
    p
}

/// Byte ranges of whitespace-separated tokens that parse as numbers.
fn number_ranges(text: &str) -> Vec<(usize, usize)> {
    text.split_ascii_whitespace()
        .filter(|t| t.parse::<f64>().is_ok())
        .map(|t| {
            let start = t.as_ptr() as usize - text.as_ptr() as usize;
            (start, start + t.len())
        })
        .collect()
}

fn apply(mut text: String, damage: &Damage) -> String {
    match damage {
        Damage::Truncate(at) => {
            let at = boundary(&text, *at);
            text.truncate(at);
        }
        Damage::TruncateLines(n, newline) => {
            let lines: Vec<&str> = text.split_inclusive('\n').collect();
            let keep = n % (lines.len() + 1);
            let mut kept = lines[..keep].concat();
            if !newline && kept.ends_with('\n') {
                kept.pop();
                if kept.ends_with('\r') {
                    kept.pop();
                }
            }
            text = kept;
        }
        Damage::SetHeader(frame_time, value) => {
            let key = if *frame_time {
                "Frame Time:"
            } else {
                "Frames:"
            };
            if let Some(start) = text.find(key) {
                let from = start + key.len();
                let end = text[from..]
                    .find(['\r', '\n'])
                    .map_or(text.len(), |e| from + e);
                text.replace_range(from..end, &format!(" {value}"));
            }
        }
        Damage::DeleteRange(at, len) => {
            let start = boundary(&text, *at);
            let end = boundary(&text, start + len % 200);
            let end = if end < start { text.len() } else { end };
            text.replace_range(start..end, "");
        }
        Damage::Insert(at, what) => {
            let at = boundary(&text, *at);
            text.insert_str(at, what);
        }
        Damage::ReplaceNumber(n, what) => {
            let ranges = number_ranges(&text);
            if !ranges.is_empty() {
                let (s, e) = ranges[n % ranges.len()];
                text.replace_range(s..e, what);
            }
        }
        Damage::DuplicateLine(n) | Damage::DeleteLine(n) => {
            let mut lines: Vec<&str> = text.split_inclusive('\n').collect();
            if !lines.is_empty() {
                let i = n % lines.len();
                if matches!(damage, Damage::DuplicateLine(_)) {
                    let line = lines[i];
                    lines.insert(i, line);
                } else {
                    lines.remove(i);
                }
            }
            text = lines.concat();
        }
        Damage::SetChannels(n, value) => {
            let at: Vec<usize> = text.match_indices("CHANNELS").map(|(i, _)| i).collect();
            if !at.is_empty() {
                let from = at[n % at.len()] + "CHANNELS".len();
                let rest = &text[from..];
                let start = from + rest.len() - rest.trim_start().len();
                let end = text[start..]
                    .find(|c: char| c.is_ascii_whitespace())
                    .map_or(text.len(), |e| start + e);
                text.replace_range(start..end, value);
            }
        }
        Damage::LineEnds(end) => {
            text = text
                .replace("\r\n", "\n")
                .replace('\r', "\n")
                .replace('\n', end);
        }
        Damage::SwapBrace(n) => {
            let braces: Vec<usize> = text.match_indices(['{', '}']).map(|(i, _)| i).collect();
            if !braces.is_empty() {
                let i = braces[n % braces.len()];
                let flipped = if &text[i..=i] == "{" { "}" } else { "{" };
                text.replace_range(i..=i, flipped);
            }
        }
    }
    text
}

fn garbage() -> impl Strategy<Value = String> {
    prop_oneof![
        "[ -~\t\r\n]{1,16}",
        prop::collection::vec(any::<u8>(), 1..12)
            .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        prop::sample::select(TOKENS).prop_map(String::from),
        prop::collection::vec(prop::sample::select(TOKENS), 1..6).prop_map(|t| t.join(" ")),
    ]
}

/// Numbers a damaged header might hold.
fn header_value() -> impl Strategy<Value = String> {
    prop_oneof![
        (0u64..40).prop_map(|v| v.to_string()),
        prop::sample::select(EXTREMES).prop_map(String::from),
        any::<u64>().prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| v.to_string()),
        (-3i32..3, -330i32..330).prop_map(|(m, e)| format!("{m}e{e}")),
        garbage(),
    ]
}

fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        any::<usize>().prop_map(Damage::Truncate),
        (any::<usize>(), any::<bool>()).prop_map(|(n, nl)| Damage::TruncateLines(n, nl)),
        (any::<bool>(), header_value()).prop_map(|(ft, v)| Damage::SetHeader(ft, v)),
        (any::<usize>(), 1..200usize).prop_map(|(a, l)| Damage::DeleteRange(a, l)),
        (any::<usize>(), garbage()).prop_map(|(a, g)| Damage::Insert(a, g)),
        (any::<usize>(), garbage()).prop_map(|(n, g)| Damage::ReplaceNumber(n, g)),
        any::<usize>().prop_map(Damage::DuplicateLine),
        any::<usize>().prop_map(Damage::DeleteLine),
        any::<usize>().prop_map(Damage::SwapBrace),
        (any::<usize>(), header_value()).prop_map(|(n, v)| Damage::SetChannels(n, v)),
        prop::sample::select(&["\n", "\r\n", "\r"][..]).prop_map(Damage::LineEnds),
    ]
}

/// Lines as the reader counts them: ended by LF, CRLF or a lone CR.
fn line_count(text: &str) -> usize {
    text.replace("\r\n", "\n")
        .replace('\r', "\n")
        .lines()
        .count()
}

/// `read_bvh` returns (never panics); an error's line is a line of the text (an empty text counts
/// as one line); a success is self-consistent.
fn check(text: &str) -> Result<(), TestCaseError> {
    let (result, peak) = peak_allocation(|| read_bvh(text));
    // Memory follows the text, never a number the text claims: a frame value takes at least two
    // bytes of text and becomes at most a few tens of bytes of decoded pose (doubled by growth).
    prop_assert!(
        peak <= 64 * text.len() + (1 << 20),
        "{} bytes allocated for {} bytes of text",
        peak,
        text.len()
    );
    match result {
        Ok(bvh) => {
            let n = bvh.skeleton.len();
            prop_assert!(n > 0);
            prop_assert_eq!(bvh.motion.rotations.len(), bvh.motion.num_frames() * n);
            prop_assert_eq!(bvh.motion.translations.len(), bvh.motion.rotations.len());
            prop_assert!(bvh.header_fps.is_finite() && bvh.header_fps > 0.0);
        }
        Err(e) => {
            let lines = line_count(text).max(1);
            prop_assert!(
                (1..=lines).contains(&e.line),
                "error line {} outside 1..={}: {}",
                e.line,
                lines,
                e
            );
            let prefix = format!("line {}", e.line);
            prop_assert!(e.to_string().starts_with(&prefix), "{}", e);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn randomly_damaged_real_file_never_panics(
        crlf in any::<bool>(),
        damages in prop::collection::vec(damage(), 1..5),
    ) {
        let base = if crlf { walk20().replace('\n', "\r\n") } else { walk20().to_string() };
        let text = damages.iter().fold(base, apply);
        check(&text)?;
    }

    /// A single number replaced by a word is a BadNumber on exactly that token's line.
    #[test]
    fn a_number_replaced_by_a_word_is_reported_on_its_line(
        crlf in any::<bool>(),
        n in any::<usize>(),
        word in "[a-zA-Z_][a-zA-Z_0-9]{0,8}",
    ) {
        let base = if crlf { walk20().replace('\n', "\r\n") } else { walk20().to_string() };
        let ranges = number_ranges(&base);
        let (start, _) = ranges[n % ranges.len()];
        let line = base[..start].matches('\n').count() + 1;
        let text = apply(base, &Damage::ReplaceNumber(n, word.clone()));
        let e = read_bvh(&text).err();
        prop_assert!(
            matches!(&e, Some(BvhError { kind: BvhErrorKind::BadNumber { found, .. }, .. })
                if *found == word),
            "{:?}", e
        );
        prop_assert_eq!(e.map(|e| e.line), Some(line));
    }

    #[test]
    fn arbitrary_text_never_panics(text in "(?s).{0,400}") {
        check(&text)?;
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        check(&String::from_utf8_lossy(&bytes))?;
    }

    /// Streams of BVH tokens get much further into the grammar than random text.
    #[test]
    fn token_soup_never_panics(
        tokens in prop::collection::vec(
            prop_oneof![
                prop::sample::select(TOKENS).prop_map(String::from),
                any::<f32>().prop_map(|v| v.to_string()),
                (0u8..10).prop_map(|v| v.to_string()),
            ],
            0..120,
        ),
        sep in prop::sample::select(&[" ", "\n", "\r\n", "\t"][..]),
    ) {
        let mut text = String::from("HIERARCHY\n");
        text.push_str(&tokens.join(sep));
        check(&text)?;
        check(&tokens.join(sep))?;
    }
}
