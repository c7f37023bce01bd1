//! Body-part labels on real data: SINC's GPT-3 answers, the manual gold labels (SINC Table 1
//! protocol), the embedded lexicon labeller, and part-velocity evidence on Bandai Namco captures.
//!
//! Run with `--nocapture` to see the tables that `docs/part-labels.md` quotes.
use crate::common;

use std::collections::BTreeMap;
use std::path::PathBuf;

use common::*;
use motionforge::motion::{BodyPart, ProfileSpec};
use motionforge::parts::answer::parse_part_answer;
use motionforge::parts::eval::{Evaluation, Gold, GoldLabel, evaluate, format_table, read_gold};
use motionforge::parts::lexicon::label_text;
use motionforge::parts::velocity::{agreement, part_scores};
use motionforge::parts::{PartSet, part_name};

fn sinc(name: &str) -> PathBuf {
    shared_data().join("sinc").join(name)
}

/// `{text: [answer_v1, answer_v2, answer_v3]}`.
fn gpt3_answers() -> BTreeMap<String, Vec<String>> {
    let path = sinc("gpt3-labels-list.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn gold() -> Gold {
    let path = sinc("part-labels-gold-dev.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    read_gold(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn third(answers: &[String]) -> &str {
    answers
        .get(2)
        .map(String::as_str)
        .unwrap_or_else(|| panic!("every text has three answers"))
}

fn assert_close(actual: f64, expected: f64, what: &str) {
    assert!(
        (actual - expected).abs() < 5e-5,
        "{what}: measured {actual:.6}, expected {expected:.6}"
    );
}

fn assert_row(eval: &Evaluation, expected: [f64; 6], mean: f64, name: &str) {
    for (i, (a, e)) in eval.per_part.iter().zip(expected).enumerate() {
        assert_close(*a, e, &format!("{name} {}", part_name(BodyPart::ALL[i])));
    }
    assert_close(eval.mean, mean, &format!("{name} mean"));
}

#[test]
fn every_third_answer_parses_and_exactly_the_off_list_ones_are_flagged() {
    let answers = gpt3_answers();
    assert_eq!(answers.len(), 6518);
    let mut parsed = 0;
    let mut raw_off_list = Vec::new();
    let mut flagged = Vec::new();
    let mut empty = Vec::new();
    for (text, a) in &answers {
        let p = parse_part_answer(third(a));
        parsed += 1;
        if p.has_raw_off_list() {
            println!(
                "off-list: {text:?} -> {:?} => parts [{}], synonyms {:?}, off-list {:?}",
                third(a),
                p.parts,
                p.synonyms,
                p.off_list
            );
            raw_off_list.push(text.as_str());
        }
        if p.is_flagged() {
            flagged.push(text.as_str());
        }
        if p.empty {
            empty.push(text.as_str());
        }
    }
    assert_eq!(parsed, 6518);
    // The data README's 12 answers with text outside the prompt's list.
    assert_eq!(
        raw_off_list,
        [
            "animal behavior series",
            "bird behavior series",
            "check time on watch",
            "elephant behavior series",
            "grab right shoulder with left arm",
            "marine animal behavior series",
            "move fingers on left hand",
            "rub right side of face with right hand",
            "shrug with hands at sides",
            "shrug with hands down",
            "swim on air",
            "touch right eye with right hand",
        ]
    );
    // `shoulders` (twice) and `right shoulder` are SINC's own synonyms: mapped, not flagged.
    assert_eq!(
        flagged,
        [
            "animal behavior series",
            "bird behavior series",
            "check time on watch",
            "elephant behavior series",
            "marine animal behavior series",
            "move fingers on left hand",
            "rub right side of face with right hand",
            "swim on air",
            "touch right eye with right hand",
        ]
    );
    // The refusals ("None of the above.", "This question does not have a specific answer...").
    assert_eq!(
        empty,
        [
            "animal behavior series",
            "bird behavior series",
            "elephant behavior series",
            "marine animal behavior series",
            "swim on air",
        ]
    );
    println!(
        "{parsed} answers parsed; {} with raw off-list text, {} flagged after synonyms, {} empty",
        raw_off_list.len(),
        flagged.len(),
        empty.len()
    );
    let shrug = parse_part_answer(third(&answers["shrug with hands down"]));
    assert_eq!(shrug.parts.to_string(), "torso, left_arm, right_arm");
    let eye = parse_part_answer(third(&answers["touch right eye with right hand"]));
    assert_eq!(eye.parts.to_string(), "right_arm");
    assert_eq!(eye.off_list, ["right eye"]);
}

#[test]
fn gold_file_reads_with_sinc_shape() {
    let gold = gold();
    assert_eq!(gold.len(), 52);
    let answers = gpt3_answers();
    assert!(
        gold.texts().all(|t| answers.contains_key(t)),
        "every gold text has a GPT-3 answer"
    );
}

#[test]
fn gpt3_answers_score_sinc_table1_on_the_gold_texts() {
    let answers = gpt3_answers();
    let gold = gold();
    let eval = evaluate(&gold, |t| {
        answers.get(t).map(|a| parse_part_answer(third(a)).parts)
    });
    println!("{}", format_table(&[("GPT-3 (list + few-shot)", &eval)]));
    assert!(eval.missing.is_empty());
    assert_eq!(eval.counted, [50, 51, 51, 51, 50, 50]);
    assert_eq!(eval.correct, [43, 42, 45, 46, 47, 47]);
    assert_row(
        &eval,
        [
            43.0 / 50.0,
            42.0 / 51.0,
            45.0 / 51.0,
            46.0 / 51.0,
            47.0 / 50.0,
            47.0 / 50.0,
        ],
        0.891307,
        "GPT-3",
    );
    assert_eq!(format!("{:.2}", eval.mean), "0.89");
}

#[test]
fn embedded_labeller_on_the_gold_texts_and_against_gpt3() {
    let answers = gpt3_answers();
    let gold = gold();
    let gpt = evaluate(&gold, |t| {
        answers.get(t).map(|a| parse_part_answer(third(a)).parts)
    });
    // Unknown texts keep the documented default, so no gold text goes missing.
    let embedded = evaluate(&gold, |t| Some(label_text(t).parts));
    // The stricter reading: an unknown text is no prediction and leaves the counts.
    let known_only = evaluate(&gold, |t| {
        let l = label_text(t);
        l.known.then_some(l.parts)
    });
    println!(
        "{}",
        format_table(&[
            ("GPT-3 (list + few-shot)", &gpt),
            ("Embedded lexicon", &embedded),
            ("Embedded, known texts only", &known_only),
        ])
    );
    for text in gold.texts() {
        let l = label_text(text);
        println!("  {text:?} -> [{}] via {:?}", l.parts, l.matched);
    }
    assert!(embedded.missing.is_empty());

    // The fixed development split (FNV-1a parity of the text): the lexicon's failure classes were
    // found on the tuning half and on BABEL's texts; the held-out half was only scored.
    let (tuning, held_out) = gold.split();
    assert_eq!((tuning.len(), held_out.len()), (28, 24));
    let tuned = evaluate(&tuning, |t| Some(label_text(t).parts));
    let held = evaluate(&held_out, |t| Some(label_text(t).parts));
    let gpt_tuned = evaluate(&tuning, |t| {
        answers.get(t).map(|a| parse_part_answer(third(a)).parts)
    });
    let gpt_held = evaluate(&held_out, |t| {
        answers.get(t).map(|a| parse_part_answer(third(a)).parts)
    });
    println!(
        "{}",
        format_table(&[
            ("Embedded, tuning half", &tuned),
            ("Embedded, held-out half", &held),
            ("GPT-3, tuning half", &gpt_tuned),
            ("GPT-3, held-out half", &gpt_held),
        ])
    );
    for entry in &held_out.entries {
        let l = label_text(&entry.text);
        let wrong: Vec<&str> = BodyPart::ALL
            .into_iter()
            .zip(entry.labels)
            .filter(|(part, g)| match g {
                GoldLabel::Yes => !l.parts.contains(*part),
                GoldLabel::No => l.parts.contains(*part),
                GoldLabel::Sometimes => false,
            })
            .map(|(part, _)| part_name(part))
            .collect();
        if !wrong.is_empty() {
            println!(
                "  held-out miss: {:?} -> [{}] wrong on {wrong:?}",
                entry.text, l.parts
            );
        }
    }
    assert_eq!(tuned.correct, TUNING_CORRECT);
    assert_eq!(held.correct, HELD_OUT_CORRECT);
    assert!(
        embedded.mean >= 0.92,
        "the goal of issue 16: mean {:.4} on the development gold",
        embedded.mean
    );

    // Held-out-style check: agreement with GPT-3's parsed answers on the BABEL texts that are not
    // gold texts (the ones the lexicon's defaults were checked against), and on all of them.
    let gold_texts: Vec<&str> = gold.texts().collect();
    let mut agree = [0usize; 6];
    let mut n = 0;
    let mut unknown = 0;
    for (text, a) in &answers {
        if gold_texts.contains(&text.as_str()) {
            continue;
        }
        let g = parse_part_answer(third(a)).parts;
        let l = label_text(text);
        unknown += usize::from(!l.known);
        n += 1;
        for (i, part) in BodyPart::ALL.into_iter().enumerate() {
            agree[i] += usize::from(g.contains(part) == l.parts.contains(part));
        }
    }
    let per_part = agree.map(|a| a as f64 / n as f64);
    let mean = per_part.iter().sum::<f64>() / 6.0;
    println!(
        "agreement with GPT-3 on {n} non-gold BABEL texts: {} mean {mean:.4}; {unknown} unknown",
        per_part
            .iter()
            .map(|x| format!("{x:.3}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    println!("agreeing texts per part: {agree:?}");
    assert_eq!(n, 6518 - 52);

    // Regression guards: the values measured when the lexicon was frozen.
    assert_eq!(embedded.counted, gpt.counted);
    assert_eq!(embedded.correct, EMBEDDED_CORRECT);
    assert_eq!(
        known_only.missing,
        ["baby position", "perform action on item", "straight up"]
    );
    assert_close(embedded.mean, EMBEDDED_MEAN, "embedded mean");
    assert_eq!(agree, AGREE_COUNTS);
    assert_eq!(unknown, UNKNOWN_TEXTS);
}

/// Before the failure classes of issue 16 were fixed: [45, 41, 47, 48, 48, 47], mean 0.911111;
/// tuning half [22, 20, 24, 24, 24, 24] (mean 0.8685), held-out half [23, 21, 23, 24, 24, 23]
/// (mean 0.9583).
const EMBEDDED_CORRECT: [usize; 6] = [45, 47, 47, 48, 48, 47];
/// (45/50 + 47/51 + 47/51 + 48/51 + 48/50 + 47/50) / 6.
const EMBEDDED_MEAN: f64 = 0.930719;
/// Of 26, 27, 27, 27, 26, 26 counted.
const TUNING_CORRECT: [usize; 6] = [22, 25, 24, 24, 24, 24];
/// Of 24 counted on every part.
const HELD_OUT_CORRECT: [usize; 6] = [23, 22, 23, 24, 24, 23];
/// Texts (of 6,466) on which the lexicon agrees with GPT-3, per part (before issue 16: [5520,
/// 4160, 5886, 5926, 5952, 5941]).
const AGREE_COUNTS: [usize; 6] = [5528, 4383, 5899, 5941, 5966, 5956];
/// 175 before issue 16: `curve 90 degrees to the right` became known (a turn), `untangle self from
/// jump rope` and `pretend to be a mime on a trap on a box` unknown (nouns after `from`, `on`).
const UNKNOWN_TEXTS: usize = 176;

/// Content label of a Bandai file name `dataset-1_{content}_{style}_{take}.bvh`.
fn bandai_content(path: &std::path::Path) -> String {
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or_else(|| panic!("{}: no file name", path.display()));
    name.split('_')
        .nth(1)
        .unwrap_or_else(|| panic!("{name}: not dataset-1_content_style_take"))
        .to_string()
}

#[test]
fn velocity_evidence_on_bandai_agrees_with_the_lexicon() {
    let files = bvh_files(&shared_data().join("bandai-namco-1/data"));
    assert_eq!(files.len(), 174);
    let spec = ProfileSpec::bundled("bandai-namco").unwrap();
    let mut by_content: BTreeMap<String, (f64, usize, BTreeMap<String, usize>)> = BTreeMap::new();
    let mut total = 0.0;
    let grid_scores = [-0.5, -0.25, 0.0, 0.25, 0.5];
    let grid_speeds = [0.0, 0.02, 0.03, 0.05, 0.10, 0.20];
    let mut grid = [[0.0; 6]; 5];
    for path in &files {
        let bvh = load(path);
        let profile = spec.bind(&bvh.skeleton).unwrap();
        let scores = part_scores(&bvh.motion, &profile);
        let content = bandai_content(path);
        // `walk-back` -> "walk back": the label read as a caption.
        let text = content.replace('-', " ");
        let label = label_text(&text);
        let a = agreement(scores.parts, label.parts);
        total += a;
        for (i, &t) in grid_scores.iter().enumerate() {
            for (j, &v) in grid_speeds.iter().enumerate() {
                grid[i][j] += agreement(scores.parts_at(t, v), label.parts) / files.len() as f64;
            }
        }
        if scores.parts.is_empty() {
            println!(
                "no part above threshold: {} speeds {:.3?} scores {:.2?}",
                path.file_name().and_then(|s| s.to_str()).unwrap_or("?"),
                scores.speed,
                scores.score
            );
        }
        let entry = by_content.entry(content).or_default();
        entry.0 += a;
        entry.1 += 1;
        *entry.2.entry(scores.parts.to_string()).or_default() += 1;
    }
    let mean = total / files.len() as f64;
    println!("velocity vs lexicon on {} Bandai captures:", files.len());
    println!(
        "{:<12} {:>5} {:>9}  {:<36} velocity parts (count)",
        "content", "n", "agreement", "lexicon parts"
    );
    let mut per_content = Vec::new();
    for (content, (sum, n, sets)) in &by_content {
        let lex = label_text(&content.replace('-', " "));
        let a = sum / *n as f64;
        per_content.push((content.clone(), a));
        println!(
            "{content:<12} {n:>5} {a:>9.3}  {:<36} {sets:?}",
            format!(
                "[{}]{}",
                lex.parts,
                if lex.known { "" } else { " (unknown)" }
            )
        );
    }
    println!("mean agreement over the six parts: {mean:.4}");
    println!("sensitivity (rows: score threshold; columns: minimum speed m/s {grid_speeds:?}):");
    for (i, t) in grid_scores.iter().enumerate() {
        println!("  {t:>5.2}: {:.3?}", grid[i]);
    }
    // The chosen thresholds are the (0.0, 0.03) cell.
    assert_close(grid[2][2], mean, "grid cell of the chosen thresholds");
    assert_close(mean, VELOCITY_AGREEMENT, "velocity agreement");
}

const VELOCITY_AGREEMENT: f64 = 0.920498;

#[test]
fn part_sets_mirror_compose_and_serialise() {
    let walk = label_text("walk forward").parts;
    let wave_left = label_text("wave with the left hand").parts;
    assert_eq!(
        wave_left.mirrored(),
        label_text("wave with the right hand").parts
    );
    assert!(
        walk.is_disjoint(wave_left),
        "SINC: walking and waving compose"
    );
    assert!(!walk.is_disjoint(label_text("kick with right leg").parts));
    let json = serde_json::to_string(&walk).unwrap();
    assert_eq!(json, r#"["global","left_leg","right_leg"]"#);
    assert_eq!(serde_json::from_str::<PartSet>(&json).unwrap(), walk);
    assert_eq!(walk.mirrored(), walk);
    assert_eq!(walk.to_vec6(), [true, false, false, false, true, true]);
}
