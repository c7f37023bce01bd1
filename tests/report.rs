//! The statistics report: counts checked against an independent reader (pyarrow), quartiles on
//! known inputs, every figure and table written, and byte-identical output for the same rows.
//!
//! Set `MOTIONFORGE_REPORT_KEEP=<dir>` to keep the demo report there for inspection.

use crate::common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use motionforge::report::{
    self, ClipRow, FIGURES, MIN_VIOLIN, NO_SPLIT, ReportInput, Stats, Summary, UNMAPPED,
    find_clip_tables, lengths_by_type, read_build_counts, read_rows, statistics, violin_outline,
    write_report,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the crate is in a folder of the repository")
        .to_path_buf()
}

/// Builds the demo into `dir` with the binary, as a user would.
fn build_demo(dir: &Path) {
    let out = Command::new(env!("CARGO_BIN_EXE_motionforge"))
        .args(["build", "--config"])
        .arg(repo().join("fixtures/demo.toml"))
        .arg("--output")
        .arg(dir)
        .output()
        .expect("run motionforge");
    assert!(
        out.status.success(),
        "demo build failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

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
    build_demo(&build);
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
    for name in ["stats.json", "tables.tex", "report.md"] {
        assert!(written.contains(&out1.join(name)), "{name} not written");
    }
    assert_eq!(written.len(), 3 + 2 * FIGURES.len());
    let out2 = tmp.path().join("report2");
    write_report(&reversed, &statistics(&reversed, &input), &out2).unwrap();
    let (a, b) = (files(&out1), files(&out2));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        assert!(bytes == &b[name], "{} differs between runs", name.display());
    }
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
    let expected_labels: [&[&str]; 5] = [
        &["motion type", "clips (log scale)"],
        &["motion type", "motion length (s)"],
        &["lateral (m, + right)", "forward (m)"],
        &["split", "clips (rows)"],
        &["foot skating (m/s)", "lean (°)", "ground penetration (m)"],
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

    // report.md embeds every figure.
    let md = String::from_utf8(a[Path::new("report.md")].clone()).unwrap();
    for f in FIGURES {
        assert!(
            md.contains(&format!("](figures/{}.png)", f.stem)),
            "report.md lacks {}",
            f.stem
        );
        assert!(md.contains(&format!("(figures/{}.svg)", f.stem)));
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
    build_demo(&build);
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
/// wider than its column). Where LaTeX is not installed (scripts/test.sh installs it from Debian
/// packages when run as root) it says so on standard error and checks nothing more.
fn compile_two_column(tables: &Path) {
    if Command::new("pdflatex").arg("--version").output().is_err() {
        eprintln!(
            "SKIPPED: tables.tex two-column compile: pdflatex is not installed (apt-get install texlive-latex-base texlive-latex-recommended)"
        );
        return;
    }
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

/// A table with a `split` column (added with pyarrow, as the sharded writer will): composition
/// per split, checked against pyarrow.
#[test]
fn split_column_gives_per_split_composition() {
    let tmp = tempfile::tempdir().unwrap();
    let build = tmp.path().join("build");
    build_demo(&build);
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

#[test]
fn empty_input_still_writes_every_file() {
    let tmp = tempfile::tempdir().unwrap();
    let stats = statistics(&[], &ReportInput::default());
    let written = write_report(&[], &stats, tmp.path()).unwrap();
    assert_eq!(written.len(), 3 + 2 * FIGURES.len());
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
