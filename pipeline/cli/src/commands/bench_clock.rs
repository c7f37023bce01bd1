//! Timing a build stage by stage for `bench --build` and `bench --amass`: the stage events the
//! build reports through its `ProgressSink`, each marked with the wall clock, the process's CPU
//! time and its peak memory, then cut into phases (stages and the gaps between them).

use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::Result;
use motionforge::build::{BuildOptions, BuildReport, build};
use motionforge::progress::{Progress, ProgressSink};

use super::bench::peak_rss_kb;
use super::bench_machine::{
    CpuSnapshot, CpuUse, clock_ticks_per_second, own_cpu_ticks, reset_peak_rss, rss_kb,
};
use crate::ui::Ui;

// ---- timing a build --------------------------------------------------------------------------

/// A stage event as the build reports it.
#[derive(Debug, Clone)]
enum Event {
    Started(String),
    Finished {
        stage: String,
        ran: u64,
        reused: u64,
    },
}

/// A moment of a build: when, the process's CPU time then, and its peak memory since the
/// previous mark.
#[derive(Debug, Clone, Copy)]
struct Mark {
    at: Instant,
    cpu_ticks: u64,
    peak_kb: Option<u64>,
}

impl Mark {
    /// Now; the peak memory is then reset, so the next mark's covers the stretch in between.
    fn now() -> Mark {
        let mark = Mark {
            at: Instant::now(),
            cpu_ticks: own_cpu_ticks(),
            peak_kb: peak_rss_kb(),
        };
        reset_peak_rss();
        mark
    }
}

/// Records when each stage starts and finishes (with CPU time and peak memory), and passes every
/// call on to the terminal's progress.
struct StageClock {
    inner: ProgressSink,
    events: Mutex<Vec<(Mark, Event)>>,
}

impl StageClock {
    fn record(&self, event: Event) {
        let mark = Mark::now();
        self.events
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((mark, event));
    }
}

impl Progress for StageClock {
    fn stage_started(&self, stage: &str, total: u64) {
        self.record(Event::Started(stage.to_string()));
        self.inner.stage_started(stage, total);
    }

    fn advanced(&self, stage: &str, n: u64) {
        self.inner.advanced(stage, n);
    }

    fn stage_finished(&self, stage: &str, ran: u64, reused: u64) {
        self.record(Event::Finished {
            stage: stage.to_string(),
            ran,
            reused,
        });
        self.inner.stage_finished(stage, ran, reused);
    }

    fn note(&self, message: &str) {
        self.inner.note(message);
    }
}

/// One stretch of a build's wall time: a stage (or stages reported as one), or the time between
/// stages that no stage reports (`gap`).
#[derive(Debug, Clone)]
pub(super) struct Phase {
    pub(super) name: String,
    pub(super) gap: bool,
    pub(super) seconds: f64,
    /// Process CPU seconds over the stretch (all threads).
    pub(super) cpu_seconds: f64,
    /// Peak resident memory of the process during the stretch.
    pub(super) peak_kb: Option<u64>,
    pub(super) ran: u64,
    pub(super) reused: u64,
}

/// A timed build: its stretches, total, peak memory and the machine's CPU use meanwhile.
pub(super) struct BuildRun {
    pub(super) phases: Vec<Phase>,
    pub(super) total: f64,
    /// The highest of the stretches' peaks.
    pub(super) peak_rss_kb: Option<u64>,
    /// Resident memory when the build started.
    pub(super) start_rss_kb: Option<u64>,
    pub(super) cpu: CpuUse,
    /// The process's CPU seconds over the build (user + system, all threads).
    pub(super) cpu_seconds: f64,
}

/// A timed call that reports no stages (plan).
pub(super) struct Timed {
    pub(super) seconds: f64,
    pub(super) peak_rss_kb: Option<u64>,
    pub(super) start_rss_kb: Option<u64>,
    pub(super) cpu: CpuUse,
}

pub(super) fn timed_build(
    config: &motionforge::config::Config,
    ui: &Ui,
) -> Result<(BuildRun, BuildReport)> {
    let clock = Arc::new(StageClock {
        inner: ui.progress(),
        events: Mutex::new(Vec::new()),
    });
    let options = BuildOptions {
        progress: ProgressSink::new(clock.clone()),
        ..BuildOptions::default()
    };
    let start_rss_kb = rss_kb();
    let cpu = CpuSnapshot::now();
    let start = Mark::now();
    let report = build(config, &options)?;
    let end = Mark::now();
    let cpu = cpu.since();
    ui.clear_bars();
    let events = std::mem::take(&mut *clock.events.lock().unwrap_or_else(|e| e.into_inner()));
    let phases = phases(start, end, &events);
    Ok((
        BuildRun {
            peak_rss_kb: phases.iter().filter_map(|p| p.peak_kb).max(),
            phases,
            total: end.at.duration_since(start.at).as_secs_f64(),
            start_rss_kb,
            cpu,
            cpu_seconds: end.cpu_ticks.saturating_sub(start.cpu_ticks) as f64
                / clock_ticks_per_second(),
        },
        report,
    ))
}

/// Cuts a build's wall time into stretches. A stage runs from its start event, or from the
/// previous event when it reports none, to its finish event; time before a start event that no
/// stage covers is a gap named after the stage it precedes. A stage finishing at the very moment
/// the previous one did, without a start of its own, ran inside that one's pass (segment inside
/// ingest's per-capture pass, paraphrase and plan inside the text pass): they share a row.
fn phases(start: Mark, end: Mark, events: &[(Mark, Event)]) -> Vec<Phase> {
    const SAME_MOMENT: f64 = 1e-3;
    let ticks = clock_ticks_per_second();
    // Stages do not overlap, so every stretch runs from the previous mark to its own.
    let stretch = |name: String, gap: bool, from: &Mark, to: &Mark, ran: u64, reused: u64| Phase {
        name,
        gap,
        seconds: to.at.duration_since(from.at).as_secs_f64(),
        cpu_seconds: to.cpu_ticks.saturating_sub(from.cpu_ticks) as f64 / ticks,
        peak_kb: to.peak_kb,
        ran,
        reused,
    };
    let mut phases: Vec<Phase> = Vec::new();
    let mut cursor = start;
    let mut last_was_finish = false;
    for (mark, event) in events {
        match event {
            Event::Started(stage) => {
                phases.push(stretch(
                    format!("(before {stage})"),
                    true,
                    &cursor,
                    mark,
                    0,
                    0,
                ));
                last_was_finish = false;
            }
            Event::Finished { stage, ran, reused } => {
                let phase = stretch(stage.clone(), false, &cursor, mark, *ran, *reused);
                match phases.last_mut() {
                    Some(prev) if last_was_finish && !prev.gap && phase.seconds < SAME_MOMENT => {
                        prev.name = format!("{} + {stage}", prev.name);
                        prev.ran += phase.ran;
                        prev.reused += phase.reused;
                        prev.seconds += phase.seconds;
                        prev.cpu_seconds += phase.cpu_seconds;
                        prev.peak_kb = prev.peak_kb.max(phase.peak_kb);
                    }
                    _ => phases.push(phase),
                }
                last_was_finish = true;
            }
        }
        cursor = *mark;
    }
    phases.push(stretch(
        "(after the last stage)".into(),
        true,
        &cursor,
        &end,
        0,
        0,
    ));
    phases
}
