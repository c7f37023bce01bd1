//! Human-readable output of builds, plans and status.

use motionforge::build::BuildReport;
use std::io::Write;

/// `name n, name n`, or `none`: counts by name (a `BTreeMap` by string or a `Tally` by kind).
pub(crate) fn counts<N, C>(map: impl IntoIterator<Item = (N, C)>) -> String
where
    N: std::fmt::Display,
    C: std::borrow::Borrow<usize>,
{
    let listed: Vec<String> = map
        .into_iter()
        .map(|(k, n)| format!("{k} {}", n.borrow()))
        .collect();
    if listed.is_empty() {
        return "none".to_string();
    }
    listed.join(", ")
}

/// `why (n); why (n)`.
pub(crate) fn reasons<N, C>(map: impl IntoIterator<Item = (N, C)>) -> String
where
    N: std::fmt::Display,
    C: std::borrow::Borrow<usize>,
{
    map.into_iter()
        .map(|(why, n)| format!("{why} ({})", n.borrow()))
        .collect::<Vec<_>>()
        .join("; ")
}

/// `7 accepted, 2 rejected (off_list 2): 2 fell back to the embedded labeller, 1 cut off`, or
/// nothing when no answer was checked.
fn checks_line(c: &motionforge::stages::augment::AnswerChecks, fallback: &str) -> Option<String> {
    if c.accepted == 0 && c.rejected() == 0 && c.truncated == 0 {
        return None;
    }
    let mut line = format!("{} accepted, {} rejected", c.accepted, c.rejected());
    if c.rejected() > 0 {
        line.push_str(&format!(" ({})", counts(&c.rejected_by_reason)));
        let mut done = Vec::new();
        if c.fell_back > 0 {
            done.push(format!("{} fell back to {fallback}", c.fell_back));
        }
        if c.dropped > 0 {
            done.push(format!("{} dropped", c.dropped));
        }
        if c.kept > 0 {
            done.push(format!("{} kept anyway", c.kept));
        }
        line.push_str(&format!(": {}", done.join(", ")));
    }
    if c.truncated > 0 {
        line.push_str(&format!(
            "; {} cut off by max_tokens (not cached)",
            c.truncated
        ));
    }
    Some(line)
}

pub(crate) fn print_plan(plan: &motionforge::build::Plan) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "plan for {} ({}):",
        plan.dataset,
        plan.output.display()
    )?;
    for stage in &plan.stages {
        if !stage.enabled {
            writeln!(out, "{:>11}  off", stage.stage.name())?;
        } else if stage.fresh() && stage.items == 0 {
            writeln!(out, "{:>11}  nothing to do", stage.stage.name())?;
        } else if stage.fresh() {
            writeln!(
                out,
                "{:>11}  up to date ({} items)",
                stage.stage.name(),
                stage.items
            )?;
        } else if stage.items == 0 {
            // Behind a stale stage: its items are not known until that stage has run (a count
            // of 1 here read as one item where the build then ran ten).
            writeln!(
                out,
                "{:>11}  all to run: {}",
                stage.stage.name(),
                stage
                    .reasons
                    .keys()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            )?;
        } else {
            writeln!(
                out,
                "{:>11}  {} of {} to run: {}",
                stage.stage.name(),
                stage.to_run,
                stage.items.max(stage.to_run),
                reasons(&stage.reasons)
            )?;
            for example in &stage.examples {
                writeln!(out, "{:>11}    {example}", "")?;
            }
        }
    }
    if plan.nothing_to_run() {
        match plan.stages.last().map(|s| s.stage) {
            // `--through`: the stages after it are not planned, and may well have work to do.
            Some(last) if last != motionforge::build::Stage::Report => writeln!(
                out,
                "nothing to run through {last}: `run {last}` would reuse everything (the stages after it are not planned)"
            )?,
            _ => writeln!(out, "nothing to run: a build would reuse everything")?,
        }
    }
    Ok(())
}

/// `YYYY-MM-DD HH:MM UTC` of Unix seconds (days to civil date as in Howard Hinnant's algorithm).
pub(crate) fn utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02} UTC",
        rem / 3_600,
        (rem % 3_600) / 60
    )
}

pub(crate) fn print_status(status: &motionforge::build::Status) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    let rows = if status.splits.is_empty() {
        "not written yet".to_string()
    } else {
        status
            .splits
            .iter()
            .map(|(split, n)| format!("{split} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    writeln!(
        out,
        "{} ({}): {rows}",
        status.dataset,
        status.output.display()
    )?;
    writeln!(
        out,
        "{:>11}  {:<6} {:<21} {:>6} {:>6} {:>6}",
        "stage", "state", "last run", "items", "ran", "reused"
    )?;
    for s in &status.stages {
        let last = s.last_run.map_or_else(|| "never".to_string(), utc);
        writeln!(
            out,
            "{:>11}  {:<6} {:<21} {:>6} {:>6} {:>6}",
            s.stage.name(),
            if !s.enabled {
                "off"
            } else if s.fresh {
                "fresh"
            } else {
                "stale"
            },
            last,
            s.items,
            s.ran,
            s.reused
        )?;
        if !s.fresh {
            writeln!(
                out,
                "{:>11}    {} to run: {}",
                "",
                s.to_run,
                reasons(&s.reasons)
            )?;
        }
    }
    Ok(())
}

/// Why a text stage answered nothing, when it skipped every text (no LLM configured, offline).
fn skipped_stage(report: &BuildReport, stage: &str) -> Option<String> {
    use motionforge::build::Stage;
    let r = if stage == Stage::Paraphrase.name() {
        &report.paraphrases
    } else if stage == Stage::Plan.name() {
        &report.plans
    } else if stage == Stage::PairCheck.name() {
        &report.pair_check
    } else {
        return None;
    };
    (r.answered == 0 && !r.skipped.is_empty())
        .then(|| r.skipped.keys().cloned().collect::<Vec<_>>().join(", "))
}

/// Rows per split of the dataset a build wrote, in split order (train, validation, test,
/// others), from its manifest; `None` before the first write.
fn split_rows(report: &BuildReport) -> Option<String> {
    let manifest = motionforge::io::manifest::Manifest::read(&report.output).ok()??;
    let rows: std::collections::BTreeMap<motionforge::clip::Split, usize> = manifest
        .splits
        .iter()
        .map(|(k, v)| (motionforge::clip::Split::new(k.as_str()), v.rows))
        .collect();
    Some(
        rows.iter()
            .map(|(k, n)| format!("{k} {n}"))
            .collect::<Vec<_>>()
            .join(", "),
    )
}

/// Per profile, which split its normalisation statistics come from and its constant dimensions
/// (a trainer dividing by their floored std would blow up noise).
fn print_normalization(out: &mut impl Write, report: &BuildReport) -> std::io::Result<()> {
    let dir = report.output.join(motionforge::build::NORMALIZATION_DIR);
    let Some(profiles) = motionforge::io::normalization::read_summary(&dir) else {
        return Ok(());
    };
    for (profile, p) in &profiles {
        let constant: Vec<String> = p
            .constant
            .iter()
            .map(|(feature, dims)| {
                let of = p.dimensions.get(feature).copied().unwrap_or_default();
                format!("{feature} {} of {of} ({})", dims.len(), dims.join(", "))
            })
            .collect();
        let constant = if constant.is_empty() {
            "none".to_string()
        } else {
            constant.join("; ")
        };
        writeln!(
            out,
            "normalisation {profile}: over {} ({} frames); constant dimensions: {constant}",
            p.split, p.frames
        )?;
    }
    Ok(())
}

/// The build's one summary on standard output: stages, rows per split, counts, rejects.
pub(crate) fn print_report(report: &BuildReport, seconds: f64) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    for stage in &report.stages {
        let what = if let Some(why) = skipped_stage(report, &stage.stage) {
            format!("skipped ({why})")
        } else if stage.items == 0 {
            // A stage with nothing to work on (no compatible pairs, say) did not find its work
            // done: it had none, on a new folder too.
            "nothing to do".to_string()
        } else if stage.ran == 0 {
            "up to date, nothing re-run".to_string()
        } else {
            format!(
                "ran {} of {} ({} reused)",
                stage.ran, stage.items, stage.reused
            )
        };
        writeln!(out, "{:>11}  {what}", stage.stage)?;
    }
    let ran =
        |stage: motionforge::build::Stage| report.stages.iter().any(|s| s.stage == stage.name());
    let wrote = ran(motionforge::build::Stage::Write);
    if wrote {
        writeln!(
            out,
            "{} captures -> {} clips ({} mirrored) in {}/ ({seconds:.1} s)",
            report.captures,
            report.clips,
            report.mirrored,
            report.output.join(motionforge::build::DATA_DIR).display()
        )?;
    } else {
        // `run <stage>` before the write stage: the clips exist in the stage cache only.
        writeln!(
            out,
            "{} captures -> {} clips ({} mirrored), not written: the run stopped before `write` ({seconds:.1} s)",
            report.captures, report.clips, report.mirrored,
        )?;
    }
    if let Some(splits) = split_rows(report).filter(|_| wrote) {
        writeln!(out, "splits: {splits}")?;
    }
    if wrote {
        print_normalization(&mut out, report)?;
    }
    writeln!(out, "by kind: {}", counts(&report.kinds))?;
    writeln!(
        out,
        "motion types (originals): {}",
        counts(&report.motion_types)
    )?;
    if !report.unmapped_labels.is_empty() {
        writeln!(
            out,
            "labels with no motion type: {}",
            counts(&report.unmapped_labels)
        )?;
    }
    writeln!(out, "dropped segments: {}", counts(&report.drops_by_reason))?;
    if !report.clips_by_effective_rate.is_empty() {
        let total: usize = report.clips_by_effective_rate.values().sum();
        writeln!(
            out,
            "clips really at another rate than labelled: {total} (by fps: {})",
            counts(&report.clips_by_effective_rate)
        )?;
    }
    if !report.notes_by_kind.is_empty() {
        writeln!(out, "annotation notes: {}", counts(&report.notes_by_kind))?;
    }
    if ran(motionforge::build::Stage::Label) {
        print_labels(&mut out, report)?;
        if ran(motionforge::build::Stage::Compose) {
            print_synthetic(&mut out, report)?;
        }
    }
    print_tail(&mut out, report)
}

/// The summary's lines on part labels, paraphrases and task plans.
fn print_labels(out: &mut impl Write, report: &BuildReport) -> std::io::Result<()> {
    let l = &report.labels;
    writeln!(
        out,
        "part labels: {} ({} texts, {} requests, {} cache hits, {} flagged)",
        counts(&l.sources),
        l.texts,
        l.requests,
        l.cache_hits,
        l.flagged.len()
    )?;
    if let Some(line) = checks_line(&l.checks, "the embedded labeller") {
        writeln!(out, "  LLM answers: {line}")?;
    }
    if let Some((agreement, n)) = l.velocity_agreement {
        writeln!(
            out,
            "  motion velocity agrees with the lexicon on {:.0}% of parts ({n} clips)",
            agreement * 100.0
        )?;
    }
    for (name, r) in [
        ("paraphrases", &report.paraphrases),
        ("task plans", &report.plans),
    ] {
        let skipped = if r.skipped.is_empty() {
            String::new()
        } else {
            format!("; skipped: {}", counts(&r.skipped))
        };
        writeln!(
            out,
            "{name}: {} of {} texts answered, {} requests, {} rejected{skipped}",
            r.answered,
            r.texts,
            r.requests,
            r.rejected.len()
        )?;
        if let Some(line) = checks_line(&r.checks, "nothing") {
            writeln!(out, "  checks: {line}")?;
        }
    }
    Ok(())
}

/// The summary's lines on synthetic pairs, labels the motion contradicts and the pair check.
fn print_synthetic(out: &mut impl Write, report: &BuildReport) -> std::io::Result<()> {
    let c = &report.synthetic;
    writeln!(
        out,
        "synthetic pairs: {} candidates, {} compatible pairs, {} sampled, {} composed, dropped: {}",
        c.candidates,
        c.compatible,
        c.sampled,
        c.composed,
        counts(&c.dropped)
    )?;
    if !report.label_contradictions.is_empty() {
        let left_out = report.label_contradictions_dropped;
        writeln!(
            out,
            "labels contradicting the motion: {} (listed in build-report.json){}",
            report.label_contradictions.len(),
            if left_out > 0 {
                format!("; {left_out} rows left out (label_check.drop)")
            } else {
                String::new()
            }
        )?;
        for c in report.label_contradictions.iter().take(10) {
            writeln!(out, "  {}: says {}, {}", c.clip_id, c.claim, c.motion)?;
        }
    }
    let pc = &report.pair_check;
    if pc.texts > 0 {
        writeln!(
            out,
            "pair check (LLM): {} of {} pairs answered, {} requests{}",
            pc.answered,
            pc.texts,
            pc.requests,
            if pc.skipped.is_empty() {
                String::new()
            } else {
                format!("; skipped: {}", counts(&pc.skipped))
            }
        )?;
    }
    Ok(())
}

/// The summary's last lines: rejects, and whether anything changed.
fn print_tail(out: &mut impl Write, report: &BuildReport) -> std::io::Result<()> {
    if report.rejects.is_empty() {
        writeln!(out, "rejects: none")?;
    } else {
        writeln!(
            out,
            "rejects: {} ({}), listed in {}:",
            report.rejects.len(),
            counts(&report.rejects_by_reason),
            report
                .output
                .join(motionforge::build::REJECTS_FILE)
                .display()
        )?;
        for r in report.rejects.iter().take(10) {
            writeln!(out, "  {r}")?;
        }
    }
    if report.nothing_ran() {
        writeln!(out, "nothing changed since the last build")?;
    }
    Ok(())
}
