//! Shadow detection in the orthophoto colour: a shadow index and an automatic threshold.
//!
//! Invariant: the index is a pure function of one cell's RGB, in [0, 255], lower = more likely
//! shadow; the threshold is Otsu's over the index histogram of the cells it is given, so it
//! depends only on those cells (the caller passes the cells around one footprint: a local
//! threshold). A histogram whose two classes are not clearly apart has no shadow class.

/// The dark class's mean index must be below this fraction of the bright class's mean for the
/// split to count as shadow versus lit (cast shadows keep roughly 20–60 % of the light).
pub const MAX_DARK_RATIO: f64 = 0.75;
/// A split with a dark class mean below this fraction of the bright class's (but not below
/// [`MAX_DARK_RATIO`]) is a *weak* split ([`weak_threshold`]): a low sun, or a hazy sky, leaves
/// its shadow only 10–25 % darker than the lit ground — as little as ground texture varies.
pub const WEAK_DARK_RATIO: f64 = 0.9;
/// The dark class must hold at least this fraction of the cells.
pub const MIN_DARK_FRACTION: f64 = 0.002;

/// Shadow index of an RGB colour: luminance (Rec. 601), lowered for bluish cells (shadows are lit
/// by the blue sky): `Y · (1 − max(0, b/(r+g+b) − 1/3))`. In [0, 255].
pub fn shadow_index(rgb: [u8; 4]) -> f64 {
    let (r, g, b) = (rgb[0] as f64, rgb[1] as f64, rgb[2] as f64);
    let y = 0.299 * r + 0.587 * g + 0.114 * b;
    let blue_excess = if r + g + b > 0.0 {
        (b / (r + g + b) - 1.0 / 3.0).max(0.0)
    } else {
        0.0
    };
    y * (1.0 - blue_excess)
}

/// Otsu's threshold over shadow indices: cells with index `< threshold` are shadow. `None` when
/// there is no clear shadow class (too few cells, one class, or classes too close; see
/// [`MAX_DARK_RATIO`], [`MIN_DARK_FRACTION`]).
///
/// Otsu's split favours classes of similar size: when the shadow is a few percent of the cells,
/// the best split can be the ground's own texture (grass versus soil, ratio ~0.85). Such an
/// unclear split is retried on its dark side — shadow sits below the darker texture — down to
/// [`MIN_DARK_FRACTION`] of all cells.
pub fn otsu_threshold(indices: impl Iterator<Item = f64>) -> Option<f64> {
    otsu_threshold_of(&histogram(indices), 1.0)
}

/// The histogram of shadow indices: bin `k` counts those whose [`index_bin`] is `k`.
fn histogram(indices: impl Iterator<Item = f64>) -> [u64; 256] {
    let mut hist = [0u64; 256];
    for v in indices {
        hist[index_bin(v)] += 1;
    }
    hist
}

/// The histogram bin of a shadow index: the index rounded, at most 255 (what
/// [`otsu_threshold`] counts; for callers that build the histogram themselves).
pub fn index_bin(index: f64) -> usize {
    // The index is never negative; NaN (none is made) would land in bin 0 as before.
    crate::num::round_i64(index).clamp(0, 255) as usize
}

/// [`otsu_threshold`] over a histogram of shadow indices already counted (bin `k` holds the
/// cells whose [`index_bin`] is `k`), with the dark class held to at most `max_dark_fraction`
/// of the cells: a clear split with a bigger dark side is retried on its dark side, like an
/// unclear one. With 1 it is [`otsu_threshold`]'s threshold. Below 1 it finds shadow under a
/// bright third class: light roofs over grass split as roof versus ground (ratio ~0.55, clear),
/// putting the ground in the dark class; the ground is most of the cells, the shadow is not.
pub fn otsu_threshold_of(hist: &[u64; 256], max_dark_fraction: f64) -> Option<f64> {
    split_below(hist, max_dark_fraction, MAX_DARK_RATIO)
}

/// [`otsu_threshold`] accepting a split whose classes are as close as [`WEAK_DARK_RATIO`]. Such
/// a split may be the ground's own texture: the caller must show the dark class lies where a
/// shadow can fall and nowhere else before taking it for shadow.
pub fn weak_threshold(indices: impl Iterator<Item = f64>) -> Option<f64> {
    split_below(&histogram(indices), 1.0, WEAK_DARK_RATIO)
}

/// Otsu's split of `hist`, retried on its dark side until the dark mean is below
/// `max_ratio` × the bright mean and the dark class at most `max_dark_fraction` of the cells.
fn split_below(hist: &[u64; 256], max_dark_fraction: f64, max_ratio: f64) -> Option<f64> {
    let n = hist.iter().sum::<u64>() as f64;
    split_walk(hist)
        .find(|s| s.apart(max_ratio) && s.dark as f64 <= max_dark_fraction * n)
        .map(|s| s.threshold)
}

/// One of Otsu's splits of a histogram of shadow indices ([`split_walk`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Split {
    /// Cells with an index below it are the dark class.
    threshold: f64,
    /// The dark and the bright class's mean index.
    means: (f64, f64),
    /// Cells in the dark class.
    dark: u64,
}

impl Split {
    /// Whether the dark class's mean is below `max_ratio` × the bright class's.
    fn apart(&self, max_ratio: f64) -> bool {
        self.means.0 < max_ratio * self.means.1
    }
}

/// Otsu's split of `hist`, then Otsu's split of its dark side, and so on, top first, while the
/// dark side holds at least [`MIN_DARK_FRACTION`] of the cells (none with under 16 cells).
fn split_walk(hist: &[u64; 256]) -> impl Iterator<Item = Split> + '_ {
    let n: u64 = hist.iter().sum();
    let min_dark = MIN_DARK_FRACTION * n as f64;
    let first = (n >= 16).then_some(hist.len());
    std::iter::successors(first.map(|top| (top, None)), move |&(top, _)| {
        let (split, m0, m1) = otsu_split(&hist[..top])?;
        let dark: u64 = hist[..=split].iter().sum();
        let s = Split {
            threshold: split as f64 + 0.5,
            means: (m0, m1),
            dark,
        };
        ((dark as f64) >= min_dark).then_some((split + 1, Some(s)))
    })
    .filter_map(|(_, s)| s)
}

/// The splits of the cells of `hist` (bin `k` holds the cells whose [`index_bin`] is `k`) that a
/// threshold `t` on it calls bright: Otsu's split of them, then of its dark side, and so on
/// ([`otsu_threshold`]'s walk), those whose classes are at least weakly apart
/// ([`WEAK_DARK_RATIO`]); thresholds, descending.
///
/// What a clear split calls bright may hold the shadow: under a low sun in an sRGB photo the
/// shadow keeps ~80 % of the lit ground's index, a weak split, while tree crowns and dark cars
/// are a clear one below it. Only the caller can tell (where a shadow must be).
pub fn weak_splits_above(hist: &[u64; 256], t: f64) -> Vec<f64> {
    let mut bright = *hist;
    for (k, c) in bright.iter_mut().enumerate() {
        if (k as f64) < t {
            *c = 0;
        }
    }
    split_walk(&bright)
        .filter(|s| s.apart(WEAK_DARK_RATIO))
        .map(|s| s.threshold)
        .collect()
}

/// Otsu's best split of a histogram (bins = index values): the last bin of the dark class and
/// the two class means. `None` with fewer than two occupied bins.
pub(crate) fn otsu_split(hist: &[u64]) -> Option<(usize, f64, f64)> {
    let n: f64 = hist.iter().sum::<u64>() as f64;
    let total: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| i as f64 * c as f64)
        .sum();
    let (mut w0, mut sum0) = (0.0, 0.0);
    let mut best: Option<(f64, usize, f64, f64)> = None; // (between-class variance, split, mean0, mean1)
    for (t, &c) in hist.iter().enumerate().take(hist.len().saturating_sub(1)) {
        w0 += c as f64;
        sum0 += t as f64 * c as f64;
        let w1 = n - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (total - sum0) / w1);
        let var = w0 * w1 * (m0 - m1) * (m0 - m1);
        if best.is_none_or(|b| var > b.0) {
            best = Some((var, t, m0, m1));
        }
    }
    best.map(|(_, t, m0, m1)| (t, m0, m1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_orders_dark_below_lit_and_blue_below_grey() {
        assert!(shadow_index([40, 40, 40, 255]) < shadow_index([90, 90, 90, 255]));
        assert!(shadow_index([60, 60, 120, 255]) < shadow_index([73, 73, 73, 255]));
        assert_eq!(shadow_index([0, 0, 0, 255]), 0.0);
        assert!(shadow_index([255, 255, 255, 255]) <= 255.0);
    }

    #[test]
    fn otsu_splits_two_clear_classes_and_refuses_one() {
        let two = (0..1000).map(|i| {
            if i % 10 == 0 {
                40.0 + (i % 7) as f64
            } else {
                150.0 + (i % 13) as f64
            }
        });
        let t = otsu_threshold(two).unwrap();
        assert!(t > 46.0 && t < 150.0, "{t}");
        // One texture class only (no shadow): the two halves of its histogram are too close.
        let one = (0..1000).map(|i| 140.0 + (i % 30) as f64);
        assert_eq!(otsu_threshold(one), None);
        assert_eq!(otsu_threshold([10.0, 200.0].into_iter()), None);
    }

    #[test]
    fn a_weak_split_is_found_by_the_weak_threshold_only() {
        // Shadow 22 against lit ground 29 (a sun at 8° under a bright sky): ratio 0.76.
        let low_sun = || {
            (0..1000).map(|i| {
                if i % 8 == 0 {
                    21.0 + (i % 3) as f64
                } else {
                    28.0 + (i % 3) as f64
                }
            })
        };
        assert_eq!(otsu_threshold(low_sun()), None);
        let t = weak_threshold(low_sun()).unwrap();
        assert!(t > 23.0 && t < 28.0, "{t}");
        // Texture alone, 0.93 apart, is not even a weak split.
        let texture = (0..1000).map(|i| if i % 2 == 0 { 140.0 } else { 150.0 });
        assert_eq!(weak_threshold(texture), None);
    }

    #[test]
    fn hard_case_a_small_shadow_on_two_tone_ground_is_still_found() {
        // Grass (~90) and soil (~110) in equal parts, 3 % shadow (0.45 × grass): plain Otsu
        // splits grass from soil (ratio ~0.8, refused); the retry on the dark side finds the shadow.
        let ground = |i: usize| if (i / 7).is_multiple_of(2) { 85.0 } else { 105.0 } + (i % 11) as f64;
        let cells = (0..10_000).map(|i| {
            if i % 33 == 0 {
                40.0 + (i % 5) as f64
            } else {
                ground(i)
            }
        });
        let t = otsu_threshold(cells).unwrap();
        assert!(t > 44.0 && t < 85.0, "{t}");
        // The same ground without the shadow: no shadow class, however deep the retry goes.
        assert_eq!(otsu_threshold((0..10_000).map(ground)), None);
    }

    #[test]
    fn a_low_suns_shadow_is_a_weak_split_above_the_tree_crowns_otsu_takes() {
        // The POV-Ray town under a 12° sun, sRGB: lit grass ~97 (26 %), its shadow ~80 (70 %,
        // ratio 0.82: weak), tree crowns and dark cars in the shadow 50–63 (4 %, 0.71 of the
        // shadow: clear). Otsu takes the crowns; the shadow is a weak split of what it calls lit.
        let mut hist = [0u64; 256];
        for i in 0..10_000usize {
            let v = match i % 100 {
                0..=3 => 50 + (i / 100) % 14,
                4..=29 => 93 + (i / 100) % 9,
                _ => 76 + (i / 100) % 9,
            };
            hist[v] += 1;
        }
        let crowns = otsu_threshold_of(&hist, 1.0).unwrap();
        assert!(crowns > 63.0 && crowns < 76.0, "{crowns}");
        let above = weak_splits_above(&hist, crowns);
        assert_eq!(above.len(), 1, "{above:?}");
        assert!(above[0] > 84.0 && above[0] < 93.0, "{above:?}");
        // Above the shadow's split, one class: nothing.
        assert!(weak_splits_above(&hist, above[0]).is_empty());
        // Texture only, 0.93 apart, is not even weakly split.
        let texture = histogram((0..1000).map(|i| if i % 2 == 0 { 140.0 } else { 150.0 }));
        assert!(weak_splits_above(&texture, 0.0).is_empty());
    }

    #[test]
    fn a_bright_third_class_is_passed_over_when_the_dark_class_must_be_a_minority() {
        // 60 % grass (85–95), 35 % light roofs (165–175), 5 % shadow (36–42).
        let mut hist = [0u64; 256];
        for i in 0..10_000usize {
            let v = match i % 20 {
                0 => 36 + (i / 20) % 7,
                1..=7 => 165 + i % 11,
                _ => 85 + i % 11,
            };
            hist[v] += 1;
        }
        let all = otsu_threshold_of(&hist, 1.0).unwrap();
        assert!(
            all > 95.0 && all < 165.0,
            "roofs split from the grass: {all}"
        );
        let t = otsu_threshold_of(&hist, 0.5).unwrap();
        assert!(t > 42.0 && t < 85.0, "{t}");
    }
}
