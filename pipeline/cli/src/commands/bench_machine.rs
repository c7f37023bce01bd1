//! Readings of the machine and the process that the benches print: peak and current resident
//! memory, load average, CPU time of the process, of a thread and of the whole machine, and the
//! sizes of folders and shards written.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};

/// Resets the process's peak resident memory to its current size (Linux `5 > clear_refs`), so
/// the next `VmHWM` reading covers what follows; silently does nothing where unsupported.
pub(super) fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Resident memory of this process now in kB (Linux `VmRSS`), if readable.
pub(super) fn rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

/// The 1, 5 and 15 minute load averages (`/proc/loadavg`), as written.
pub(super) fn load_average() -> Option<String> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    Some(
        text.split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" "),
    )
}

/// This process's CPU time (user + system, all threads) in clock ticks; 0 where unreadable.
pub(super) fn own_cpu_ticks() -> u64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0;
    };
    // Fields after the command name (which may hold spaces): state is field 3, utime 14, stime 15.
    let Some((_, rest)) = stat.rsplit_once(')') else {
        return 0;
    };
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let field = |n: usize| {
        fields
            .get(n - 3)
            .and_then(|f| f.parse::<u64>().ok())
            .unwrap_or(0)
    };
    field(14) + field(15)
}

/// This thread's CPU time in seconds (user + system); 0 where unreadable.
pub(super) fn thread_cpu_seconds() -> f64 {
    let mut now = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec, which lives on this stack frame.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) } == 0;
    if ok {
        now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9
    } else {
        0.0
    }
}

/// Clock ticks per second of `/proc` times.
pub(super) fn clock_ticks_per_second() -> f64 {
    // SAFETY: sysconf reads a constant of the running system; no memory is passed.
    let ticks = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if ticks > 0 { ticks as f64 } else { 100.0 }
}

/// The machine's busy and total CPU ticks (`/proc/stat`) and this process's own, at a moment.
pub(super) struct CpuSnapshot {
    pub(super) busy: u64,
    pub(super) total: u64,
    pub(super) own: u64,
}

/// CPU use over a stretch: this process's, and everything else's, as shares of all CPUs.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct CpuUse {
    pub(super) own: f64,
    pub(super) others: f64,
}

impl CpuSnapshot {
    pub(super) fn now() -> CpuSnapshot {
        let (busy, total) = std::fs::read_to_string("/proc/stat")
            .ok()
            .and_then(|text| {
                let line = text.lines().next()?;
                let values: Vec<u64> = line
                    .split_whitespace()
                    .skip(1)
                    .filter_map(|v| v.parse().ok())
                    .collect();
                // user nice system idle iowait irq softirq steal (guest time is inside user).
                let total: u64 = values.iter().take(8).sum();
                let idle =
                    values.get(3).copied().unwrap_or(0) + values.get(4).copied().unwrap_or(0);
                Some((total.saturating_sub(idle), total))
            })
            .unwrap_or((0, 0));
        CpuSnapshot {
            busy,
            total,
            own: own_cpu_ticks(),
        }
    }

    /// The CPU use from this snapshot to now.
    pub(super) fn since(&self) -> CpuUse {
        let now = CpuSnapshot::now();
        let total = now.total.saturating_sub(self.total);
        if total == 0 {
            return CpuUse::default();
        }
        let busy = now.busy.saturating_sub(self.busy);
        let own = now.own.saturating_sub(self.own).min(busy);
        CpuUse {
            own: own as f64 / total as f64,
            others: (busy - own) as f64 / total as f64,
        }
    }
}

/// Bytes of the files under each sub-folder of `dir` (a stage's cache folder), recursively.
pub(super) fn folder_sizes(dir: &Path) -> Result<BTreeMap<String, u64>> {
    let mut sizes = BTreeMap::new();
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?;
    for entry in entries {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        sizes.insert(name, tree_bytes(&entry.path())?);
    }
    Ok(sizes)
}

pub(super) fn tree_bytes(path: &Path) -> Result<u64> {
    let meta = std::fs::symlink_metadata(path)?;
    if !meta.is_dir() {
        return Ok(meta.len());
    }
    let mut bytes = 0;
    for entry in std::fs::read_dir(path)? {
        bytes += tree_bytes(&entry?.path())?;
    }
    Ok(bytes)
}

/// Bytes of every `*.parquet` shard in the dataset's data folder.
pub(super) fn shard_sizes(dir: &Path) -> Result<Vec<u64>> {
    let mut sizes = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let path = entry?.path();
        if path.extension().is_some_and(|x| x == "parquet") {
            sizes.push(std::fs::metadata(&path)?.len());
        }
    }
    Ok(sizes)
}
