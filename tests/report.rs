//! The statistics report: counts checked against an independent reader (pyarrow), quartiles on
//! known inputs, every figure and table written, byte-identical output for the same rows, and the
//! figures' text measured on a compiled two-column page.
//!
//! Set `MOTIONFORGE_REPORT_KEEP=<dir>` to keep the demo report there for inspection.

use crate::common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use motionforge::report::{
    self, ClipRow, DPI, FIGURES, MIN_VIOLIN, NO_SPLIT, ReportInput, Span, Stats, Summary, UNMAPPED,
    find_clip_tables, lengths_by_type, read_build_counts, read_rows, statistics, violin_outline,
    write_report,
};

/// The clip tables of a build, wherever the build put them: every `.parquet` with a `clip_id`
/// column (tables are moving from `<out>/clips.parquet` to sharded `data/<split>-*.parquet`).
fn clip_tables(dir: &Path) -> Vec<PathBuf> {
    let tables = find_clip_tables(dir).expect("scan the build output");
    assert!(!tables.is_empty(), "no clip table under {}", dir.display());
    assert!(
        tables
            .iter()
            .all(|t| t.file_name().is_some_and(|n| n != "plans.parquet")),
        "{tables:?}"
    );
    tables
}

/// The build report (`build-report.json`) next to the tables, if any.
fn find_build_report(dir: &Path) -> Option<PathBuf> {
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).ok()?.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().is_some_and(|n| n == "build-report.json") {
                return Some(p);
            }
        }
    }
    None
}

fn python(script: &str, args: &[&Path]) -> serde_json::Value {
    let out = Command::new(common::python())
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{:?}: {e}; {}", common::python(), common::PYTHON_SETUP));
    assert!(
        out.status.success(),
        "python failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("python prints JSON")
}

/// Independent statistics with pyarrow and numpy over the same files.
const PY_STATS: &str = r#"
import json, sys
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
tables = [pq.read_table(p) for p in sys.argv[1:]]
rows = []
for t in tables:
    has_split = "split" in t.column_names
    d = t.select([c for c in ["clip_id", "source_kind", "mirrored", "motion_type", "fps",
                              "num_frames", "label_source", "goal_pelvis"]
                  + (["split"] if has_split else [])
                  + (["texts"] if "texts" in t.column_names else [])]).to_pylist()
    for r in d:
        r["split"] = r["split"] if has_split else "all"
        rows.append(r)
types = {}
for r in rows:
    if r["mirrored"] or r["source_kind"] != "real_single":
        continue
    t = r["motion_type"] if r["motion_type"] is not None else "(unmapped)"
    types.setdefault(t, []).append(r)
out = {"types": {}, "composition": {}, "label_sources": {}, "goals": 0, "rows": len(rows)}
for t, rs in types.items():
    secs = np.array([r["num_frames"] / r["fps"] for r in rs])
    q = np.percentile(secs, [0, 25, 50, 75, 100]).tolist()
    out["types"][t] = {"clips": len(rs), "frames": sum(r["num_frames"] for r in rs), "q": q}
for r in rows:
    c = out["composition"].setdefault(r["split"], {})
    c[r["source_kind"]] = c.get(r["source_kind"], 0) + 1
    if not r["mirrored"]:
        if r["source_kind"] != "synthetic":
            k = r["label_source"] if r["label_source"] is not None else "(none)"
            out["label_sources"][k] = out["label_sources"].get(k, 0) + 1
        if r["goal_pelvis"] is not None:
            out["goals"] += 1
import re
captions = [c for r in rows if not r["mirrored"] and r["source_kind"] != "synthetic" for c in (r.get("texts") or [])]
words = [re.findall(r"[a-z0-9']+", c.lower()) for c in captions]
per_clip = [len(r.get("texts") or []) for r in rows if not r["mirrored"] and r["source_kind"] != "synthetic"]
out["text"] = {"captions": len(captions), "vocabulary": len({w for ws in words for w in ws}),
               "words_median": float(np.median([len(ws) for ws in words])) if words else None,
               "words_mean": float(np.mean([len(ws) for ws in words])) if words else None,
               "per_clip_mean": float(np.mean(per_clip)) if per_clip else None}
print(json.dumps(out))
"#;

fn check_against_pyarrow(stats: &Stats, tables: &[PathBuf]) {
    let args: Vec<&Path> = tables.iter().map(PathBuf::as_path).collect();
    let py = python(PY_STATS, &args);
    assert_eq!(stats.overview.rows as u64, py["rows"].as_u64().unwrap());
    let py_types = py["types"].as_object().unwrap();
    assert_eq!(stats.motion_types.len(), py_types.len(), "{py_types:?}");
    for t in &stats.motion_types {
        let p = &py_types[&t.motion_type];
        assert_eq!(
            t.clips as u64,
            p["clips"].as_u64().unwrap(),
            "{}",
            t.motion_type
        );
        assert_eq!(t.total_frames, p["frames"].as_u64().unwrap());
        let s = t.seconds.expect("a type with clips has lengths");
        let q: Vec<f64> = p["q"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for (mine, theirs) in [s.min, s.q1, s.median, s.q3, s.max].iter().zip(&q) {
            assert!(
                (mine - theirs).abs() < 1e-5,
                "{}: {mine} vs {theirs}",
                t.motion_type
            );
        }
    }
    let py_comp = py["composition"].as_object().unwrap();
    assert_eq!(stats.composition.len(), py_comp.len());
    for split in &stats.composition {
        let p = &py_comp[&split.split];
        for k in &split.kinds {
            let expected = p.get(&k.source_kind).and_then(|v| v.as_u64()).unwrap_or(0);
            assert_eq!(
                k.total as u64, expected,
                "{} {}",
                split.split, k.source_kind
            );
        }
    }
    let py_labels: BTreeMap<String, usize> =
        serde_json::from_value(py["label_sources"].clone()).unwrap();
    assert_eq!(stats.label_sources, py_labels);
    assert_eq!(stats.goals.clips as u64, py["goals"].as_u64().unwrap());
    // Caption statistics: counts, vocabulary and words per caption as numpy computes them.
    let t = &stats.text;
    assert_eq!(t.captions as u64, py["text"]["captions"].as_u64().unwrap());
    assert_eq!(
        t.vocabulary as u64,
        py["text"]["vocabulary"].as_u64().unwrap()
    );
    if let Some(w) = t.words_per_caption {
        assert!((w.median - py["text"]["words_median"].as_f64().unwrap()).abs() < 1e-9);
        assert!((w.mean - py["text"]["words_mean"].as_f64().unwrap()).abs() < 1e-6);
    }
    if let Some(c) = t.captions_per_clip {
        assert!((c.mean - py["text"]["per_clip_mean"].as_f64().unwrap()).abs() < 1e-6);
    }
}

fn input(tables: &[PathBuf], drops: BTreeMap<String, usize>) -> ReportInput {
    let mut rejects = BTreeMap::new();
    rejects.insert("llm_failed".to_string(), 1);
    ReportInput {
        tables: tables.to_vec(),
        drops,
        rejects,
        title: "demo_set & co".to_string(),
        contradictions: Vec::new(),
    }
}

/// Reads a PNG's width and height from its IHDR chunk.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    (be(&bytes[16..20]), be(&bytes[20..24]))
}

/// Per SVG: parsed with Python's XML parser, the texts of its `<text>` elements.
const PY_SVG: &str = r#"
import json, sys
import xml.etree.ElementTree as ET
out = {}
for p in sys.argv[1:]:
    root = ET.parse(p).getroot()
    out[p] = ["".join(e.itertext()).strip() for e in root.iter() if e.tag.endswith("text")]
print(json.dumps(out))
"#;

/// Per PNG: how many distinct RGB colours its pixels have (decoded with zlib, filters undone).
const PY_PNG: &str = r#"
import json, struct, sys, zlib
out = {}
for p in sys.argv[1:]:
    b = open(p, "rb").read()
    pos, idat, w, h, ct = 8, b"", 0, 0, 0
    while pos < len(b):
        n, kind = struct.unpack(">I4s", b[pos:pos + 8])
        data = b[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ct = struct.unpack(">IIBB", data[:10])
        elif kind == b"IDAT":
            idat += data
        pos += 12 + n
    raw = zlib.decompress(idat)
    bpp = {2: 3, 6: 4}[ct]
    stride = w * bpp
    prev = bytearray(stride)
    colours = set()
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            up = prev[x]
            c = prev[x - bpp] if x >= bpp else 0
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + up) & 255
            elif f == 3: line[x] = (line[x] + (a + up) // 2) & 255
            elif f == 4:
                pa, pb, pc = abs(up - c), abs(a - c), abs(a + up - 2 * c)
                pr = a if pa <= pb and pa <= pc else (up if pb <= pc else c)
                line[x] = (line[x] + pr) & 255
        prev = line
        if y % 4 == 0:
            for x in range(0, w, 2):
                colours.add(bytes(line[x * bpp:x * bpp + 3]))
    out[p] = len(colours)
print(json.dumps(out))
"#;

fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_path_buf();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

#[test]
fn demo_report_matches_pyarrow_and_is_reproducible() {
    let tmp = tempfile::tempdir().unwrap();
    let build = tmp.path().join("build");
    common::build_demo(&build);
    let tables = clip_tables(&build);
    let rows = read_rows(&tables).unwrap();
    assert!(!rows.is_empty());

    let (mut drops, _rejects) = match find_build_report(&build) {
        Some(p) => read_build_counts(&p).unwrap(),
        None => Default::default(),
    };
    // Names with LaTeX specials, to see them escaped.
    drops.insert("too_short".to_string(), 2);
    drops.insert("50% overlap & more".to_string(), 1);
    let input = input(&tables, drops);
    let stats = statistics(&rows, &input);
    check_against_pyarrow(&stats, &tables);
    // The demo's captions ("walk, normal style", "wave", ...) give verbs; the tagger lemmatises.
    assert!(stats.text.vocabulary > 5, "{:?}", stats.text);
    assert!(
        stats.text.top_verbs.iter().any(|(v, _)| v == "walk"),
        "{:?}",
        stats.text.top_verbs
    );

    // Order of rows does not matter.
    let mut reversed = rows.clone();
    reversed.reverse();
    assert_eq!(statistics(&reversed, &input), stats);

    let out1 = tmp.path().join("report1");
    let written = write_report(&rows, &stats, &out1).unwrap();
    for name in ["stats.json", "tables.tex", "figures.tex", "report.md"] {
        assert!(written.contains(&out1.join(name)), "{name} not written");
    }
    assert_eq!(written.len(), 4 + 3 * FIGURES.len());
    let out2 = tmp.path().join("report2");
    write_report(&reversed, &statistics(&reversed, &input), &out2).unwrap();
    let (a, b) = (files(&out1), files(&out2));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    let differ: Vec<&PathBuf> = a.keys().filter(|name| a[*name] != b[*name]).collect();
    assert!(differ.is_empty(), "{differ:?} differ between runs");
    assert!(
        !a.keys().any(|k| k.to_string_lossy().contains(".tmp")),
        "temporary files left: {:?}",
        a.keys()
    );

    // stats.json round-trips and holds the counts.
    let json: serde_json::Value = serde_json::from_slice(&a[Path::new("stats.json")]).unwrap();
    assert_eq!(json["overview"]["rows"], rows.len());
    assert_eq!(json["title"], "demo_set & co");

    // Figures: SVGs are XML with the axis labels, PNGs the right size and not blank.
    let svgs: Vec<PathBuf> = FIGURES
        .iter()
        .map(|f| out1.join(format!("figures/{}.svg", f.stem)))
        .collect();
    let pngs: Vec<PathBuf> = FIGURES
        .iter()
        .map(|f| out1.join(format!("figures/{}.png", f.stem)))
        .collect();
    let texts = python(
        PY_SVG,
        &svgs.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
    );
    // Titles in words with their units; the demo's 1 to 3 clips per type on a linear axis.
    let expected_labels: [&[&str]; 5] = [
        &["motion type", "clips"],
        &["motion type", "length (s)"],
        &["lateral (m, + right)", "forward (m)"],
        &["split", "clips"],
        &[
            "foot skating (m/s)",
            "ground penetration (m)",
            "limb-to-spine distance (m)",
            "lean (°)",
            "threshold ≤ 0.4",
            "threshold ≥ 0.03",
        ],
    ];
    for ((svg, labels), spec) in svgs.iter().zip(expected_labels).zip(FIGURES) {
        let t: Vec<String> =
            serde_json::from_value(texts[svg.to_string_lossy().as_ref()].clone()).unwrap();
        for label in labels {
            assert!(
                t.iter().any(|x| x == label),
                "{}: no text {label:?} in {t:?}",
                spec.stem
            );
        }
    }
    let all_texts: Vec<String> = svgs
        .iter()
        .flat_map(|svg| {
            serde_json::from_value::<Vec<String>>(texts[svg.to_string_lossy().as_ref()].clone())
                .unwrap()
        })
        .collect();
    for text in &all_texts {
        assert!(
            !text.contains('_') && !text.contains("<=") && !text.contains(">="),
            "a column name or ASCII bound in a figure: {text:?}"
        );
    }
    assert!(!all_texts.iter().any(|t| t.contains("log scale")));
    // Readable type names on the type figures.
    let type_svg: Vec<String> =
        serde_json::from_value(texts[svgs[0].to_string_lossy().as_ref()].clone()).unwrap();
    for t in &stats.motion_types {
        assert!(
            type_svg
                .iter()
                .any(|x| t.motion_type.starts_with(x.as_str()) && !x.is_empty()),
            "{} not labelled in {type_svg:?}",
            t.motion_type
        );
    }
    let colours = python(
        PY_PNG,
        &pngs.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
    );
    let mut seen = Vec::new();
    for (png, spec) in pngs.iter().zip(FIGURES) {
        let bytes = std::fs::read(png).unwrap();
        assert_eq!(png_size(&bytes), (spec.width, spec.height), "{}", spec.stem);
        // Drawn at its printed width: 3.4 in for a column, 7 in across the page, at 300 dpi.
        let inches = match spec.span {
            Span::Column => 3.4,
            Span::Page => 7.0,
        };
        assert_eq!(
            f64::from(spec.width),
            inches * f64::from(DPI),
            "{}",
            spec.stem
        );
        assert!(
            bytes.len() > 20_000,
            "{}: only {} bytes",
            spec.stem,
            bytes.len()
        );
        let n = colours[png.to_string_lossy().as_ref()].as_u64().unwrap();
        assert!(n > 20, "{}: only {n} colours, looks blank", spec.stem);
        assert!(
            !seen.contains(&bytes),
            "{} repeats another figure",
            spec.stem
        );
        seen.push(bytes);
    }

    // tables.tex: booktabs, escaped names, every table.
    let tex = String::from_utf8(a[Path::new("tables.tex")].clone()).unwrap();
    for needle in [
        "\\toprule",
        "\\midrule",
        "\\bottomrule",
        "too\\_short",
        "50\\% overlap \\& more",
        "llm\\_failed",
        "demo\\_set \\& co",
        "real single",
        "tab:mf-motion-types",
        "tab:mf-composition",
        "tab:mf-plausibility",
        "tab:mf-text",
        "Vocabulary &",
    ] {
        assert!(tex.contains(needle), "tables.tex lacks {needle:?}");
    }
    assert!(!tex.contains("too_short"), "unescaped name in tables.tex");
    for t in &stats.motion_types {
        assert!(tex.contains(&report::latex_escape(&t.motion_type)));
    }
    assert_eq!(
        tex.matches("\\begin{table}").count(),
        tex.matches("\\end{table}").count()
    );

    // tables.tex typesets in a two-column paper without an overfull box.
    compile_two_column(&out1.join("tables.tex"));

    // The type rows in the order of the type figures' bars.
    let md = String::from_utf8(a[Path::new("report.md")].clone()).unwrap();
    let at = |hay: &str, name: &str| hay.find(name).unwrap_or(usize::MAX);
    let table_order = |hay: &str, quote: fn(&str) -> String| {
        let mut names: Vec<&str> = stats
            .motion_types
            .iter()
            .map(|t| t.motion_type.as_str())
            .collect();
        names.sort_by_key(|n| at(hay, &quote(n)));
        names
    };
    let bar_order: Vec<&str> = type_svg
        .iter()
        .filter_map(|x| {
            stats
                .motion_types
                .iter()
                .find(|t| t.motion_type == *x)
                .map(|t| t.motion_type.as_str())
        })
        .collect();
    assert_eq!(bar_order.len(), stats.motion_types.len(), "{type_svg:?}");
    assert_eq!(
        table_order(&md, |n| format!("| {} |", report::markdown_escape(n))),
        bar_order
    );
    assert_eq!(
        table_order(&tex, |n| format!("{} &", report::latex_escape(n))),
        bar_order
    );

    // The figures' PDFs: one page at the printed size, the font embedded.
    for spec in FIGURES {
        let pdf = &a[&PathBuf::from(format!("figures/{}.pdf", spec.stem))];
        assert!(pdf.starts_with(b"%PDF-"), "{}", spec.stem);
        let text = String::from_utf8_lossy(pdf);
        let media: Vec<f64> = text
            .split("/MediaBox [")
            .nth(1)
            .and_then(|t| t.split(']').next())
            .map(|t| t.split_whitespace().map(|v| v.parse().unwrap()).collect())
            .unwrap_or_default();
        let (w, h) = spec.inches();
        assert_eq!(media.len(), 4, "{}: {media:?}", spec.stem);
        assert!(
            (media[2] - w * 72.0).abs() < 0.01 && (media[3] - h * 72.0).abs() < 0.01,
            "{}: page {media:?}, not {w} x {h} in",
            spec.stem
        );
        assert!(
            text.contains("/FontFile2"),
            "{}: font not embedded",
            spec.stem
        );
        assert!(text.contains("DejaVuSans"), "{}", spec.stem);
    }
    // figures.tex: each figure at the width it was drawn for, with its caption and label.
    let figures_tex = String::from_utf8(a[Path::new("figures.tex")].clone()).unwrap();
    for spec in FIGURES {
        let (float, width) = match spec.span {
            Span::Column => ("figure", "\\columnwidth"),
            Span::Page => ("figure*", "\\textwidth"),
        };
        let block = format!(
            "\\begin{{{float}}}[tbp]\n\\centering\n\\includegraphics[width={width}]{{figures/{}.pdf}}\n\\caption{{demo\\_set \\& co: {}.}}\n\\label{{{}}}\n\\end{{{float}}}\n",
            spec.stem, spec.caption, spec.label
        );
        assert!(figures_tex.contains(&block), "no {block} in\n{figures_tex}");
    }
    // Compiled in a two-column paper, the figures' text prints at 7 to 10 pt.
    measure_figure_text(&out1);

    // report.md embeds every figure.
    for f in FIGURES {
        assert!(
            md.contains(&format!("](figures/{}.png)", f.stem)),
            "report.md lacks {}",
            f.stem
        );
        assert!(md.contains(&format!("(figures/{}.svg)", f.stem)));
        assert!(md.contains(&format!("(figures/{}.pdf)", f.stem)));
    }
    assert!(md.contains("too\\_short"));

    // The reference report of docs/report.md: the demo as built, titled by its dataset name.
    if let Ok(keep) = std::env::var("MOTIONFORGE_REPORT_KEEP") {
        let (drops, rejects) = match find_build_report(&build) {
            Some(p) => read_build_counts(&p).unwrap(),
            None => Default::default(),
        };
        let input = ReportInput {
            tables: tables.clone(),
            drops,
            rejects,
            title: "demo".to_string(),
            contradictions: Vec::new(),
        };
        write_report(&rows, &statistics(&rows, &input), Path::new(&keep)).unwrap();
    }
}

/// The motion-length figure's violins: density only within each type's shortest and longest
/// clip, and points instead of a violin below `MIN_VIOLIN` clips.
#[test]
fn violins_stay_within_each_types_data_range() {
    let tmp = tempfile::tempdir().unwrap();
    let build = tmp.path().join("build");
    common::build_demo(&build);
    let rows = read_rows(&clip_tables(&build)).unwrap();
    let by_type = lengths_by_type(&rows);
    assert!(!by_type.is_empty());
    // The demo's types have 1 to 3 original clips each: points, no violin.
    for (name, lengths) in &by_type {
        assert!(lengths.len() < MIN_VIOLIN, "{name}: {lengths:?}");
        assert_eq!(violin_outline(lengths, 0.0), None, "{name}");
    }
    // All lengths together (0.8 s to 23 s of real clips, skewed) do get a violin, inside them.
    let mut all: Vec<f64> = by_type
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .collect();
    all.sort_by(f64::total_cmp);
    assert!(all.len() >= MIN_VIOLIN, "{all:?}");
    let (lo, hi) = (all[0], all[all.len() - 1]);
    let outline = violin_outline(&all, 2.0).expect("a violin");
    for (x, y) in &outline {
        assert!(
            *y >= lo && *y <= hi,
            "violin at {y} s outside the data's {lo}..{hi} s"
        );
        assert!((x - 2.0).abs() <= 0.4 + 1e-12, "{x}");
    }
    // It reaches both ends (clipped, not shrunk).
    let ys: Vec<f64> = outline.iter().map(|p| p.1).collect();
    assert!(ys.contains(&lo) && ys.contains(&hi));
}

/// Compiles `tables` in a two-column article with pdflatex and fails on any overfull box (a table
/// wider than its column). Needs LaTeX: `scripts/test.sh` installs it (`scripts/system-packages.sh`);
/// without it the test fails saying so, rather than passing on a check it did not make.
fn compile_two_column(tables: &Path) {
    assert!(
        Command::new("pdflatex").arg("--version").output().is_ok(),
        "pdflatex is not installed: run the tests through scripts/test.sh, or scripts/system-packages.sh once (texlive-latex-base texlive-latex-recommended)"
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(tables, dir.path().join("tables.tex")).unwrap();
    std::fs::write(
        dir.path().join("paper.tex"),
        "\\documentclass[twocolumn]{article}\n\\usepackage{booktabs}\n\\begin{document}\nText.\n\\input{tables.tex}\n\\end{document}\n",
    )
    .unwrap();
    let out = Command::new("pdflatex")
        .args(["-interaction=nonstopmode", "-halt-on-error", "paper.tex"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let log = std::fs::read_to_string(dir.path().join("paper.log")).unwrap_or_default();
    assert!(out.status.success(), "pdflatex failed:\n{log}");
    assert!(dir.path().join("paper.pdf").is_file());
    let overfull: Vec<&str> = log.lines().filter(|l| l.starts_with("Overfull")).collect();
    assert!(
        overfull.is_empty(),
        "{overfull:#?}\n{}",
        std::fs::read_to_string(tables).unwrap()
    );
}

/// DejaVu Sans, the figures' font, per em (2048 units): digits stand 1493 units tall, lowercase
/// letters without ascenders or descenders 1120.
const DIGIT_HEIGHT_EM: f64 = 1493.0 / 2048.0;
const X_HEIGHT_EM: f64 = 1120.0 / 2048.0;
/// DejaVu Sans' ascender to descender, per em ((1901 + 483) / 2048): the height of the box
/// pdftotext gives an upright word.
const LINE_EM: f64 = 2384.0 / 2048.0;
/// Letters that stand exactly at the x-height (no ascender, descender, dot or accent).
const X_LETTERS: &str = "acemnorsuvwxz";
/// Rasterising resolution of the compiled page, pixels per inch.
const PAGE_DPI: f64 = 400.0;

/// The two-column paper of the figure test: US letter with a 7 in text block and 0.3 in between
/// the columns (a 3.35 in column), as conference templates have; no page numbers, so every
/// number on the page is a figure's.
fn paper(report: &Path, body: &str) -> String {
    format!(
        "\\documentclass[twocolumn]{{article}}\n\\usepackage{{graphicx}}\n\
         \\setlength{{\\textwidth}}{{7in}}\n\\setlength{{\\columnsep}}{{0.3in}}\n\
         \\setlength{{\\oddsidemargin}}{{-0.25in}}\n\\setlength{{\\evensidemargin}}{{-0.25in}}\n\
         \\graphicspath{{{{{}/}}}}\n\\pagestyle{{empty}}\n\\begin{{document}}\n{body}\n\\end{{document}}\n",
        report.display()
    )
}

/// Runs pdflatex on `tex` in `dir`; fails on an error or an overfull box.
fn pdflatex(dir: &Path, tex: &str) -> PathBuf {
    std::fs::write(dir.join("paper.tex"), tex).unwrap();
    let out = Command::new("pdflatex")
        .args(["-interaction=nonstopmode", "-halt-on-error", "paper.tex"])
        .current_dir(dir)
        .output()
        .expect("run pdflatex");
    let log = std::fs::read_to_string(dir.join("paper.log")).unwrap_or_default();
    assert!(out.status.success(), "pdflatex failed:\n{log}\n{tex}");
    let overfull: Vec<&str> = log.lines().filter(|l| l.starts_with("Overfull")).collect();
    assert!(overfull.is_empty(), "{overfull:#?}\n{tex}");
    dir.join("paper.pdf")
}

/// A word pdftotext found: its text, page (from 0) and box in points from the page's top left.
#[derive(Debug)]
struct Word {
    text: String,
    page: usize,
    x: (f64, f64),
    y: (f64, f64),
}

/// Every word of `pdf` with its box (`pdftotext -bbox`).
fn words(pdf: &Path) -> Vec<Word> {
    let html = pdf.with_extension("html");
    let out = Command::new("pdftotext")
        .arg("-bbox")
        .arg(pdf)
        .arg(&html)
        .output()
        .expect("run pdftotext (poppler-utils; scripts/system-packages.sh installs it)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(&html).unwrap();
    let attr = |line: &str, name: &str| -> f64 {
        let start = line.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        let end = start + line[start..].find('"').unwrap();
        line[start..end].parse().unwrap()
    };
    let mut page = 0;
    let mut found = Vec::new();
    for line in html.lines().map(str::trim) {
        if line.starts_with("<page ") {
            page += 1;
        } else if line.starts_with("<word ") {
            let text = &line[line.find('>').unwrap() + 1..line.rfind("</word>").unwrap()];
            found.push(Word {
                text: text
                    .replace("&amp;", "&")
                    .replace("&lt;", "<")
                    .replace("&gt;", ">"),
                page: page - 1,
                x: (attr(line, "xMin"), attr(line, "xMax")),
                y: (attr(line, "yMin"), attr(line, "yMax")),
            });
        }
    }
    found
}

/// The pages of `pdf` rasterised in grey at [`PAGE_DPI`]: (width, height, pixels) each.
fn raster_pages(pdf: &Path) -> Vec<(usize, usize, Vec<u8>)> {
    let dir = pdf.parent().unwrap();
    let out = Command::new("pdftoppm")
        .args(["-gray", "-r", &PAGE_DPI.to_string()])
        .arg(pdf)
        .arg(dir.join("page"))
        .output()
        .expect("run pdftoppm (poppler-utils; scripts/system-packages.sh installs it)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "pgm"))
        .collect();
    files.sort();
    files
        .iter()
        .map(|p| {
            let bytes = std::fs::read(p).unwrap();
            // Binary PGM: "P5", width, height, maxval, one byte per pixel.
            let mut fields = Vec::new();
            let mut at = 0;
            while fields.len() < 4 {
                while bytes[at].is_ascii_whitespace() {
                    at += 1;
                }
                let start = at;
                while !bytes[at].is_ascii_whitespace() {
                    at += 1;
                }
                fields.push(String::from_utf8_lossy(&bytes[start..at]).into_owned());
            }
            assert_eq!(fields[0], "P5", "{}", p.display());
            let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
            let pixels = bytes[at + 1..].to_vec();
            assert_eq!(pixels.len(), w * h, "{}", p.display());
            (w, h, pixels)
        })
        .collect()
}

/// The ink height in points of `word` on its rendered page: the tallest run of rows, within the
/// word's box, that have a dark pixel (black or dark grey text, not the light grid or blue bars).
fn ink_height(page: &(usize, usize, Vec<u8>), word: &Word) -> Option<f64> {
    let (w, h, pixels) = page;
    let px = |pt: f64| (pt * PAGE_DPI / 72.0) as usize;
    let (x0, x1) = (px(word.x.0), (px(word.x.1) + 1).min(*w));
    let (y0, y1) = (px(word.y.0), (px(word.y.1) + 1).min(*h));
    let mut best = 0;
    let mut run = 0;
    for y in y0..y1 {
        if pixels[y * w + x0..y * w + x1].iter().any(|v| *v < 80) {
            run += 1;
            best = best.max(run);
        } else {
            run = 0;
        }
    }
    (best > 0).then(|| f64::from(best) * 72.0 / PAGE_DPI)
}

/// The font size, in points, that `word` is printed at on `page`, from its ink: digits (and a
/// decimal point or minus) over DejaVu's digit height, x-height words over its x-height. `None`
/// for other words.
fn printed_size(page: &(usize, usize, Vec<u8>), word: &Word) -> Option<f64> {
    let t = word.text.as_str();
    let em = if t.chars().any(|c| c.is_ascii_digit())
        && t.chars()
            .all(|c| c.is_ascii_digit() || c == '.' || c == '-')
    {
        DIGIT_HEIGHT_EM
    } else if !t.is_empty() && t.chars().all(|c| X_LETTERS.contains(c)) {
        X_HEIGHT_EM
    } else {
        return None;
    };
    let ink = ink_height(page, word)?;
    // Upright text only: ink and box heights scale together, so their ratio tells a rotated
    // label (whose box is as tall as the word is long) or a line crossing the box from a word
    // that lies straight, whatever the size.
    let ratio = ink / (word.y.1 - word.y.0) / (em / LINE_EM);
    (0.8..1.2).contains(&ratio).then_some(ink / em)
}

/// Each figure of the report in `report` (a written report folder), through its `figures.tex`
/// block, compiled alone in a two-column paper, rasterised: the text of the figure's labels,
/// measured from its ink on the page, is 7 to 10 pt (the figures set 8 and 9 pt). A full page
/// with every figure and body text compiles too (kept as `paper.pdf` in
/// `$MOTIONFORGE_REPORT_KEEP` for `docs/report.md`). Needs pdflatex and poppler-utils
/// (`scripts/system-packages.sh`); fails saying so without them.
fn measure_figure_text(report: &Path) {
    let have = |tool: &str| Command::new(tool).arg("-v").output().is_ok();
    assert!(
        have("pdflatex") && have("pdftoppm") && have("pdftotext"),
        "pdflatex, pdftoppm or pdftotext is missing: run the tests through scripts/test.sh, or scripts/system-packages.sh once (poppler-utils, texlive)"
    );
    let figures_tex = std::fs::read_to_string(report.join("figures.tex")).unwrap();
    let blocks: Vec<&str> = figures_tex
        .split("\\begin{figure")
        .skip(1)
        .map(|b| b.trim())
        .collect();
    assert_eq!(blocks.len(), FIGURES.len(), "{figures_tex}");
    let filler = "The text of a paper runs in two columns around its figures. ".repeat(40);
    for (spec, block) in FIGURES.iter().zip(&blocks) {
        assert!(block.contains(&format!("figures/{}.pdf", spec.stem)));
        let dir = tempfile::tempdir().unwrap();
        let body = format!("{filler}\n\n\\begin{{figure{block}\n\n{filler}");
        let pdf = pdflatex(dir.path(), &paper(report, &body));
        // Words of the caption and body are LaTeX's, not the figure's.
        let latex_words: Vec<&str> = block
            .split_whitespace()
            .chain(filler.split_whitespace())
            .collect();
        let pages = raster_pages(&pdf);
        let candidates: Vec<Word> = words(&pdf)
            .into_iter()
            .filter(|w| !latex_words.contains(&w.text.as_str()))
            .collect();
        let mut sizes: Vec<(String, f64)> = candidates
            .iter()
            .filter_map(|w| printed_size(&pages[w.page], w).map(|s| (w.text.clone(), s)))
            .collect();
        assert!(
            sizes.len() >= 3,
            "{}: only {sizes:?} measured on the page",
            spec.stem
        );
        sizes.sort_by(|a, b| a.1.total_cmp(&b.1));
        eprintln!(
            "{}: {} of {} words measured, {:.2} to {:.2} pt ({} and {} at the ends)",
            spec.stem,
            sizes.len(),
            candidates.len(),
            sizes[0].1,
            sizes[sizes.len() - 1].1,
            sizes[0].0,
            sizes[sizes.len() - 1].0
        );
        for (text, size) in &sizes {
            assert!(
                (7.0..=10.0).contains(size),
                "{}: {text:?} prints at {size:.2} pt, not 7 to 10: {sizes:?}",
                spec.stem
            );
        }
        // The figure is as wide as the paper sets it: a column, or the text block.
        let expected = match spec.span {
            Span::Column => (7.0 - 0.3) / 2.0,
            Span::Page => 7.0,
        };
        assert!(
            (expected / spec.inches().0 - 1.0).abs() < 0.03,
            "{}",
            spec.stem
        );
    }

    // Every figure with body text around them, as a paper would have them.
    let dir = tempfile::tempdir().unwrap();
    let body = format!(
        "{filler}\n\n\\input{{{}/figures.tex}}\n\n{}",
        report.display(),
        filler.repeat(3)
    );
    let pdf = pdflatex(dir.path(), &paper(report, &body));
    let all = words(&pdf);
    assert!(
        all.iter().any(|w| w.text == "lateral"),
        "no figure text on the page"
    );

    // The page of docs/report.md: a figure across the page and one in a column, in the text.
    if let Ok(keep) = std::env::var("MOTIONFORGE_REPORT_KEEP") {
        let block = |stem: &str| {
            let i = FIGURES.iter().position(|f| f.stem == stem).unwrap();
            format!("\\begin{{figure{}", blocks[i])
        };
        let body = format!(
            "{filler}{}\n\n{}\n\n{}\n\n{}",
            &filler[..filler.len() / 4],
            block("plausibility"),
            block("composition"),
            filler.repeat(5)
        );
        let dir = tempfile::tempdir().unwrap();
        let pdf = pdflatex(dir.path(), &paper(report, &body));
        std::fs::create_dir_all(&keep).unwrap();
        std::fs::copy(&pdf, Path::new(&keep).join("paper.pdf")).unwrap();
    }
}

/// A table with a `split` column (added with pyarrow, as the sharded writer will): composition
/// per split, checked against pyarrow.
#[test]
fn split_column_gives_per_split_composition() {
    let tmp = tempfile::tempdir().unwrap();
    let build = tmp.path().join("build");
    common::build_demo(&build);
    let tables = clip_tables(&build);
    let with_split = tmp.path().join("split.parquet");
    let script = r#"
import sys
import pyarrow as pa
import pyarrow.parquet as pq
t = pa.concat_tables([pq.read_table(p) for p in sys.argv[2:]], promote_options="default")
if "split" in t.column_names:
    t = t.drop_columns(["split"])
names = ["train", "val", "test"]
split = [names[i % 3] for i in range(t.num_rows)]
t = t.append_column("split", pa.array(split, pa.string()))
pq.write_table(t, sys.argv[1], compression="zstd")
print("{}")
"#;
    let mut args: Vec<&Path> = vec![&with_split];
    args.extend(tables.iter().map(PathBuf::as_path));
    python(script, &args);
    let rows = read_rows(std::slice::from_ref(&with_split)).unwrap();
    let stats = statistics(
        &rows,
        &input(std::slice::from_ref(&with_split), BTreeMap::new()),
    );
    let splits: Vec<&str> = stats.composition.iter().map(|s| s.split.as_str()).collect();
    assert_eq!(splits, ["train", "val", "test"]);
    assert_eq!(stats.overview.splits, ["train", "val", "test"]);
    check_against_pyarrow(&stats, &[with_split]);
    let total: usize = stats.composition.iter().map(|s| s.total).sum();
    assert_eq!(total, rows.len());
}

fn row(id: &str, kind: &str, mirrored: bool, motion_type: Option<&str>, frames: usize) -> ClipRow {
    ClipRow {
        clip_id: id.to_string(),
        split: NO_SPLIT.to_string(),
        source_kind: kind.to_string(),
        mirrored,
        motion_type: motion_type.map(str::to_string),
        seconds: frames as f64 / 30.0,
        frames,
        goal_pelvis: None,
        label_source: None,
        texts: vec![format!("a person does {id}")],
        plausibility: Some([0.1, 0.0, 0.1, 5.0]),
    }
}

#[test]
fn quartiles_and_groups_on_a_known_input() {
    // Lengths 1, 2, 3, 4 s for "walk" (numpy: Q1 1.75, median 2.5, Q3 3.25); a mirrored copy, a
    // pair and a synthetic clip that the type statistics leave out; one unmapped single.
    let rows = vec![
        row("a", "real_single", false, Some("walk"), 30),
        row("b", "real_single", false, Some("walk"), 60),
        row("c", "real_single", false, Some("walk"), 90),
        row("d", "real_single", false, Some("walk"), 120),
        row("d:m", "real_single", true, Some("walk"), 120),
        row("e", "real_single", false, None, 45),
        row("p", "real_pair", false, None, 300),
        row("s", "synthetic", false, None, 60),
    ];
    let stats = statistics(&rows, &ReportInput::default());
    let names: Vec<&str> = stats
        .motion_types
        .iter()
        .map(|t| t.motion_type.as_str())
        .collect();
    assert_eq!(names, ["walk", UNMAPPED]);
    let walk = &stats.motion_types[0];
    assert_eq!((walk.clips, walk.total_frames), (4, 300));
    let s = walk.seconds.unwrap();
    assert_eq!(
        (s.min, s.q1, s.median, s.q3, s.max),
        (1.0, 1.75, 2.5, 3.25, 4.0)
    );
    assert_eq!(stats.motion_types_total.clips, 5);
    assert_eq!(stats.overview.splits, [NO_SPLIT]);
    let kinds: Vec<(String, usize, usize)> = stats.composition[0]
        .kinds
        .iter()
        .map(|k| (k.source_kind.clone(), k.originals, k.mirrored))
        .collect();
    assert_eq!(
        kinds,
        [
            ("real_single".to_string(), 5, 1),
            ("real_pair".to_string(), 1, 0),
            ("synthetic".to_string(), 1, 0)
        ]
    );
    // Plausibility: 6 real originals, 1 synthetic.
    assert_eq!(stats.plausibility[0].real.unwrap().n, 6);
    assert_eq!(stats.plausibility[0].synthetic.unwrap().n, 1);
    // Original real clips only: the synthetic one is not a label source's.
    assert_eq!(stats.label_sources["(none)"], 6);

    let q = Summary::of(&[3.0, 1.0, 2.0]).unwrap();
    assert_eq!((q.q1, q.median, q.q3), (1.5, 2.0, 2.5));
}

/// The text elements of a figure's SVG (plotters writes each on its own line).
fn svg_texts(report: &Path, stem: &str) -> Vec<String> {
    let svg = std::fs::read_to_string(report.join(format!("figures/{stem}.svg"))).unwrap();
    svg.split("<text")
        .skip(1)
        .filter_map(|t| t.split_once('>'))
        .filter_map(|(_, rest)| rest.split_once("</text>"))
        .map(|(text, _)| text.trim().to_string())
        .collect()
}

/// A few clips per type get a linear count axis from zero; counts spanning more than two
/// decades a log axis. A source kind without rows, or no mirrored copies, get no legend entry
/// (the composition table still lists the kind, with its zeros).
#[test]
fn count_axes_fit_the_counts_and_empty_kinds_have_no_legend() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rows = vec![
        row("a", "real_single", false, Some("walk"), 30),
        row("b", "real_single", false, Some("walk"), 60),
        row("c", "real_single", false, Some("walk"), 90),
        row("d", "real_single", false, Some("kick"), 45),
        row("e", "synthetic", false, None, 45),
    ];
    let small = tmp.path().join("small");
    write_report(&rows, &statistics(&rows, &ReportInput::default()), &small).unwrap();
    let counts = svg_texts(&small, "motion_type_counts");
    assert!(counts.iter().any(|t| t == "clips"), "{counts:?}");
    assert!(!counts.iter().any(|t| t.contains("log")), "{counts:?}");
    // Whole clips from 0: 0, 1, 2, 3.
    for tick in ["0", "1", "2", "3"] {
        assert!(
            counts.iter().any(|t| t == tick),
            "no tick {tick}: {counts:?}"
        );
    }
    assert!(!counts.iter().any(|t| t.contains('.')), "{counts:?}");
    let composition = svg_texts(&small, "composition");
    assert!(
        composition.iter().any(|t| t == "real single"),
        "{composition:?}"
    );
    assert!(
        composition.iter().any(|t| t == "synthetic"),
        "{composition:?}"
    );
    assert!(
        !composition.iter().any(|t| t == "real pair"),
        "{composition:?}"
    );
    assert!(
        !composition.iter().any(|t| t.contains("mirrored")),
        "{composition:?}"
    );
    let tex = std::fs::read_to_string(small.join("tables.tex")).unwrap();
    assert!(tex.contains("real pair"), "the table lists every kind");

    // 300 walks against 2 kicks: a log axis; a mirrored copy gets its legend entry.
    for i in 0..297 {
        rows.push(row(
            &format!("w{i:03}"),
            "real_single",
            false,
            Some("walk"),
            30,
        ));
    }
    rows.push(row("k", "real_single", false, Some("kick"), 45));
    rows.push(row("a-m", "real_single", true, Some("walk"), 30));
    let large = tmp.path().join("large");
    write_report(&rows, &statistics(&rows, &ReportInput::default()), &large).unwrap();
    let counts = svg_texts(&large, "motion_type_counts");
    assert!(
        counts.iter().any(|t| t == "clips (log scale)"),
        "{counts:?}"
    );
    let composition = svg_texts(&large, "composition");
    assert!(
        composition.iter().any(|t| t == "mirrored copies (lighter)"),
        "{composition:?}"
    );
}

#[test]
fn empty_input_still_writes_every_file() {
    let tmp = tempfile::tempdir().unwrap();
    let stats = statistics(&[], &ReportInput::default());
    let written = write_report(&[], &stats, tmp.path()).unwrap();
    assert_eq!(written.len(), 4 + 3 * FIGURES.len());
    for p in &written {
        assert!(std::fs::metadata(p).unwrap().len() > 0, "{}", p.display());
    }
    if let Ok(keep) = std::env::var("MOTIONFORGE_REPORT_KEEP") {
        write_report(&[], &stats, &PathBuf::from(keep).join("empty")).unwrap();
    }
}

/// A LINGO-sized synthetic dataset (40 types, thousands of clips, three splits): every figure
/// renders (long type names rotate) and the output is reproducible.
#[test]
fn large_dataset_renders_every_figure() {
    const TYPES: [&str; 40] = [
        "walk forward",
        "walk back",
        "walk front left",
        "walk front right",
        "walk left",
        "walk right",
        "turn left",
        "turn right",
        "run",
        "jog",
        "sit down",
        "stand up",
        "lie down",
        "get up",
        "pick up",
        "put down",
        "drink",
        "eat",
        "wash",
        "wave",
        "kick",
        "punch",
        "squat",
        "jump",
        "stretch",
        "bow",
        "clap",
        "point",
        "throw",
        "catch",
        "open door",
        "close door",
        "type on keyboard",
        "play guitar",
        "play gamepad",
        "answer cellphone",
        "raise both hands",
        "look around",
        "hold",
        "dance",
    ];
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut rows = Vec::new();
    for i in 0..4000 {
        let t = (next().powi(3) * TYPES.len() as f64) as usize;
        let kind = match next() {
            u if u < 0.7 => "real_single",
            u if u < 0.75 => "real_pair",
            _ => "synthetic",
        };
        let frames = (30.0 * (1.0 + 11.0 * next() * next())) as usize;
        let walk = TYPES[t].starts_with("walk") && kind == "real_single";
        rows.push(ClipRow {
            clip_id: format!("src/{i:05}"),
            split: ["train", "train", "train", "val", "test"][i % 5].to_string(),
            source_kind: kind.to_string(),
            mirrored: i % 2 == 1 && kind != "synthetic",
            motion_type: (kind == "real_single" && t < 38).then(|| TYPES[t].to_string()),
            seconds: frames as f64 / 30.0,
            frames,
            goal_pelvis: walk.then(|| [(next() * 6.0 - 3.0) as f32, (next() * 8.0 - 1.0) as f32]),
            label_source: Some(
                if next() < 0.9 {
                    "embedded:lexicon"
                } else {
                    "llm:gemma"
                }
                .to_string(),
            ),
            texts: vec!["a person walks forward and waves".to_string()],
            plausibility: Some([
                (next() * 0.1) as f32,
                (next() * 0.01) as f32,
                (0.05 + next() * 0.1) as f32,
                (next() * 20.0) as f32,
            ]),
        });
    }
    let input = ReportInput {
        title: "synthetic LINGO-sized set".to_string(),
        ..ReportInput::default()
    };
    let stats = statistics(&rows, &input);
    assert_eq!(stats.motion_types.len(), 39);
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    write_report(&rows, &stats, &a).unwrap();
    write_report(&rows, &stats, &b).unwrap();
    let (fa, fb) = (files(&a), files(&b));
    assert_eq!(fa, fb);
    for f in FIGURES {
        let png = &fa[&PathBuf::from(format!("figures/{}.png", f.stem))];
        assert_eq!(png_size(png), (f.width, f.height));
    }
    if let Ok(keep) = std::env::var("MOTIONFORGE_REPORT_KEEP") {
        let keep = PathBuf::from(keep).join("large");
        for (name, bytes) in &fa {
            let p = keep.join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, bytes).unwrap();
        }
    }
}
