//! The session as an event log (the CSV form `annotate::event_log` reads) with its times left
//! blank for the capture, and as a short sheet for the operator.

use std::fmt::Write as _;

use super::scene::{Hold, Scene};
use super::{Session, chain};

/// The event log's columns, as the event-log reader names them; `time` first, to be filled in.
pub const EVENT_LOG_COLUMNS: [&str; 6] = [
    "time",
    "event",
    "instruction",
    "motion_type",
    "hand",
    "object",
];

/// One CSV field: quoted when it holds a comma, a quote or edge spaces.
fn field(s: &str) -> String {
    if s.contains([',', '"']) || s.trim() != s {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The event log: a header, one `instruction` row per step and, after a step that takes or puts
/// down an object, a `grasp` or `release` row for the assistant to time. Every `time` is blank:
/// the reader refuses a row without one, so a log nobody filled in cannot pass for a timed one.
pub fn event_log_csv(session: &Session) -> String {
    let mut out = EVENT_LOG_COLUMNS.join(",");
    out.push('\n');
    for step in &session.steps {
        let hand = step.hand.map(|h| h.as_str()).unwrap_or_default();
        let object = step.object.as_deref().unwrap_or_default();
        let row = [
            "",
            "instruction",
            &step.text,
            &step.motion_type,
            hand,
            object,
        ];
        out.push_str(&row.map(field).join(","));
        out.push('\n');
        let mark = match step.hold {
            Some(Hold::Take) => Some("grasp"),
            Some(Hold::Release) => Some("release"),
            _ => None,
        };
        if let Some(mark) = mark {
            let row = ["", mark, "", "", hand, object];
            out.push_str(&row.map(field).join(","));
            out.push('\n');
        }
    }
    out
}

/// `12.5 s` or `3 min 5 s`.
fn duration(seconds: f64) -> String {
    let s = seconds.round() as u64;
    if s < 60 {
        format!("{seconds:.1} s")
    } else {
        format!("{} min {} s", s / 60, s % 60)
    }
}

/// The operator's sheet (Markdown): the start state, the numbered instructions with what to
/// mark, the end state, the balance before and after, and how to fill in the log.
pub fn operator_sheet(session: &Session, scene: &Scene, capture: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Capture session `{capture}`\n");
    let _ = writeln!(
        s,
        "Scene `{}`, seed {}: {} instructions, about {} of motion by the duration estimates.\n",
        scene.name,
        session.seed,
        session.steps.len(),
        duration(session.seconds())
    );
    let _ = writeln!(
        s,
        "Record the whole session as one capture named `{capture}` (for example \
         `{capture}.bvh`): the event log `{capture}.csv` is matched to it by name.\n"
    );
    if let Some(first) = session.steps.first() {
        let _ = writeln!(s, "**Start:** {}.\n", first.before.text(scene));
    }
    let _ = writeln!(s, "| # | instruction | type | hand | about | mark | then |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for (i, step) in session.steps.iter().enumerate() {
        let mark = match step.hold {
            Some(Hold::Take) => "grasp frame",
            Some(Hold::Release) => "release frame",
            _ => "",
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} |",
            i + 1,
            step.text.replace('|', "\\|"),
            step.motion_type,
            step.hand.map(|h| h.as_str()).unwrap_or(""),
            duration(step.seconds),
            mark,
            step.after.text(scene).replace('|', "\\|"),
        );
    }
    if let Some(last) = session.steps.last() {
        let _ = writeln!(
            s,
            "\n**End:** {} (a valid end state: {}).\n",
            last.after.text(scene),
            scene
                .end
                .iter()
                .map(|r| r.text(scene))
                .collect::<Vec<_>>()
                .join(", ")
        );
        debug_assert!(chain::is_end(scene, &last.after));
    }
    let _ = writeln!(s, "## Balance\n");
    let (before, after) = session.kl();
    let combined = session.combined_counts();
    let _ = writeln!(
        s,
        "Clips per motion type of the scene's target: the dataset's, this session's and the \
         target share. KL divergence to the target: {} before, {} after the session.\n",
        before.map_or("n/a (no dataset)".to_string(), |d| format!("{d:.4}")),
        after.map_or("n/a".to_string(), |d| format!("{d:.4}"))
    );
    let _ = writeln!(s, "| type | dataset | session | after | target |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for (t, q) in &session.target {
        let _ = writeln!(
            s,
            "| {t} | {} | {} | {} | {:.3} |",
            session.dataset_counts.get(t).copied().unwrap_or(0),
            session.session_counts.get(t).copied().unwrap_or(0),
            combined.get(t).copied().unwrap_or(0),
            q
        );
    }
    if !session.unreachable.is_empty() {
        let _ = writeln!(s, "\n## Never possible in this scene\n");
        for note in &session.unreachable {
            let _ = writeln!(s, "- {note}");
        }
    }
    let _ = writeln!(s, "\n## After the session\n");
    let _ = writeln!(
        s,
        "Fill the `time` column of `{capture}.csv`: the second (from the start of the capture) at \
         which each instruction was shown, and the grasp and release moments the assistant \
         marked (delete a grasp or release row that was not marked). A row left without a time \
         is refused when the log is read. Then add the capture and its log to a source with \
         `kind = \"event_log\"` and rebuild."
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_the_readers_and_fields_quote_commas() {
        for c in EVENT_LOG_COLUMNS {
            assert!(
                motionforge_sources::annotate::event_log::EVENT_COLUMNS.contains(&c),
                "{c} is not a column the event-log reader knows"
            );
        }
        assert_eq!(field("put the cup, then sit"), "\"put the cup, then sit\"");
        assert_eq!(field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(field("plain"), "plain");
    }
}
