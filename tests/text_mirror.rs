//! Caption mirroring checked on real action texts (BABEL labels and the SINC GPT-3 label list):
//! every property must hold on every text, and hand-checked real captions must come out exactly.
use crate::common;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use motionforge::text::*;
use serde_json::Value;

fn sinc_dir() -> PathBuf {
    let sinc = common::shared_data().join("sinc");
    assert!(sinc.is_dir(), "{} is missing", sinc.display());
    sinc
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&read(path)).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The real texts, by source.
struct Corpus {
    /// BABEL action labels, one per line of `clean_labels.txt`.
    clean_labels: Vec<String>,
    /// Keys of `gpt3-labels-list.json`: the action texts GPT-3 was asked about.
    gpt3_labels: Vec<String>,
    /// Values of `gpt3-labels-list.json`: multi-line "Answer: right arm\nleft arm" body-part lists.
    gpt3_answers: Vec<String>,
    /// Every `text` entry of `labels.json` (train and val pairs).
    pair_texts: Vec<String>,
}

impl Corpus {
    fn load() -> Corpus {
        let sinc = sinc_dir();

        let clean_labels: Vec<String> = read(&sinc.join("clean_labels.txt"))
            .lines()
            .map(str::to_owned)
            .collect();

        let gpt3 = read_json(&sinc.join("gpt3-labels-list.json"));
        let gpt3 = gpt3
            .as_object()
            .expect("gpt3-labels-list.json: top level must be an object of text -> answers");
        let gpt3_labels: Vec<String> = gpt3.keys().cloned().collect();
        let mut gpt3_answers = Vec::new();
        for (label, answers) in gpt3 {
            let answers = answers
                .as_array()
                .unwrap_or_else(|| panic!("gpt3 answers for {label:?} must be an array"));
            for answer in answers {
                let answer = answer
                    .as_str()
                    .unwrap_or_else(|| panic!("gpt3 answer for {label:?} must be a string"));
                gpt3_answers.push(answer.to_owned());
            }
        }

        let labels = read_json(&sinc.join("labels.json"));
        let mut pair_texts = Vec::new();
        let splits = labels
            .as_object()
            .expect("labels.json: top level must be an object of splits");
        assert!(
            splits.contains_key("train") && splits.contains_key("val"),
            "labels.json: expected train and val splits, found {:?}",
            splits.keys().collect::<Vec<_>>()
        );
        for (split, pairs) in splits {
            let pairs = pairs
                .as_object()
                .unwrap_or_else(|| panic!("labels.json {split}: must be an object"));
            for (id, pair) in pairs {
                let texts = pair["text"]
                    .as_array()
                    .unwrap_or_else(|| panic!("labels.json {split}/{id}: no text array"));
                for text in texts {
                    let text = text
                        .as_str()
                        .unwrap_or_else(|| panic!("labels.json {split}/{id}: text not a string"));
                    pair_texts.push(text.to_owned());
                }
            }
        }

        let corpus = Corpus {
            clean_labels,
            gpt3_labels,
            gpt3_answers,
            pair_texts,
        };
        // Exact sizes so that a truncated or swapped file fails here, not as a vacuous pass.
        assert_eq!(corpus.clean_labels.len(), 762, "clean_labels.txt lines");
        assert_eq!(corpus.gpt3_labels.len(), 6518, "gpt3-labels-list.json keys");
        assert_eq!(
            corpus.gpt3_answers.len(),
            19554,
            "gpt3-labels-list.json answers"
        );
        assert_eq!(corpus.pair_texts.len(), 46976, "labels.json texts");
        corpus
    }

    /// Distinct action texts (labels and pair texts, not the GPT-3 answers).
    fn action_texts(&self) -> BTreeSet<&str> {
        self.clean_labels
            .iter()
            .chain(&self.gpt3_labels)
            .chain(&self.pair_texts)
            .map(String::as_str)
            .collect()
    }

    /// Every distinct real text, answers included.
    fn all_texts(&self) -> BTreeSet<&str> {
        let mut all = self.action_texts();
        all.extend(self.gpt3_answers.iter().map(String::as_str));
        all
    }
}

/// Splits into maximal runs of word characters and of everything else, without any regex, as an
/// independent reading of "whole words, hyphens and underscores are boundaries".
fn runs(text: &str) -> Vec<(bool, &str)> {
    let mut out: Vec<(bool, &str)> = Vec::new();
    let mut start = 0;
    let mut current: Option<bool> = None;
    for (i, c) in text.char_indices() {
        let is_word = c.is_alphanumeric();
        if current.is_some_and(|w| w != is_word) {
            out.push((current.unwrap_or(false), &text[start..i]));
            start = i;
        }
        current = Some(is_word);
    }
    if let Some(w) = current {
        out.push((w, &text[start..]));
    }
    out
}

fn words(text: &str) -> Vec<&str> {
    runs(text)
        .into_iter()
        .filter_map(|(is_word, run)| is_word.then_some(run))
        .collect()
}

const SIDE_PAIRS: &[(&str, &str)] = &[
    ("left", "right"),
    ("lefts", "rights"),
    ("leftward", "rightward"),
    ("leftwards", "rightwards"),
    ("leftmost", "rightmost"),
];

fn swap_side(word: &str) -> Option<&'static str> {
    SIDE_PAIRS.iter().find_map(|&(l, r)| {
        if word == l {
            Some(r)
        } else if word == r {
            Some(l)
        } else {
            None
        }
    })
}

fn is_rotation_part(word: &str) -> bool {
    word.to_lowercase().contains("clockwise")
}

/// Word-level expectation: the sides named, and (meaningful for texts without rotation words)
/// the mirror, where each side word swaps except "right" in the geometric "a right angle" /
/// "right angles" / "right angled".
fn oracle(text: &str) -> (String, Vec<Side>) {
    let runs = runs(text);
    let word_positions: Vec<usize> = (0..runs.len()).filter(|&i| runs[i].0).collect();
    let mut out = String::new();
    let mut sides = Vec::new();
    for (i, &(is_word, run)) in runs.iter().enumerate() {
        if !is_word {
            out.push_str(run);
            continue;
        }
        let k = word_positions.iter().position(|&p| p == i).unwrap_or(0);
        let prev = k
            .checked_sub(1)
            .map(|j| runs[word_positions[j]].1.to_lowercase());
        let next = word_positions.get(k + 1).map(|&j| runs[j].1.to_lowercase());
        let lower = run.to_lowercase();
        let geometric = lower == "right"
            && match next.as_deref() {
                Some("angles" | "angled") => true,
                Some("angle") => prev.as_deref() == Some("a"),
                _ => false,
            };
        match swap_side(&lower) {
            Some(mirror) if !geometric => {
                sides.push(if lower.starts_with("left") {
                    Side::Left
                } else {
                    Side::Right
                });
                assert!(
                    run == lower || run == run.to_uppercase(),
                    "real texts are lower or upper case: {run:?} in {text:?}"
                );
                if run == lower {
                    out.push_str(mirror);
                } else {
                    out.push_str(&mirror.to_uppercase());
                }
            }
            _ => out.push_str(run),
        }
    }
    (out, sides)
}

fn count(sides: &[Side], side: Side) -> usize {
    sides.iter().filter(|&&s| s == side).count()
}

fn title_case_words(text: &str) -> String {
    runs(text)
        .into_iter()
        .map(|(is_word, run)| {
            let mut chars = run.chars();
            match (is_word, chars.next()) {
                (true, Some(first)) => first.to_uppercase().collect::<String>() + chars.as_str(),
                _ => run.to_owned(),
            }
        })
        .collect()
}

/// The properties every real text must satisfy; returns whether it round-tripped.
fn check_properties(text: &str) -> bool {
    let mirrored = mirror_text(text);
    let sides = side_words(text);
    let mirrored_sides = side_words(&mirrored);
    let rotations = rotation_words(text);

    // Position by position: no "left" after mirroring where the original said "left".
    let expected_sides: Vec<Side> = sides.iter().map(|s| s.mirrored()).collect();
    assert_eq!(
        mirrored_sides, expected_sides,
        "sides of {text:?} -> {mirrored:?}"
    );
    assert_eq!(
        count(&mirrored_sides, Side::Left),
        count(&sides, Side::Right)
    );
    assert_eq!(
        count(&mirrored_sides, Side::Right),
        count(&sides, Side::Left)
    );
    let expected_rotations: Vec<Rotation> = rotations.iter().map(|r| r.mirrored()).collect();
    assert_eq!(
        rotation_words(&mirrored),
        expected_rotations,
        "rotations of {text:?} -> {mirrored:?}"
    );

    // The library's word list agrees with a plain word split.
    let (oracle_mirrored, oracle_sides) = oracle(text);
    assert_eq!(sides, oracle_sides, "side detection of {text:?}");
    assert_eq!(
        !rotations.is_empty(),
        words(text).iter().any(|w| is_rotation_part(w)),
        "rotation detection of {text:?}"
    );

    if sides.is_empty() && rotations.is_empty() {
        assert_eq!(mirrored, text, "a text without side words must not change");
    }

    // Hyphens and underscores behave like spaces, and case is carried through.
    for sep in ["-", "_"] {
        assert_eq!(
            mirror_text(&text.replace(' ', sep)),
            mirrored.replace(' ', sep),
            "{text:?} with {sep:?} for spaces"
        );
    }
    assert_eq!(mirror_text(&text.to_uppercase()), mirrored.to_uppercase());
    assert_eq!(
        mirror_text(&title_case_words(text)),
        title_case_words(&mirrored),
        "title case of {text:?}"
    );

    if !rotations.is_empty() {
        // Spellings of counterclockwise collapse, so only the meaning must come back.
        assert_eq!(rotation_words(&mirror_text(&mirrored)), rotations);
        assert_eq!(side_words(&mirror_text(&mirrored)), sides);
        return false;
    }
    assert_eq!(mirrored, oracle_mirrored, "word-level mirror of {text:?}");
    assert_eq!(mirror_text(&mirrored), text, "mirroring {text:?} twice");
    let upper = text.to_uppercase();
    assert_eq!(mirror_text(&mirror_text(&upper)), upper);
    let title = title_case_words(text);
    assert_eq!(mirror_text(&mirror_text(&title)), title);
    true
}

#[derive(Debug, Default, PartialEq)]
struct Stats {
    texts: usize,
    with_side: usize,
    with_rotation: usize,
    round_trips: usize,
    changed: usize,
}

fn check_all<'a>(texts: impl IntoIterator<Item = &'a str>) -> Stats {
    let mut stats = Stats::default();
    for text in texts {
        stats.texts += 1;
        stats.with_side += usize::from(!side_words(text).is_empty());
        stats.with_rotation += usize::from(!rotation_words(text).is_empty());
        stats.changed += usize::from(mirror_text(text) != text);
        stats.round_trips += usize::from(check_properties(text));
    }
    stats
}

#[test]
fn properties_hold_on_every_real_action_text() {
    let corpus = Corpus::load();
    let texts = corpus.action_texts();
    let stats = check_all(texts.iter().copied());
    eprintln!("action texts: {stats:?}");
    // Every text without a rotation word round-trips; the rest only keep their meaning.
    assert_eq!(stats.round_trips, stats.texts - stats.with_rotation);
    assert_eq!(
        stats,
        Stats {
            texts: 6679,
            with_side: 2385,
            with_rotation: 51,
            round_trips: 6628,
            changed: 2423,
        }
    );
}

#[test]
fn properties_hold_on_every_real_gpt3_answer() {
    let corpus = Corpus::load();
    let answers: BTreeSet<&str> = corpus.gpt3_answers.iter().map(String::as_str).collect();
    let stats = check_all(answers.iter().copied());
    eprintln!("gpt3 answers: {stats:?}");
    assert_eq!(stats.round_trips, stats.texts - stats.with_rotation);
    assert_eq!(
        stats,
        Stats {
            texts: 315,
            with_side: 277,
            with_rotation: 0,
            round_trips: 315,
            changed: 277,
        }
    );
}

#[test]
fn each_source_has_side_words() {
    let corpus = Corpus::load();
    for (name, texts) in [
        ("clean_labels.txt", &corpus.clean_labels),
        ("gpt3 labels", &corpus.gpt3_labels),
        ("labels.json", &corpus.pair_texts),
    ] {
        let with_side = texts.iter().filter(|t| !side_words(t).is_empty()).count();
        eprintln!("{name}: {} texts, {with_side} with side words", texts.len());
        assert!(with_side > 0, "{name}: no side words found at all");
    }
}

/// Real captions (each asserted to be in the data) and their exact mirrors.
const EXAMPLES: &[(&str, &str)] = &[
    // Sides, swapped in one pass.
    ("turn left", "turn right"),
    ("walk left and right", "walk right and left"),
    ("cross left over right arm", "cross right over left arm"),
    (
        "waves right arm from left to right",
        "waves left arm from right to left",
    ),
    (
        "wave right hand under left arm",
        "wave left hand under right arm",
    ),
    (
        "brush teeth with right right hand",
        "brush teeth with left left hand",
    ),
    ("left right stepping", "right left stepping"),
    (
        "walk straight with both elbow slight fix at chest and right forearm slightly further apart from waist than left forearm",
        "walk straight with both elbow slight fix at chest and left forearm slightly further apart from waist than right forearm",
    ),
    (
        "Answer: right leg\nleft leg\nglobal orientation\ntorso",
        "Answer: left leg\nright leg\nglobal orientation\ntorso",
    ),
    // Longer side forms.
    ("walk left leftward", "walk right rightward"),
    ("turn lefts", "turn rights"),
    // Geometry, not a side.
    ("turn left at a right angle", "turn right at a right angle"),
    (
        "move in a right angle triangular path",
        "move in a right angle triangular path",
    ),
    ("rotate right angle", "rotate left angle"),
    ("rotate left angle", "rotate right angle"),
    // Rotation family.
    ("turn clockwise", "turn counterclockwise"),
    ("turn counterclockwise", "turn clockwise"),
    ("turn counter clockwise", "turn clockwise"),
    ("walk anticlockwise", "walk clockwise"),
    ("walk anti clockwise", "walk clockwise"),
    ("arms swing counter clockwise", "arms swing clockwise"),
    (
        "walk forward in counter clockwise circle",
        "walk forward in clockwise circle",
    ),
    (
        "circle left hand clockwise",
        "circle right hand counterclockwise",
    ),
    (
        "circle right hand counterclockwise",
        "circle left hand clockwise",
    ),
    (
        "anticlockwise rotation right hand",
        "clockwise rotation left hand",
    ),
    (
        "circle anticlockwise with t position",
        "circle clockwise with t position",
    ),
    (
        "large counter clockwise pot stir motion with left hand in front of torso",
        "large clockwise pot stir motion with right hand in front of torso",
    ),
    (
        "make large counter clockwise circles with left leg in front of body",
        "make large clockwise circles with right leg in front of body",
    ),
    (
        "rolls left ankle clockwise in front of body",
        "rolls right ankle counterclockwise in front of body",
    ),
    // Look-alikes that are not side or rotation words.
    ("stand upright", "stand upright"),
    ("return upright", "return upright"),
    ("mimic fright", "mimic fright"),
    ("place brush on counter", "place brush on counter"),
    ("look at clock", "look at clock"),
    // Hyphenated real texts without side words stay as they are.
    ("t-pose", "t-pose"),
    ("wear t-shirt", "wear t-shirt"),
    ("do push-up", "do push-up"),
];

#[test]
fn real_examples_mirror_exactly() {
    let corpus = Corpus::load();
    let all = corpus.all_texts();
    for &(text, expected) in EXAMPLES {
        assert!(
            all.contains(text),
            "{text:?} is not a real text in the data"
        );
        assert_eq!(mirror_text(text), expected, "mirror of {text:?}");
    }
}

/// Real captions rewritten with hyphens and underscores, as they appear in file names and keys.
#[test]
fn hyphenated_and_capitalised_forms_of_real_texts() {
    let corpus = Corpus::load();
    let all = corpus.all_texts();
    for (source, text, expected) in [
        ("wave left hand", "wave-left-hand", "wave-right-hand"),
        ("turn left", "turn_left", "turn_right"),
        ("turn left", "Turn Left", "Turn Right"),
        ("turn left", "TURN LEFT", "TURN RIGHT"),
        (
            "walk counter clockwise",
            "walk-counter-clockwise",
            "walk-clockwise",
        ),
        (
            "walk anti clockwise",
            "walk_anti-clockwise",
            "walk_clockwise",
        ),
        (
            "walk counterclockwise",
            "Walk Counterclockwise",
            "Walk Clockwise",
        ),
        ("walk clockwise", "WALK CLOCKWISE", "WALK COUNTERCLOCKWISE"),
        ("walk clockwise", "Walk Clockwise", "Walk Counterclockwise"),
        (
            "turn left at a right angle",
            "turn-left-at-a-right-angle",
            "turn-right-at-a-right-angle",
        ),
        ("stand upright", "stand-upright", "stand-upright"),
    ] {
        assert!(
            all.contains(source),
            "{source:?} is not a real text in the data"
        );
        assert_eq!(mirror_text(text), expected, "mirror of {text:?}");
    }
}

#[test]
fn hand_fields_mirror() {
    assert_eq!(mirror_side_word("left"), Some("right"));
    assert_eq!(mirror_side_word("right"), Some("left"));
    for keep in ["both", "none", ""] {
        assert_eq!(mirror_side_word(keep).unwrap_or(keep), keep);
    }
}

/// Issue 16: the two misspellings found in real KIT-ML captions. The captions themselves are not
/// in `../shared/data` (KIT-ML is not bundled), so the words are checked alone and in a caption's
/// usual frame.
#[test]
fn kit_ml_typos_are_mirrored() {
    assert_eq!(mirror_text("conterclockwise"), "clockwise");
    assert_eq!(mirror_text("degreeleftwards"), "degreerightwards");
    assert_eq!(
        mirror_text("a person walks in a conterclockwise circle"),
        "a person walks in a clockwise circle"
    );
    assert_eq!(
        mirror_text("a person turns 90 degreeleftwards"),
        "a person turns 90 degreerightwards"
    );
    assert_eq!(
        rotation_words("conterclockwise"),
        [Rotation::Counterclockwise]
    );
    assert_eq!(side_words("turns 90 degreeleftwards"), [Side::Left]);
}

/// The real texts outside [`Corpus`]: SINC's spatial pairs, BABEL's raw and processed labels, and
/// the Bandai Namco content labels (file-name captions such as `wave-left-hand`).
fn other_real_texts() -> Vec<String> {
    let data = common::shared_data();
    let mut texts = Vec::new();
    for split in ["train", "val"] {
        let path = data.join(format!("sinc/labels_{split}_spatial.json"));
        let pairs = read_json(&path);
        let pairs = pairs
            .as_object()
            .unwrap_or_else(|| panic!("{}: not an object", path.display()));
        for pair in pairs.values() {
            for text in pair.as_array().into_iter().flatten().take(2) {
                texts.extend(text.as_str().map(str::to_owned));
            }
        }
    }
    fn labels(value: &Value, out: &mut Vec<String>) {
        match value {
            Value::Object(map) => {
                for (key, v) in map {
                    match v {
                        Value::String(s) if key == "raw_label" || key == "proc_label" => {
                            out.push(s.clone())
                        }
                        _ => labels(v, out),
                    }
                }
            }
            Value::Array(items) => items.iter().for_each(|v| labels(v, out)),
            _ => {}
        }
    }
    let babel = read_json(&data.join("babel/babel_records_from_notebook_outputs.json"));
    let before = texts.len();
    labels(&babel, &mut texts);
    assert!(texts.len() > before, "BABEL records have labels");
    for folder in ["bandai-namco-1", "bandai-namco-2-subset"] {
        let list = read(&data.join(folder).join("cfg/content_label.txt"));
        texts.extend(list.lines().map(str::to_owned));
    }
    texts
}

/// Issue 16: no false positive on a word that merely contains a side word. Every word of every
/// real caption, and every word of WordNet 3.0 (`schemas/pos-lexicon.tsv`), is mirrored alone;
/// only the side and rotation words themselves may change.
#[test]
fn words_that_merely_contain_a_side_word_stay() {
    let corpus = Corpus::load();
    let mut texts: BTreeSet<String> = corpus.all_texts().into_iter().map(str::to_owned).collect();
    texts.extend(other_real_texts());
    let mut caption_words: BTreeSet<String> = BTreeSet::new();
    for text in &texts {
        caption_words.extend(words(text).into_iter().map(str::to_lowercase));
    }
    eprintln!(
        "{} real texts, {} distinct words",
        texts.len(),
        caption_words.len()
    );
    let wordnet_path = crate::common::repo().join("schemas/pos-lexicon.tsv");
    let wordnet: BTreeSet<String> = read(&wordnet_path)
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split('\t').next())
        .map(str::to_lowercase)
        .collect();
    assert!(wordnet.len() > 70_000, "{}", wordnet_path.display());
    let side_like = |w: &str| ["left", "right", "clock"].iter().any(|s| w.contains(s));
    let changed = |set: &BTreeSet<String>| -> Vec<String> {
        set.iter()
            .filter(|w| mirror_text(w) != **w || !side_words(w).is_empty())
            .cloned()
            .collect()
    };
    let caption_lookalikes: Vec<&String> = caption_words
        .iter()
        .filter(|w| side_like(w) && swap_side(w).is_none() && !is_rotation_part(w))
        .collect();
    let wordnet_lookalikes = wordnet
        .iter()
        .filter(|w| side_like(w) && swap_side(w).is_none() && !is_rotation_part(w))
        .count();
    eprintln!(
        "caption words containing a side word: {caption_lookalikes:?}; WordNet: {wordnet_lookalikes}"
    );
    assert_eq!(
        caption_lookalikes,
        ["clock", "fright", "upright"],
        "the real captions' look-alikes"
    );
    assert_eq!(
        changed(&caption_words),
        [
            "anticlockwise",
            "clockwise",
            "counterclockwise",
            "left",
            "lefts",
            "leftward",
            "right"
        ],
        "only side and rotation words change in real captions"
    );
    assert!(wordnet_lookalikes >= 70, "{wordnet_lookalikes}");
    assert_eq!(
        changed(&wordnet),
        [
            "anticlockwise",
            "clockwise",
            "contraclockwise",
            "counterclockwise",
            "left",
            "leftmost",
            "right",
            "rightmost"
        ],
        "only side and rotation words change among WordNet's 77,000"
    );
}
