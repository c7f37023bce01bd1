//! SINC Table 1 protocol: part-labelling accuracy against manual labels.
//!
//! The gold file maps each action text to six labels in SINC's order `[global, torso, left arm,
//! right arm, left leg, right leg]`: `1` the part is involved, `0` it is not, `0.5` "sometimes"
//! (acceptable either way). For every part, accuracy is the fraction of texts whose prediction
//! matches a `1`/`0` label; `0.5` labels are skipped, as in SINC, so each part has its own count.
//! The mean is the unweighted mean of the six per-part accuracies (SINC's "Mean" column), not the
//! accuracy over all counted cells.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use super::{PartSet, part_name};
use motionforge_core::motion::BodyPart;

/// One manual label.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoldLabel {
    /// `0`: not involved.
    No,
    /// `1`: involved.
    Yes,
    /// `0.5`: sometimes; skipped when scoring.
    Sometimes,
}

/// One labelled text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct GoldEntry {
    /// The action text.
    pub text: String,
    /// Labels in SINC's order.
    pub labels: [GoldLabel; 6],
}

/// A gold file: labelled texts in the file's key order as the JSON reader returns it (sorted).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Gold {
    /// The labelled texts.
    pub entries: Vec<GoldEntry>,
}

impl Gold {
    /// Number of labelled texts.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there is no text.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The texts.
    pub fn texts(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|e| e.text.as_str())
    }

    /// The fixed development split (tuning half, held-out half) by [`is_tuning_text`].
    pub fn split(&self) -> (Gold, Gold) {
        let (tuning, held_out) = self
            .entries
            .iter()
            .cloned()
            .partition(|e| is_tuning_text(&e.text));
        (Gold { entries: tuning }, Gold { entries: held_out })
    }
}

/// Whether a gold text is in the tuning half of the development split: the 64-bit FNV-1a hash
/// of its UTF-8 bytes is even. The split was fixed before the held-out answers were read, so a
/// rule tuned on one half can be measured on the other; it depends only on the text, so it is
/// the same for any gold file and any order.
pub fn is_tuning_text(text: &str) -> bool {
    let hash = text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    hash % 2 == 0
}

/// Why a gold file does not read.
#[derive(Debug, thiserror::Error)]
pub enum GoldError {
    /// Not JSON.
    #[error("gold labels are not valid JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// JSON, but not an object of text -> labels.
    #[error("gold labels must be a JSON object mapping each text to six labels")]
    NotAnObject,
    /// A text whose labels are not a list of six.
    #[error("gold labels for `{text}`: expected a list of 6 numbers, found {found}")]
    Shape {
        /// The action text.
        text: String,
        /// What was there instead.
        found: String,
    },
    /// A label other than 0, 0.5 or 1.
    #[error("gold label {index} ({part}) for `{text}` is {value}: expected 0, 0.5 or 1")]
    Value {
        /// The action text.
        text: String,
        /// Position in SINC's order.
        index: usize,
        /// The part at that position.
        part: &'static str,
        /// The offending value.
        value: String,
    },
}

/// Reads a gold file: `{"text": [g, t, la, ra, ll, rl], ...}` with values 0, 0.5 or 1.
pub fn read_gold(text: &str) -> Result<Gold, GoldError> {
    let value: serde_json::Value = serde_json::from_str(text)?;
    let serde_json::Value::Object(map) = value else {
        return Err(GoldError::NotAnObject);
    };
    let mut entries = Vec::with_capacity(map.len());
    for (text, labels) in map {
        let list = match &labels {
            serde_json::Value::Array(list) if list.len() == 6 => list,
            other => {
                return Err(GoldError::Shape {
                    text,
                    found: other.to_string(),
                });
            }
        };
        let mut out = [GoldLabel::No; 6];
        for (index, v) in list.iter().enumerate() {
            out[index] = match v.as_f64() {
                Some(0.0) => GoldLabel::No,
                Some(1.0) => GoldLabel::Yes,
                Some(0.5) => GoldLabel::Sometimes,
                _ => {
                    return Err(GoldError::Value {
                        text,
                        index,
                        part: part_name(BodyPart::ALL[index]),
                        value: v.to_string(),
                    });
                }
            };
        }
        entries.push(GoldEntry { text, labels: out });
    }
    Ok(Gold { entries })
}

/// Scores of one labeller on a gold file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Accuracy per part in SINC's order (`NaN`, written as JSON `null`, for a part with nothing
    /// counted).
    pub per_part: [f64; 6],
    /// Unweighted mean of the per-part accuracies that have a count (SINC's "Mean").
    pub mean: f64,
    /// Texts counted per part: those with a prediction and a 0/1 label for the part.
    pub counted: [usize; 6],
    /// Correct predictions per part.
    pub correct: [usize; 6],
    /// Texts the labeller gave no prediction for; they are left out of every count.
    pub missing: Vec<String>,
    /// Texts in the gold file.
    pub texts: usize,
}

/// Scores `predict` on every gold text (SINC Table 1 protocol, see the module doc).
pub fn evaluate(gold: &Gold, predict: impl Fn(&str) -> Option<PartSet>) -> Evaluation {
    let mut counted = [0usize; 6];
    let mut correct = [0usize; 6];
    let mut missing = Vec::new();
    for entry in &gold.entries {
        let Some(parts) = predict(&entry.text) else {
            missing.push(entry.text.clone());
            continue;
        };
        for (i, part) in BodyPart::ALL.into_iter().enumerate() {
            let truth = match entry.labels[i] {
                GoldLabel::Yes => true,
                GoldLabel::No => false,
                GoldLabel::Sometimes => continue,
            };
            counted[i] += 1;
            if parts.contains(part) == truth {
                correct[i] += 1;
            }
        }
    }
    let per_part: [f64; 6] = std::array::from_fn(|i| {
        if counted[i] == 0 {
            f64::NAN
        } else {
            correct[i] as f64 / counted[i] as f64
        }
    });
    let scored: Vec<f64> = per_part.iter().copied().filter(|x| !x.is_nan()).collect();
    let mean = if scored.is_empty() {
        f64::NAN
    } else {
        scored.iter().sum::<f64>() / scored.len() as f64
    };
    Evaluation {
        per_part,
        mean,
        counted,
        correct,
        missing,
        texts: gold.len(),
    }
}

const HEADER: [&str; 7] = [
    "Global",
    "Torso",
    "Left arm",
    "Right arm",
    "Left leg",
    "Right leg",
    "Mean",
];

impl Evaluation {
    /// The per-part accuracies and the mean, two decimals, in SINC's column order.
    pub fn row(&self) -> [f64; 7] {
        let p = self.per_part;
        [p[0], p[1], p[2], p[3], p[4], p[5], self.mean]
    }

    /// A plain-text table of this evaluation alone (see [`format_table`] for several).
    pub fn to_table(&self) -> String {
        format_table(&[("accuracy", self)])
    }
}

/// A plain-text table in SINC Table 1's layout, one row per labeller, with each row's counts and
/// missing texts underneath.
pub fn format_table(rows: &[(&str, &Evaluation)]) -> String {
    let name_width = rows
        .iter()
        .map(|(n, _)| n.chars().count())
        .chain(["Body part labeling".len()])
        .max()
        .unwrap_or(0);
    let mut out = String::new();
    let _ = write!(out, "{:<name_width$}", "Body part labeling");
    for h in HEADER {
        let _ = write!(out, "  {h:>9}");
    }
    out.push('\n');
    for (name, eval) in rows {
        let _ = write!(out, "{name:<name_width$}");
        for x in eval.row() {
            if x.is_nan() {
                let _ = write!(out, "  {:>9}", "-");
            } else {
                let _ = write!(out, "  {x:>9.2}");
            }
        }
        out.push('\n');
    }
    for (name, eval) in rows {
        let counts: Vec<String> = eval.counted.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(
            out,
            "{name}: {} texts, counted per part [{}], {} without a prediction",
            eval.texts,
            counts.join(", "),
            eval.missing.len()
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOLD: &str = r#"{
        "walk": [1, 0, 0, 0, 1, 1],
        "wave": [0, 0.5, 1, 1, 0, 0],
        "look left": [0, 1, 0, 0, 0, 0]
    }"#;

    #[test]
    fn reads_the_sinc_shape() {
        let gold = read_gold(GOLD).unwrap();
        assert_eq!(gold.len(), 3);
        let wave = gold.entries.iter().find(|e| e.text == "wave").unwrap();
        assert_eq!(wave.labels[1], GoldLabel::Sometimes);
    }

    #[test]
    fn rejects_bad_shapes_and_values() {
        assert!(matches!(read_gold("[1]"), Err(GoldError::NotAnObject)));
        assert!(matches!(
            read_gold(r#"{"a": [1, 0]}"#),
            Err(GoldError::Shape { .. })
        ));
        let err = read_gold(r#"{"a": [1, 0, 0, 0, 0, 2]}"#).unwrap_err();
        assert!(matches!(err, GoldError::Value { index: 5, .. }), "{err}");
        assert!(err.to_string().contains("right_leg"));
        assert!(matches!(read_gold("{"), Err(GoldError::Json(_))));
    }

    #[test]
    fn the_split_depends_on_the_text_only() {
        // FNV-1a 64 of "" is the offset basis (odd); of "a" it is 0xaf63dc4c8601ec8c (even).
        assert!(!is_tuning_text(""));
        assert!(is_tuning_text("a"));
        let gold = read_gold(GOLD).unwrap();
        let (tuning, held_out) = gold.split();
        assert_eq!(tuning.len() + held_out.len(), gold.len());
        assert!(tuning.texts().all(is_tuning_text));
        assert!(!held_out.texts().any(is_tuning_text));
    }

    #[test]
    fn sometimes_is_skipped_and_mean_is_over_parts() {
        let gold = read_gold(GOLD).unwrap();
        // Perfect except the torso of "walk" and nothing for "look left".
        let eval = evaluate(&gold, |t| match t {
            "walk" => Some(PartSet::from_vec6([true, true, false, false, true, true])),
            "wave" => Some(PartSet::ARMS),
            _ => None,
        });
        assert_eq!(eval.missing, ["look left"]);
        assert_eq!(eval.counted, [2, 1, 2, 2, 2, 2]);
        assert_eq!(eval.per_part[1], 0.0);
        assert!((eval.mean - 5.0 / 6.0).abs() < 1e-12);
        let table = eval.to_table();
        assert!(table.contains("0.83"), "{table}");
        let json = serde_json::to_string(&eval).unwrap();
        assert!(json.contains("\"mean\""));
    }
}
