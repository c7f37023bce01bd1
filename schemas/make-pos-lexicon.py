"""Regenerates pos-lexicon.tsv and pos-exceptions.tsv from WordNet 3.0 (Debian's wordnet-base
package: `apt-get install wordnet-base`, files in /usr/share/wordnet). Nothing here looks at any
caption: the lexicon is every single-word, lower-case alphabetic lemma of WordNet's four index
files, with how often each part of speech was tagged in SemCor (WordNet's cntlist.rev)."""
import collections
import re
import sys

WN = sys.argv[1] if len(sys.argv) > 1 else "/usr/share/wordnet"
HEADER = """# Open-class English words for the HumanML3D caption tagger (pipeline/language/src/caption/rules.rs).
# Source: WordNet 3.0 (Princeton University), index.noun/.verb/.adj/.adv and cntlist.rev, as
# shipped in Debian's wordnet-base 1:3.0; converted by schemas/make-pos-lexicon.py.
# Licence: WordNet 3.0 licence (schemas/LICENSE.wordnet.txt). WordNet 3.0 Copyright 2006 by
# Princeton University. All rights reserved.
# Columns: word, then for NOUN, VERB, ADJ, ADV: '-' when WordNet has no such lemma, else the number
# of SemCor tokens tagged with a sense of it (0 = a lemma that SemCor never tagged).
"""
EXC_HEADER = """# Irregular inflections for the HumanML3D caption tagger's lemmatiser.
# Source: WordNet 3.0 (Princeton University) noun.exc, verb.exc, adj.exc, as shipped in Debian's
# wordnet-base 1:3.0; converted by schemas/make-pos-lexicon.py (alphabetic single words only).
# Licence: WordNet 3.0 licence (schemas/LICENSE.wordnet.txt). WordNet 3.0 Copyright 2006 by
# Princeton University. All rights reserved.
# Columns: inflected form, part of speech (NOUN, VERB, ADJ), lemma.
"""
WORD = re.compile(r"[a-z]+")
COLUMNS = {"noun": 0, "verb": 1, "adj": 2, "adv": 3}
SS_TYPE = {"1": 0, "2": 1, "3": 2, "4": 3, "5": 2}

counts = collections.defaultdict(lambda: [None] * 4)
for name, col in COLUMNS.items():
    with open(f"{WN}/index.{name}") as f:
        for line in f:
            lemma = line.split(" ", 1)[0]
            if not line.startswith(" ") and WORD.fullmatch(lemma):
                counts[lemma][col] = 0
with open(f"{WN}/cntlist.rev") as f:
    for line in f:
        key, _, tagged = line.split()
        lemma, rest = key.split("%")
        col = SS_TYPE[rest.split(":")[0]]
        if lemma in counts and counts[lemma][col] is not None:
            counts[lemma][col] += int(tagged)
with open("pos-lexicon.tsv", "w") as out:
    out.write(HEADER)
    for word in sorted(counts):
        cells = ["-" if c is None else str(c) for c in counts[word]]
        out.write(word + "\t" + "\t".join(cells) + "\n")
with open("pos-exceptions.tsv", "w") as out:
    out.write(EXC_HEADER)
    for name, tag in [("noun", "NOUN"), ("verb", "VERB"), ("adj", "ADJ")]:
        with open(f"{WN}/{name}.exc") as f:
            for line in f:
                form, *lemmas = line.split()
                for lemma in lemmas:
                    if WORD.fullmatch(form) and WORD.fullmatch(lemma) and form != lemma:
                        out.write(f"{form}\t{tag}\t{lemma}\n")
