//! Where labelled frame ranges overlap: the real simultaneous actions of BABEL-style annotations.

/// A maximal stretch of frames during which the same set of ranges is active.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Overlap {
    /// First frame.
    pub start: u64,
    /// One past the last frame.
    pub end: u64,
    /// Indices of the ranges active throughout, ascending.
    pub members: Vec<usize>,
}

/// Maximal stretches where two or more of the half-open `ranges` are active, by a sweep over
/// range boundaries; adjacent stretches with the same active set are merged.
pub fn overlaps(ranges: &[(u64, u64)]) -> Vec<Overlap> {
    let mut cuts: Vec<u64> = ranges.iter().flat_map(|&(s, e)| [s, e]).collect();
    cuts.sort_unstable();
    cuts.dedup();
    let mut out: Vec<Overlap> = Vec::new();
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let members: Vec<usize> = ranges
            .iter()
            .enumerate()
            .filter(|(_, (s, e))| *s <= a && b <= *e && s < e)
            .map(|(i, _)| i)
            .collect();
        if members.len() < 2 {
            continue;
        }
        match out.last_mut() {
            Some(last) if last.end == a && last.members == members => last.end = b,
            _ => out.push(Overlap {
                start: a,
                end: b,
                members,
            }),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Frame-by-frame reference: the active set at every frame, grouped into maximal runs.
    fn brute_force(ranges: &[(u64, u64)]) -> Vec<Overlap> {
        let end = ranges.iter().map(|r| r.1).max().unwrap_or(0);
        let mut out: Vec<Overlap> = Vec::new();
        for f in 0..end {
            let members: Vec<usize> = ranges
                .iter()
                .enumerate()
                .filter(|(_, (s, e))| *s <= f && f < *e)
                .map(|(i, _)| i)
                .collect();
            if members.len() < 2 {
                continue;
            }
            match out.last_mut() {
                Some(last) if last.end == f && last.members == members => last.end = f + 1,
                _ => out.push(Overlap {
                    start: f,
                    end: f + 1,
                    members,
                }),
            }
        }
        out
    }

    #[test]
    fn humanml3d_spans_of_cmu_01_01_overlap_once() {
        // 19-219 and 201-401 at 20 fps, as 120 fps frames after the added T-pose frame.
        let ranges = [(115, 1315), (1207, 2407)];
        assert_eq!(
            overlaps(&ranges),
            vec![Overlap {
                start: 1207,
                end: 1315,
                members: vec![0, 1]
            }]
        );
    }

    proptest! {
        #[test]
        fn sweep_matches_frame_by_frame(ranges in prop::collection::vec((0u64..60, 0u64..30), 0..8)) {
            let ranges: Vec<(u64, u64)> = ranges.into_iter().map(|(s, len)| (s, s + len)).collect();
            prop_assert_eq!(overlaps(&ranges), brute_force(&ranges));
        }
    }
}
