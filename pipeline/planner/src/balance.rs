//! What a built dataset already holds (clips and lengths per motion type, read through the
//! report's readers), the balance factor that steers the chain toward the target, and the
//! distance of a distribution to the target.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use motionforge_report::{ReportError, ReportInput, find_clip_tables, read_rows, statistics};

/// Clips and median length per motion type of a built dataset: original real single clips, as
/// the report counts them (mirrored copies and pairs are not counted).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DatasetCounts {
    /// The dataset folder read, if any.
    pub dataset: Option<PathBuf>,
    /// Clips per motion type (unmapped labels left out).
    pub clips: BTreeMap<String, u64>,
    /// Median clip length in seconds per motion type.
    pub median_seconds: BTreeMap<String, f64>,
}

impl DatasetCounts {
    /// Reads a built dataset folder's shards (`<dataset>/data`) with the report's readers.
    pub fn read(dataset: &Path) -> Result<DatasetCounts, ReportError> {
        let data = dataset.join(motionforge_core::base::layout::DATA_DIR);
        let tables = find_clip_tables(&data)?;
        if tables.is_empty() {
            return Err(ReportError::Io {
                path: data,
                source: std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "no clip tables (.parquet with a clip_id column): expected a built dataset \
                     folder (<output>/<name>)",
                ),
            });
        }
        let rows = read_rows(&tables)?;
        let stats = statistics(
            &rows,
            &ReportInput {
                tables,
                ..ReportInput::default()
            },
        );
        let mut counts = DatasetCounts {
            dataset: Some(dataset.to_path_buf()),
            ..DatasetCounts::default()
        };
        for t in stats.motion_types {
            if t.motion_type == motionforge_report::UNMAPPED {
                continue;
            }
            if let Some(s) = &t.seconds
                && s.median.is_finite()
                && s.median > 0.0
            {
                counts
                    .median_seconds
                    .insert(t.motion_type.clone(), s.median);
            }
            counts.clips.insert(t.motion_type, t.clips as u64);
        }
        Ok(counts)
    }
}

/// The balance factor of each target type given the counts so far (dataset plus session):
/// `(q_t / p_t)^strength` with `p_t = (n_t + 1) / (N + |T|)`, the smoothed share of type `t`
/// among the target's types. Types outside the target are not in the map (the chain gives them
/// the smallest factor of the target's types).
pub fn factors(
    target: &BTreeMap<String, f64>,
    counts: &BTreeMap<String, u64>,
    strength: f64,
) -> BTreeMap<String, f64> {
    let n: u64 = target
        .keys()
        .map(|t| counts.get(t).copied().unwrap_or(0))
        .sum();
    let denominator = n as f64 + target.len() as f64;
    target
        .iter()
        .map(|(t, q)| {
            let share = (counts.get(t).copied().unwrap_or(0) as f64 + 1.0) / denominator;
            (t.clone(), (q / share).powf(strength))
        })
        .collect()
}

/// Kullback-Leibler divergence `KL(p || q)` in nats of the counts' distribution over the target's
/// types (`p`) from the target (`q`); `None` when the counts hold none of the target's types.
pub fn kl_to_target(counts: &BTreeMap<String, u64>, target: &BTreeMap<String, f64>) -> Option<f64> {
    let n: u64 = target
        .keys()
        .map(|t| counts.get(t).copied().unwrap_or(0))
        .sum();
    if n == 0 {
        return None;
    }
    let mut kl = 0.0;
    for (t, q) in target {
        let c = counts.get(t).copied().unwrap_or(0);
        if c > 0 {
            let p = c as f64 / n as f64;
            kl += p * (p / q).ln();
        }
    }
    Some(kl)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kl_is_zero_on_the_target_and_grows_away_from_it() {
        let target: BTreeMap<String, f64> = [("a".to_string(), 0.5), ("b".to_string(), 0.5)].into();
        let even: BTreeMap<String, u64> = [("a".to_string(), 3), ("b".to_string(), 3)].into();
        let skew: BTreeMap<String, u64> = [("a".to_string(), 5), ("b".to_string(), 1)].into();
        assert!(kl_to_target(&even, &target).unwrap().abs() < 1e-12);
        let d = kl_to_target(&skew, &target).unwrap();
        // 5/6 ln(5/3) + 1/6 ln(1/3)
        let expected = 5.0 / 6.0 * (5.0f64 / 3.0).ln() + 1.0 / 6.0 * (1.0f64 / 3.0).ln();
        assert!((d - expected).abs() < 1e-12, "{d} vs {expected}");
        let f = factors(&target, &skew, 1.0);
        assert!(f["b"] > 1.0 && f["a"] < 1.0, "{f:?}");
    }
}
