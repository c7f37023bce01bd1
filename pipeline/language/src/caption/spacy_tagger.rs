//! spaCy `en_core_web_sm`'s part-of-speech tagger, run without Python.
//!
//! HumanML3D's caption tags are what `en_core_web_sm` predicted, so the caption writer runs
//! that model's own network on weights exported from it (`tools/export-caption-tagger.py`,
//! `schemas/caption-tagger-spacy.bin`; `docs/humanml3d-captions.md`): each token's NORM,
//! PREFIX, SUFFIX, SHAPE, SPACY and IS_SPACE attributes are hashed into six embedding tables
//! (thinc's `HashEmbed`: spaCy's 64-bit string hash, then MurmurHash3 x86-128 of that number
//! gives four rows per table, summed); a maxout layer with layer normalisation mixes them; four
//! residual layers each see a token and its two neighbours (window 1, maxout with three
//! pieces, layer normalisation), over the caption padded with four zero rows at each end as
//! thinc pads a document; a linear layer scores the 50 Penn Treebank tags and the best wins.

use std::collections::HashMap;

use serde::Deserialize;

const MODEL: &[u8] = include_bytes!("../../../../schemas/caption-tagger-spacy.bin");
const FILE: &str = "schemas/caption-tagger-spacy.bin";
const FORMAT: &str = "motionforge-caption-tagger 1";
const ATTRS: [&str; 6] = ["NORM", "PREFIX", "SUFFIX", "SHAPE", "SPACY", "IS_SPACE"];
/// Pieces per maxout unit, as the model was trained.
const PIECES: usize = 3;
/// Tokens the network encodes at once. It needs about 5 KB a token (six embedding rows, three
/// maxout pieces and a window of three rows, each of `width` floats), so a long text is encoded
/// in pieces of this many tokens (docs/performance.md, "Caption tagger memory").
const CHUNK_TOKENS: usize = 256;
/// Tokens of several texts encoded at once by [`SpacyTagger::tag_many`].
const BATCH_TOKENS: usize = 1024;

/// One token as spaCy's tokenizer gives it.
pub(crate) struct SpacyToken<'a> {
    /// The token's text.
    pub text: &'a str,
    /// Its norm when a tokenizer exception sets one (`n't` -> `not`).
    pub norm: Option<&'a str>,
    /// Whether one space follows it (spaCy's `whitespace_`).
    pub space_after: bool,
    /// Whether it is whitespace itself (spaCy's `is_space`: runs beyond one space).
    pub is_space: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    format: String,
    /// Which model the weights came from; for people reading the file.
    #[serde(rename = "source")]
    _source: String,
    labels: Vec<String>,
    attrs: Vec<String>,
    seeds: Vec<u32>,
    pad: usize,
    dtype: String,
    tensors: Vec<(String, Vec<usize>)>,
    lexeme_norm: HashMap<String, String>,
    special_norms: HashMap<String, Vec<String>>,
    symbols: HashMap<String, u64>,
}

/// A maxout layer followed by layer normalisation.
struct Maxout {
    /// (outputs * pieces) rows of `inputs` weights; row `o * PIECES + p` is piece p of output o.
    w: Vec<f32>,
    b: Vec<f32>,
    gain: Vec<f32>,
    shift: Vec<f32>,
    inputs: usize,
}

/// The loaded network.
pub(crate) struct SpacyTagger {
    labels: Vec<String>,
    /// Embedding tables (rows x width) with their hash seeds, in [`ATTRS`] order.
    embed: Vec<(Vec<f32>, usize, u32)>,
    /// The embedding mixer, then the residual window layers.
    layers: Vec<Maxout>,
    out_w: Vec<f32>,
    out_b: Vec<f32>,
    width: usize,
    pad: usize,
    lexeme_norm: HashMap<u64, String>,
    special_norms: HashMap<String, Vec<String>>,
    /// spaCy's symbol table: these strings get their symbol number instead of their hash.
    symbols: HashMap<String, u64>,
}

/// spaCy's string hash: MurmurHash64A of the UTF-8 bytes with seed 1 (`murmurhash.mrmr.hash64`).
pub(crate) fn hash_string(s: &str) -> u64 {
    const M: u64 = 0xc6a4_a793_5bd1_e995;
    const R: u32 = 47;
    let data = s.as_bytes();
    let mut h: u64 = 1 ^ (data.len() as u64).wrapping_mul(M);
    let mut chunks = data.chunks_exact(8);
    for c in &mut chunks {
        let mut k = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        k = k.wrapping_mul(M);
        k ^= k >> R;
        k = k.wrapping_mul(M);
        h ^= k;
        h = h.wrapping_mul(M);
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        for (j, &b) in rest.iter().enumerate() {
            h ^= u64::from(b) << (8 * j);
        }
        h = h.wrapping_mul(M);
    }
    h ^= h >> R;
    h = h.wrapping_mul(M);
    h ^ (h >> R)
}

/// thinc's `MurmurHash3_x86_128_uint64`: four 32-bit keys from one 64-bit id.
fn hash_id(val: u64, seed: u32) -> [u32; 4] {
    fn fmix(mut h: u64) -> u64 {
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
    let mut h1 = val.wrapping_mul(0x87c3_7b91_1142_53d5);
    h1 = h1.rotate_left(31);
    h1 = h1.wrapping_mul(0x4cf5_ad43_2745_937f);
    h1 ^= u64::from(seed);
    h1 ^= 8;
    let mut h2 = u64::from(seed) ^ 8;
    h1 = h1.wrapping_add(h2);
    h2 = h2.wrapping_add(h1);
    h1 = fmix(h1);
    h2 = fmix(h2);
    h1 = h1.wrapping_add(h2);
    h2 = h2.wrapping_add(h1);
    [h1 as u32, (h1 >> 32) as u32, h2 as u32, (h2 >> 32) as u32]
}

/// spaCy's `word_shape`: letters as `X`/`x`, digits as `d`, other characters kept, runs cut
/// after four.
fn word_shape(text: &str) -> String {
    if text.chars().count() >= 100 {
        return "LONG".into();
    }
    let mut out = String::new();
    let (mut last, mut run) = ('\0', 0);
    for c in text.chars() {
        let s = if c.is_alphabetic() {
            if c.is_uppercase() { 'X' } else { 'x' }
        } else if c.is_ascii_digit() {
            'd'
        } else {
            c
        };
        if s == last {
            run += 1;
        } else {
            run = 0;
            last = s;
        }
        if run < 4 {
            out.push(s);
        }
    }
    out
}

/// `out` (m x n) = `a` (m x k) times the transpose of `w` (n x k), all row-major: every layer
/// of the network is one such product, done by `matrixmultiply` (an optimised dependency, so
/// debug-build tests stay quick too).
fn matmul_t(a: &[f32], m: usize, k: usize, w: &[f32], n: usize, out: &mut [f32]) {
    assert!(
        a.len() == m * k && w.len() == n * k && out.len() == m * n,
        "matrix sizes are fixed when the model loads"
    );
    if m == 0 || n == 0 {
        return;
    }
    // SAFETY: the assertion above keeps every index sgemm reads or writes inside the slices:
    // a is m x k with strides (k, 1), w read as k x n with strides (1, k), out m x n with (n, 1).
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            k as isize,
            1,
            w.as_ptr(),
            1,
            k as isize,
            0.0,
            out.as_mut_ptr(),
            n as isize,
            1,
        );
    }
}

impl Maxout {
    /// Each row of `out` (m x width) = layernorm(maxout(row of `x`)), `x` being m x inputs.
    fn apply(&self, x: &[f32], m: usize, out: &mut [f32]) {
        let width = self.gain.len();
        let mut y = vec![0.0f32; m * width * PIECES];
        matmul_t(x, m, self.inputs, &self.w, width * PIECES, &mut y);
        for (row, dst) in y
            .chunks_exact(width * PIECES)
            .zip(out.chunks_exact_mut(width))
        {
            for (o, slot) in dst.iter_mut().enumerate() {
                let mut best = f32::NEG_INFINITY;
                for p in 0..PIECES {
                    best = best.max(row[o * PIECES + p] + self.b[o * PIECES + p]);
                }
                *slot = best;
            }
            let n = width as f32;
            let mean = dst.iter().sum::<f32>() / n;
            let var = dst.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / n + 1e-8;
            let scale = 1.0 / var.sqrt();
            for (i, v) in dst.iter_mut().enumerate() {
                *v = (*v - mean) * scale * self.gain[i] + self.shift[i];
            }
        }
    }
}

/// Why the exported spaCy tagger model does not load (a build with a broken `schemas/` file).
#[derive(Debug, thiserror::Error)]
pub enum SpacyModelError {
    /// No line break ends the JSON header.
    #[error("{FILE}: no header line")]
    NoHeader,
    /// The header is not the expected JSON.
    #[error("{FILE}: header: {0}")]
    Header(#[source] serde_json::Error),
    /// Another format or value type than this reader's.
    #[error("{FILE}: format {format:?} / dtype {dtype:?}, expected {FORMAT:?} / \"f16le\"")]
    Format {
        /// The header's format.
        format: String,
        /// The header's value type.
        dtype: String,
    },
    /// Other token attributes than this reader's, or not one seed each.
    #[error("{FILE}: attributes {attrs:?}, expected {ATTRS:?} with one seed each")]
    Attrs {
        /// The header's attributes.
        attrs: Vec<String>,
    },
    /// A tensor's shape multiplies beyond what can be counted.
    #[error("{FILE}: tensor {name}: shape {shape:?} overflows")]
    ShapeOverflow {
        /// The tensor.
        name: String,
        /// Its shape.
        shape: Vec<usize>,
    },
    /// The tensors' sizes add up beyond what can be counted.
    #[error("{FILE}: tensor sizes overflow")]
    SizesOverflow,
    /// The header lists another number of weights than the file holds.
    #[error("{FILE}: the header lists {need} weights, the file holds {bytes} bytes of them")]
    Size {
        /// Weights listed.
        need: usize,
        /// Bytes after the header.
        bytes: usize,
    },
    /// A weight is NaN or infinite.
    #[error("{FILE}: tensor {name} holds a non-finite weight")]
    NonFinite {
        /// The tensor.
        name: String,
    },
    /// A tensor the network needs is missing.
    #[error("{FILE}: no tensor {name}")]
    NoTensor {
        /// The tensor.
        name: String,
    },
    /// A tensor has another shape than the network needs.
    #[error("{FILE}: tensor {name} has shape {shape:?}, expected {want:?}")]
    Shape {
        /// The tensor.
        name: String,
        /// Its shape.
        shape: Vec<usize>,
        /// The shape needed.
        want: Vec<usize>,
    },
    /// No `layernorm0.G` tensor gives the network's width.
    #[error("{FILE}: no layernorm0.G to give the width")]
    NoWidth,
    /// A `lexeme_norm` key is not a hash.
    #[error("{FILE}: lexeme_norm key {key:?} is not a 64-bit hash")]
    NormKey {
        /// The key.
        key: String,
    },
}

impl SpacyTagger {
    /// The bundled model.
    pub(crate) fn bundled() -> Result<SpacyTagger, SpacyModelError> {
        SpacyTagger::load(MODEL)
    }

    /// Reads an exported model: a JSON header line, then half floats (`tools/export-caption-tagger.py`).
    pub(crate) fn load(bytes: &[u8]) -> Result<SpacyTagger, SpacyModelError> {
        let split = bytes
            .iter()
            .position(|&b| b == b'\n')
            .ok_or(SpacyModelError::NoHeader)?;
        let header: Header =
            serde_json::from_slice(&bytes[..split]).map_err(SpacyModelError::Header)?;
        if header.format != FORMAT || header.dtype != "f16le" {
            let (format, dtype) = (header.format, header.dtype);
            return Err(SpacyModelError::Format { format, dtype });
        }
        if header.attrs != ATTRS || header.seeds.len() != ATTRS.len() {
            let attrs = header.attrs;
            return Err(SpacyModelError::Attrs { attrs });
        }
        let body = &bytes[split + 1..];
        // Check the sizes the header claims against the bytes there before allocating anything.
        let mut need = 0usize;
        for (name, shape) in &header.tensors {
            let n = shape
                .iter()
                .try_fold(1usize, |a, &d| a.checked_mul(d))
                .ok_or_else(|| SpacyModelError::ShapeOverflow {
                    name: name.clone(),
                    shape: shape.clone(),
                })?;
            need = need.checked_add(n).ok_or(SpacyModelError::SizesOverflow)?;
        }
        if need.checked_mul(2) != Some(body.len()) {
            return Err(SpacyModelError::Size {
                need,
                bytes: body.len(),
            });
        }
        let mut tensors: HashMap<&str, (&[usize], Vec<f32>)> = HashMap::new();
        let mut at = 0;
        for (name, shape) in &header.tensors {
            let n: usize = shape.iter().product();
            let values = body[at..at + 2 * n]
                .chunks_exact(2)
                .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
                .collect::<Vec<f32>>();
            if values.iter().any(|v| !v.is_finite()) {
                return Err(SpacyModelError::NonFinite { name: name.clone() });
            }
            at += 2 * n;
            tensors.insert(name.as_str(), (shape.as_slice(), values));
        }
        let mut take = |name: &str, want: &[usize]| -> Result<Vec<f32>, SpacyModelError> {
            let (shape, v) = tensors
                .remove(name)
                .ok_or_else(|| SpacyModelError::NoTensor { name: name.into() })?;
            if shape != want {
                return Err(SpacyModelError::Shape {
                    name: name.into(),
                    shape: shape.to_vec(),
                    want: want.to_vec(),
                });
            }
            Ok(v)
        };
        let width = header
            .tensors
            .iter()
            .find(|(n, _)| n == "layernorm0.G")
            .and_then(|(_, s)| s.first().copied())
            .filter(|&w| w > 0)
            .ok_or(SpacyModelError::NoWidth)?;
        let mut embed = Vec::new();
        for (attr, &seed) in ATTRS.iter().zip(&header.seeds) {
            let name = format!("embed.{attr}");
            let rows = header
                .tensors
                .iter()
                .find(|(n, _)| *n == name)
                .and_then(|(_, s)| s.first().copied())
                .filter(|&r| r > 0)
                .ok_or_else(|| SpacyModelError::NoTensor { name: name.clone() })?;
            embed.push((take(&name, &[rows, width])?, rows, seed));
        }
        let mut layers = Vec::new();
        for i in 0..5 {
            let inputs = if i == 0 {
                ATTRS.len() * width
            } else {
                3 * width
            };
            layers.push(Maxout {
                w: take(&format!("maxout{i}.W"), &[width * PIECES, inputs])?,
                b: take(&format!("maxout{i}.b"), &[width * PIECES])?,
                gain: take(&format!("layernorm{i}.G"), &[width])?,
                shift: take(&format!("layernorm{i}.b"), &[width])?,
                inputs,
            });
        }
        let n_labels = header.labels.len();
        let out_w = take("softmax.W", &[n_labels, width])?;
        let out_b = take("softmax.b", &[n_labels])?;
        let mut lexeme_norm = HashMap::with_capacity(header.lexeme_norm.len());
        for (k, v) in header.lexeme_norm {
            let key: u64 = k
                .parse()
                .map_err(|_| SpacyModelError::NormKey { key: k.clone() })?;
            lexeme_norm.insert(key, v);
        }
        Ok(SpacyTagger {
            labels: header.labels,
            embed,
            layers,
            out_w,
            out_b,
            width,
            pad: header.pad,
            lexeme_norm,
            special_norms: header.special_norms,
            symbols: header.symbols,
        })
    }

    /// The norms spaCy's tokenizer exceptions give the pieces of `chunk` (`doesn't` -> `does`,
    /// `not`), when it has an exception for it.
    pub(crate) fn special_norms(&self, chunk: &str) -> Option<&[String]> {
        self.special_norms.get(chunk).map(Vec::as_slice)
    }

    fn norm(&self, t: &SpacyToken) -> String {
        if let Some(n) = t.norm {
            return n.to_string();
        }
        self.lexeme_norm
            .get(&hash_string(t.text))
            .cloned()
            .unwrap_or_else(|| t.text.to_lowercase())
    }

    /// A token's NORM, PREFIX, SUFFIX, SHAPE, SPACY and IS_SPACE as spaCy's `Doc.to_array`
    /// gives them: strings as their 64-bit hashes, flags as 0 or 1.
    pub(crate) fn attributes(&self, t: &SpacyToken) -> [u64; 6] {
        let suffix_start = t.text.char_indices().rev().nth(2).map_or(0, |(j, _)| j);
        let prefix_end = t.text.chars().next().map_or(0, char::len_utf8);
        let id = |s: &str| {
            self.symbols
                .get(s)
                .copied()
                .unwrap_or_else(|| hash_string(s))
        };
        [
            id(&self.norm(t)),
            id(&t.text[..prefix_end]),
            id(&t.text[suffix_start..]),
            id(&word_shape(t.text)),
            u64::from(t.space_after),
            u64::from(t.is_space),
        ]
    }

    /// The Penn Treebank tag of each token.
    #[cfg(test)]
    pub(crate) fn tag(&self, tokens: &[SpacyToken]) -> Vec<&str> {
        self.tag_many(&[tokens]).pop().unwrap_or_default()
    }

    /// The label with the highest score (the first of equal ones).
    fn best(&self, row: &[f32]) -> &str {
        let mut best = (0, f32::NEG_INFINITY);
        for (c, (s, b)) in row.iter().zip(&self.out_b).enumerate() {
            if s + b > best.1 {
                best = (c, s + b);
            }
        }
        self.labels[best.0].as_str()
    }

    /// The Penn Treebank tags of each of several texts, computed together: every layer is one
    /// matrix product over the rows of all of them. The weights are packed once a product, which
    /// for one short caption costs as much as the product itself (`docs/performance.md`,
    /// "Captions tagged in batches"); each row's arithmetic is the same as alone, so the tags
    /// (and the scores, bit for bit) are those of each text tagged alone (the tests' `tag`).
    pub(crate) fn tag_many(&self, texts: &[&[SpacyToken]]) -> Vec<Vec<&str>> {
        let mut out: Vec<Vec<&str>> = texts.iter().map(|t| Vec::with_capacity(t.len())).collect();
        let windows = texts.iter().enumerate().flat_map(|(i, tokens)| {
            (0..tokens.len()).step_by(CHUNK_TOKENS).map(move |from| {
                let to = tokens.len().min(from + CHUNK_TOKENS);
                (i, Window { tokens, from, to })
            })
        });
        // Batches of at most BATCH_TOKENS tokens asked for, so memory stays bounded.
        let mut batch: Vec<(usize, Window)> = Vec::new();
        let mut asked = 0;
        for (i, window) in windows {
            let len = window.to - window.from;
            if asked + len > BATCH_TOKENS && !batch.is_empty() {
                self.tag_batch(&batch, &mut out);
                batch.clear();
                asked = 0;
            }
            asked += len;
            batch.push((i, window));
        }
        self.tag_batch(&batch, &mut out);
        out
    }

    /// Appends the tags of each window of `batch` to its text's tags in `out`.
    fn tag_batch<'s>(&'s self, batch: &[(usize, Window)], out: &mut [Vec<&'s str>]) {
        let labels = self.out_b.len();
        let windows: Vec<Window> = batch.iter().map(|(_, w)| *w).collect();
        for ((i, _), scores) in batch.iter().zip(self.scores(&windows)) {
            if let Some(tags) = out.get_mut(*i) {
                tags.extend(scores.chunks_exact(labels).map(|row| self.best(row)));
            }
        }
    }

    /// The label scores (before the bias) of every token, `chunk` tokens at a time in order:
    /// the network's buffers then hold `chunk` tokens and their neighbours however long the
    /// text is, and each token's scores are those of one pass over the whole text.
    #[cfg(test)]
    fn scores_in_chunks(&self, tokens: &[SpacyToken], chunk: usize, mut each: impl FnMut(&[f32])) {
        let mut from = 0;
        while from < tokens.len() {
            let to = tokens.len().min(from + chunk.max(1));
            let window = Window { tokens, from, to };
            for scores in self.scores(&[window]) {
                each(&scores);
            }
            from = to;
        }
    }

    /// The label scores of each window's `tokens[from..to]`, computed over just the rows they
    /// depend on, all windows' rows in one matrix product a layer.
    ///
    /// The encoder runs over a text with `pad` zero rows at each end, as thinc pads a
    /// document; the rows are numbered here from the first of those. Residual layer `l` (from 0)
    /// changes the rows within `depth - 1 - l` of a token and reads one row either side, so a
    /// token's result depends only on the rows within `depth` of it: the span `[a, b)` takes
    /// those of the tokens asked for. A row at the span's edge that is not the document's
    /// edge is computed with a zero neighbour, but that error moves inwards one row a layer and
    /// stops `depth` rows short of the first token asked for.
    fn scores(&self, windows: &[Window]) -> Vec<Vec<f32>> {
        let w = self.width;
        let depth = self.layers.len() - 1;
        let spans: Vec<Span> = windows
            .iter()
            .scan(0, |rows, win| {
                let span = Span::of(win, self.pad, depth, *rows);
                *rows += span.b - span.a;
                Some(span)
            })
            .collect();
        let total_rows: usize = spans.iter().map(|s| s.b - s.a).sum();
        // Layer 0 mixes each token's embeddings; its rows go to the tokens' places in `x`.
        let token_rows: usize = spans.iter().map(|s| s.t1 - s.t0).sum();
        let mut features = vec![0.0f32; token_rows * ATTRS.len() * w];
        let mut rows = features.chunks_exact_mut(ATTRS.len() * w);
        for (win, span) in windows.iter().zip(&spans) {
            for (t, row) in win.tokens[span.t0..span.t1].iter().zip(&mut rows) {
                self.embed_into(t, row);
            }
        }
        let mut mixed = vec![0.0f32; token_rows * w];
        self.layers[0].apply(&features, token_rows, &mut mixed);
        let mut x = vec![0.0f32; total_rows * w];
        let mut mixed_rows = mixed.chunks_exact(w);
        for span in &spans {
            let at = span.offset + span.t0 + self.pad - span.a;
            for (dst, src) in x[at * w..]
                .chunks_exact_mut(w)
                .zip(&mut mixed_rows)
                .take(span.t1 - span.t0)
            {
                dst.copy_from_slice(src);
            }
        }
        for (l, layer) in self.layers[1..].iter().enumerate() {
            let margin = depth - (l + 1);
            // The rows a pass over the whole document changes at this layer, inside each span.
            let changed: Vec<(usize, usize)> = spans
                .iter()
                .map(|s| {
                    let lo = self.pad.saturating_sub(margin).max(s.a);
                    let hi = (self.pad + s.n + margin).min(s.b);
                    (lo, hi.max(lo))
                })
                .collect();
            let m: usize = changed.iter().map(|(lo, hi)| hi - lo).sum();
            if m == 0 {
                continue;
            }
            let mut window = vec![0.0f32; m * 3 * w];
            let mut wins = window.chunks_exact_mut(3 * w);
            for (span, &(lo, hi)) in spans.iter().zip(&changed) {
                let xs = &x[span.offset * w..(span.offset + span.b - span.a) * w];
                for (r, win) in (lo - span.a..hi - span.a).zip(&mut wins) {
                    if r > 0 {
                        win[..w].copy_from_slice(&xs[(r - 1) * w..r * w]);
                    }
                    win[w..2 * w].copy_from_slice(&xs[r * w..(r + 1) * w]);
                    if span.a + r + 1 < span.b {
                        win[2 * w..].copy_from_slice(&xs[(r + 1) * w..(r + 2) * w]);
                    }
                }
            }
            let mut out = vec![0.0f32; m * w];
            layer.apply(&window, m, &mut out);
            let mut added = out.chunks_exact(w);
            for (span, &(lo, hi)) in spans.iter().zip(&changed) {
                let rows = (span.offset + lo - span.a)..(span.offset + hi - span.a);
                for (dst, add) in x[rows.start * w..rows.end * w]
                    .chunks_exact_mut(w)
                    .zip(&mut added)
                {
                    for (d, a) in dst.iter_mut().zip(add) {
                        *d += a;
                    }
                }
            }
        }
        let asked: usize = windows.iter().map(|win| win.to - win.from).sum();
        let mut rows = Vec::with_capacity(asked * w);
        for span in &spans {
            let first = span.offset + span.first - span.a;
            rows.extend_from_slice(&x[first * w..(first + span.end - span.first) * w]);
        }
        let labels = self.out_b.len();
        let mut scores = vec![0.0f32; asked * labels];
        matmul_t(&rows, asked, w, &self.out_w, labels, &mut scores);
        let mut rest = scores.as_slice();
        windows
            .iter()
            .map(|win| {
                let (mine, after) = rest.split_at((win.to - win.from) * labels);
                rest = after;
                mine.to_vec()
            })
            .collect()
    }

    /// Adds a token's six embedding rows (four hashed rows of each table) into `row`.
    fn embed_into(&self, t: &SpacyToken, row: &mut [f32]) {
        let w = self.width;
        let ids = self.attributes(t);
        for (((table, rows, seed), id), slot) in
            self.embed.iter().zip(ids).zip(row.chunks_exact_mut(w))
        {
            for key in hash_id(id, *seed) {
                let r = key as usize % rows;
                for (s, e) in slot.iter_mut().zip(&table[r * w..(r + 1) * w]) {
                    *s += e;
                }
            }
        }
    }
}

/// Tokens `from..to` of a text, whose scores are asked for.
#[derive(Clone, Copy)]
struct Window<'t, 'a> {
    tokens: &'t [SpacyToken<'a>],
    from: usize,
    to: usize,
}

/// Where a [`Window`]'s rows lie: `[a, b)` of its padded text (the rows its tokens depend on),
/// its tokens `t0..t1` among them, the rows asked for `first..end`, and its first row's place
/// in the batch's buffer.
struct Span {
    a: usize,
    b: usize,
    t0: usize,
    t1: usize,
    first: usize,
    end: usize,
    n: usize,
    offset: usize,
}

impl Span {
    fn of(win: &Window, pad: usize, depth: usize, offset: usize) -> Span {
        let n = win.tokens.len();
        let total = n + 2 * pad;
        let (first, end) = (pad + win.from, pad + win.to);
        let a = first.saturating_sub(depth);
        let b = total.min(end + depth);
        Span {
            a,
            b,
            t0: a.max(pad) - pad,
            t1: b.min(pad + n) - pad,
            first,
            end,
            n,
            offset,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hashes_match_spacy_and_thinc() {
        // Values printed by spaCy 3.8's `spacy.strings.hash_string` and thinc's `NumpyOps.hash`.
        assert_eq!(hash_string("adjust"), 12254408354648292678);
        assert_eq!(
            hash_id(12254408354648292678, 8),
            [83421806, 2734496466, 125132709, 1954261051]
        );
        assert_eq!(word_shape("Walk"), "Xxxx");
        assert_eq!(word_shape("walking"), "xxxx");
        assert_eq!(word_shape("90s"), "ddx");
    }

    /// Tokens of `words`, one space between each.
    fn spaced<'a>(words: &[&'a str]) -> Vec<SpacyToken<'a>> {
        words
            .iter()
            .enumerate()
            .map(|(i, text)| SpacyToken {
                text,
                norm: None,
                space_after: i + 1 < words.len(),
                is_space: false,
            })
            .collect()
    }

    #[test]
    fn tags_do_not_depend_on_what_was_tagged_before() {
        let m = SpacyTagger::bundled().unwrap();
        let caption = spaced(&["raise", "left", "arm"]);
        let first = m.tag(&caption);
        let other = [SpacyToken {
            text: "walk",
            norm: None,
            space_after: false,
            is_space: false,
        }];
        m.tag(&other);
        assert_eq!(m.tag(&caption), first);
        assert_eq!(first, ["VB", "JJ", "NN"]);
    }

    #[test]
    fn scores_do_not_depend_on_how_the_text_is_cut() {
        let m = SpacyTagger::bundled().unwrap();
        let text = "a person walks forward , turns around and waves the left hand ; then \
                    someone doesn't stop but jumps up twice , arms raised over the head .";
        let words: Vec<&str> = text.split(' ').collect();
        let tokens = spaced(&words);
        let cut = |chunk: usize| {
            let mut all = Vec::new();
            m.scores_in_chunks(&tokens, chunk, |s| {
                all.extend(s.iter().map(|v| v.to_bits()))
            });
            all
        };
        let whole = cut(tokens.len());
        assert_eq!(whole.len(), tokens.len() * m.out_b.len());
        for chunk in [1, 2, 3, 5, 8, 9, tokens.len() - 1] {
            assert!(cut(chunk) == whole, "cut every {chunk} tokens");
        }
        assert_eq!(m.tag(&tokens[..3]), ["DT", "NN", "VBZ"]);
    }

    #[test]
    fn texts_scored_together_get_the_bits_they_get_alone() {
        let m = SpacyTagger::bundled().unwrap();
        let long: Vec<String> = (0..CHUNK_TOKENS + 40)
            .map(|i| ["walk", "forward", "and", "wave", "twice", ","][i % 6].to_string())
            .collect();
        let texts: Vec<Vec<&str>> = vec![
            "a person walks forward , then turns around"
                .split(' ')
                .collect(),
            vec!["jump"],
            vec![],
            long.iter().map(String::as_str).collect(),
            "raise left arm".split(' ').collect(),
        ];
        let tokens: Vec<Vec<SpacyToken>> = texts.iter().map(|t| spaced(t)).collect();
        // Whole short texts in one product, against each alone.
        let short: Vec<Window> = tokens
            .iter()
            .filter(|t| !t.is_empty() && t.len() < CHUNK_TOKENS)
            .map(|t| Window {
                tokens: t,
                from: 0,
                to: t.len(),
            })
            .collect();
        let bits = |s: Vec<f32>| s.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let together: Vec<_> = m.scores(&short).into_iter().map(bits).collect();
        let alone: Vec<_> = short
            .iter()
            .map(|w| bits(m.scores(&[*w]).remove(0)))
            .collect();
        assert!(together == alone);
        // Tags of a batch with an empty and a long text, against one pass over each text.
        let refs: Vec<&[SpacyToken]> = tokens.iter().map(Vec::as_slice).collect();
        let tagged = m.tag_many(&refs);
        assert_eq!(tagged.len(), texts.len());
        for (t, tags) in tokens.iter().zip(&tagged) {
            let mut whole = Vec::new();
            m.scores_in_chunks(t, t.len().max(1), |s| {
                whole.extend(s.chunks_exact(m.out_b.len()).map(|row| m.best(row)))
            });
            assert_eq!(tags, &whole);
        }
        assert_eq!(tagged[4], ["VB", "JJ", "NN"]);
    }

    #[test]
    fn bundled_model_loads_and_damaged_files_are_refused() {
        let m = SpacyTagger::bundled().unwrap();
        assert_eq!(m.labels.len(), 50);
        assert!(SpacyTagger::load(b"no header").is_err());
        let cut = &MODEL[..MODEL.len() - 2];
        let err = SpacyTagger::load(cut).err().unwrap();
        assert!(matches!(err, SpacyModelError::Size { .. }), "{err}");
        assert!(err.to_string().contains("weights"), "{err}");
    }
}
