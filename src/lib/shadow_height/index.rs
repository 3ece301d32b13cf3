//! Which footprints a box meets, without looking at every footprint: a uniform grid of buckets
//! over the database, each listing the footprints whose box overlaps it.
//!
//! Invariant: [`BoxIndex::meeting`] returns exactly the footprints whose box meets the query
//! box (closed boxes: touching counts), in ascending order — what a scan of every box returns —
//! in time proportional to the boxes near the query, so a city's footprints cost linear time.

/// A world box `(min_x, min_y, max_x, max_y)`, metres.
pub type Box2 = (f64, f64, f64, f64);

/// Most buckets along a side (bounds the index's memory for a vast extent).
pub const MAX_BUCKETS: usize = 1024;

/// Footprint boxes bucketed on a uniform grid.
pub struct BoxIndex {
    boxes: Vec<Box2>,
    /// The bucket grid's south-west corner and bucket size, metres.
    origin: (f64, f64),
    size: f64,
    cols: usize,
    rows: usize,
    /// Per bucket (row-major from the south-west), the indices of the boxes overlapping it;
    /// boxes outside the extent are kept in the border buckets.
    buckets: Vec<Vec<u32>>,
}

impl BoxIndex {
    /// Index `boxes` over `extent` (the area queries fall in; boxes beyond it still answer)
    /// in buckets of about `bucket_m` metres (at most [`MAX_BUCKETS`] a side).
    pub fn new(boxes: Vec<Box2>, extent: Box2, bucket_m: f64) -> BoxIndex {
        let (w, h) = (
            (extent.2 - extent.0).max(0.0),
            (extent.3 - extent.1).max(0.0),
        );
        let size = bucket_m
            .max(w / MAX_BUCKETS as f64)
            .max(h / MAX_BUCKETS as f64)
            .max(f64::MIN_POSITIVE);
        let cols = ((w / size).ceil() as usize).clamp(1, MAX_BUCKETS);
        let rows = ((h / size).ceil() as usize).clamp(1, MAX_BUCKETS);
        let mut index = BoxIndex {
            boxes,
            origin: (extent.0, extent.1),
            size,
            cols,
            rows,
            buckets: vec![Vec::new(); cols * rows],
        };
        for k in 0..index.boxes.len() {
            let b = index.boxes[k];
            if !(b.0 <= b.2 && b.1 <= b.3) {
                continue; // empty or NaN: meets nothing
            }
            let (c0, c1, r0, r1) = index.span(b);
            for r in r0..=r1 {
                for c in c0..=c1 {
                    index.buckets[r * cols + c].push(k as u32);
                }
            }
        }
        index
    }

    /// The bucket columns and rows box `b` overlaps, clamped to the grid.
    fn span(&self, b: Box2) -> (usize, usize, usize, usize) {
        let at = |v: f64, o: f64, n: usize| {
            ((v - o) / self.size).floor().clamp(0.0, (n - 1) as f64) as usize
        };
        (
            at(b.0, self.origin.0, self.cols),
            at(b.2, self.origin.0, self.cols),
            at(b.1, self.origin.1, self.rows),
            at(b.3, self.origin.1, self.rows),
        )
    }

    /// The boxes meeting `q`, ascending.
    pub fn meeting(&self, q: Box2) -> Vec<usize> {
        if !(q.0 <= q.2 && q.1 <= q.3) {
            return Vec::new();
        }
        let (c0, c1, r0, r1) = self.span(q);
        let mut out: Vec<usize> = (r0..=r1)
            .flat_map(|r| (c0..=c1).map(move |c| r * self.cols + c))
            .flat_map(|b| self.buckets[b].iter().map(|&k| k as usize))
            .filter(|&k| {
                let b = self.boxes[k];
                b.0 <= q.2 && b.2 >= q.0 && b.1 <= q.3 && b.3 >= q.1
            })
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Box `k` as indexed.
    pub fn get(&self, k: usize) -> Box2 {
        self.boxes[k]
    }
}

/// `b` grown to also cover itself moved by `(sx, sy)` metres.
pub fn swept(b: Box2, (sx, sy): (f64, f64)) -> Box2 {
    (
        b.0.min(b.0 + sx),
        b.1.min(b.1 + sy),
        b.2.max(b.2 + sx),
        b.3.max(b.3 + sy),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every query answers what a scan of all boxes answers: boxes of every size, inside and
    /// outside the extent, touching queries at their edges.
    #[test]
    fn meeting_is_a_scan_of_every_box() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut boxes = Vec::new();
        for _ in 0..400 {
            let (x, y) = (next() * 1400.0 - 200.0, next() * 1400.0 - 200.0);
            let (w, h) = (next() * next() * 300.0, next() * 40.0);
            boxes.push((x, y, x + w, y + h));
        }
        boxes.push((5.0, 5.0, 5.0, 5.0)); // a point
        boxes.push((f64::NAN, 0.0, 1.0, 1.0)); // meets nothing
        let index = BoxIndex::new(boxes.clone(), (0.0, 0.0, 1000.0, 1000.0), 64.0);
        for _ in 0..300 {
            let (x, y) = (next() * 1600.0 - 300.0, next() * 1600.0 - 300.0);
            let q = (x, y, x + next() * 250.0, y + next() * 250.0);
            let scan: Vec<usize> = (0..boxes.len())
                .filter(|&k| {
                    let b = boxes[k];
                    b.0 <= q.2 && b.2 >= q.0 && b.1 <= q.3 && b.3 >= q.1
                })
                .collect();
            assert_eq!(index.meeting(q), scan, "{q:?}");
        }
        let edge = boxes[0];
        assert!(index
            .meeting((edge.2, edge.3, edge.2 + 1.0, edge.3 + 1.0))
            .contains(&0));
        assert_eq!(index.meeting((5.0, 5.0, 5.0, 5.0)).last(), Some(&400));
    }

    #[test]
    fn a_vast_extent_keeps_the_bucket_count_bounded() {
        let index = BoxIndex::new(vec![(0.0, 0.0, 1.0, 1.0)], (-1e15, -1e15, 1e15, 1e15), 1.0);
        assert!(index.buckets.len() <= MAX_BUCKETS * MAX_BUCKETS);
        assert_eq!(index.meeting((0.5, 0.5, 0.6, 0.6)), vec![0]);
    }
}
