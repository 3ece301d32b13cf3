//! Voxel columns: the solid runs of a level-0 cell with holes or overhangs (the tile format's
//! per-page `bricks` blob, header string [`crate::tiles::BRICKS_FORMAT`], `"dbms voxel columns 1"`).
//!
//! This is case 3 of the Hughes patent (a height field `Z(X, Y)` plus voxels above it) stored
//! as run lengths: every partial cell (`state` 1) of a level-0 page lists its column's solid
//! z-runs, bottom to top. The first run is the **ground**: it is solid from `−∞` (its bottom is
//! stored as `−inf`) up to the terrain, or up to the top of whatever stands on the terrain
//! without a gap (an arch's leg). Each later run floats: it has a finite bottom strictly above
//! the previous run's top (runs that touch are merged, so a gap always has positive height).
//! The last run's top is the cell's `max_z`, bit for bit, so the max-Z hierarchy stays an exact
//! bound. Each run carries the RGBA colour a ray sees on it: the colour of its highest voxel
//! (for the ground run of a cell where only terrain is below the gap, the orthophoto's colour).
//!
//! Heights are absolute metres as `f32`: terrain and object heights are small numbers (a few km
//! at most), where `f32` resolves better than a millimetre, unlike the f64 world x / y.
//!
//! Invariant: a [`PageColumns`] only ever holds valid columns — cells strictly ascending, runs
//! valid by [`check_runs`] — whether built with [`PageColumns::push`] or decoded, so
//! [`PageColumns::encode`] and [`PageColumns::decode`] round-trip bit for bit and a decoder
//! never accepts what an encoder could not have written. Byte layout: `docs/tile-format.md`
//! ("Bricks").

/// `state` of an empty or nodata cell.
pub const STATE_EMPTY: u8 = 0;
/// `state` of a cell with holes or overhangs: the page's voxel bricks say what is where.
pub const STATE_PARTIAL: u8 = 1;
/// `state` of an opaque height-field column, solid from the ground to `max_z`.
pub const STATE_OPAQUE: u8 = 2;

/// One solid run of a column: `bottom ..= top`, absolute metres, and the colour seen on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    /// Bottom of the run, metres; `−inf` for the ground run (the first of a column).
    pub bottom: f32,
    /// Top of the run, metres (finite, above `bottom`).
    pub top: f32,
    /// RGBA colour seen on the run (alpha 255).
    pub colour: [u8; 4],
}

/// Bytes of one encoded run: bottom and top as f32, then r, g, b, a.
pub const RUN_BYTES: usize = 12;

/// The columns of one page's partial cells, by in-page cell index (`row · P + col`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PageColumns {
    cells: Vec<u32>,
    /// `ends[k]`: one past the last run of `cells[k]` in `runs`.
    ends: Vec<u32>,
    runs: Vec<Run>,
}

/// Check that `runs` is a valid column (the module's rules); `Err` says what is wrong.
pub fn check_runs(runs: &[Run]) -> Result<(), String> {
    let Some(first) = runs.first() else {
        return Err("has no runs (the ground run is required)".into());
    };
    if first.bottom != f32::NEG_INFINITY {
        return Err(format!(
            "ground run's bottom is {}, expected -inf",
            first.bottom
        ));
    }
    let mut below = f32::NEG_INFINITY;
    for (k, r) in runs.iter().enumerate() {
        if k > 0 && !(r.bottom.is_finite() && r.bottom > below) {
            return Err(format!(
                "run {k} starts at {} m, not strictly above the previous top {below} m (runs must be sorted, apart and finite)",
                r.bottom
            ));
        }
        if !(r.top.is_finite() && r.top > r.bottom) {
            return Err(format!(
                "run {k} has top {} m, not finite and above its bottom {} m",
                r.top, r.bottom
            ));
        }
        if r.colour[3] != 255 {
            return Err(format!("run {k} has alpha {}, expected 255", r.colour[3]));
        }
        below = r.top;
    }
    Ok(())
}

impl PageColumns {
    /// Number of cells with a column.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when no cell has a column.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Add the column of in-page cell `cell`, which must come after every cell already added.
    pub fn push(&mut self, cell: usize, runs: &[Run]) -> Result<(), String> {
        let c = u32::try_from(cell).map_err(|_| format!("cell {cell} is beyond u32"))?;
        if self.cells.last().is_some_and(|&last| last >= c) {
            return Err(format!(
                "cell {cell} is not after cell {}",
                self.cells.last().unwrap()
            ));
        }
        check_runs(runs).map_err(|e| format!("cell {cell}: {e}"))?;
        let end = u32::try_from(self.runs.len() + runs.len())
            .map_err(|_| "over 2^32 runs in a page".to_string())?;
        self.cells.push(c);
        self.runs.extend_from_slice(runs);
        self.ends.push(end);
        Ok(())
    }

    /// The runs of in-page cell `cell`, bottom first; `None` when it has no column.
    pub fn runs(&self, cell: usize) -> Option<&[Run]> {
        let k = self.cells.binary_search(&u32::try_from(cell).ok()?).ok()?;
        let start = if k == 0 { 0 } else { self.ends[k - 1] as usize };
        Some(&self.runs[start..self.ends[k] as usize])
    }

    /// Every `(cell, runs)`, cells ascending.
    pub fn iter(&self) -> impl Iterator<Item = (usize, &[Run])> + '_ {
        self.cells.iter().enumerate().map(|(k, &c)| {
            let start = if k == 0 { 0 } else { self.ends[k - 1] as usize };
            (c as usize, &self.runs[start..self.ends[k] as usize])
        })
    }

    /// The blob: `u32` cell count, then per cell `u32` cell index, `u32` run count and its runs
    /// ([`RUN_BYTES`] each: `f32` bottom, `f32` top, RGBA), all little-endian.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(4 + 8 * self.cells.len() + RUN_BYTES * self.runs.len());
        out.extend_from_slice(&(self.cells.len() as u32).to_le_bytes());
        for (cell, runs) in self.iter() {
            out.extend_from_slice(&(cell as u32).to_le_bytes());
            out.extend_from_slice(&(runs.len() as u32).to_le_bytes());
            for r in runs {
                out.extend_from_slice(&r.bottom.to_bits().to_le_bytes());
                out.extend_from_slice(&r.top.to_bits().to_le_bytes());
                out.extend_from_slice(&r.colour);
            }
        }
        out
    }

    /// Decode a blob of a page of `page_cells` cells. `Err` says what is wrong (without the
    /// page's name, which the caller adds); never panics.
    pub fn decode(blob: &[u8], page_cells: usize) -> Result<PageColumns, String> {
        let mut at = 0usize;
        let mut word = |what: &str| -> Result<u32, String> {
            let b = blob
                .get(at..at + 4)
                .ok_or_else(|| format!("ends at byte {} inside {what} (truncated)", blob.len()))?;
            at += 4;
            Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        let n = word("the cell count")? as usize;
        let mut out = PageColumns::default();
        let mut runs = Vec::new();
        for k in 0..n {
            let cell = word("a cell header")? as usize;
            let count = word("a cell header")? as usize;
            if cell >= page_cells {
                return Err(format!(
                    "column {k} is for cell {cell}, beyond the page's {page_cells} cells"
                ));
            }
            runs.clear();
            for _ in 0..count {
                let bottom = f32::from_bits(word("a run")?);
                let top = f32::from_bits(word("a run")?);
                let c = word("a run")?.to_le_bytes();
                runs.push(Run {
                    bottom,
                    top,
                    colour: c,
                });
            }
            out.push(cell, &runs)?;
        }
        if at != blob.len() {
            return Err(format!(
                "has {} bytes after its last column",
                blob.len() - at
            ));
        }
        Ok(out)
    }

    /// Check the columns against their page's layers: exactly the `state` 1 cells have a column,
    /// and each column's last top is the cell's `max_z`, bit for bit.
    pub fn check_layers(&self, state: &[u8], max_z: &[f32]) -> Result<(), String> {
        let partial = state.iter().filter(|&&s| s == STATE_PARTIAL).count();
        for (cell, runs) in self.iter() {
            if state.get(cell) != Some(&STATE_PARTIAL) {
                return Err(format!(
                    "cell {cell} has a column but its state is not 1 (partial)"
                ));
            }
            let top = runs.last().expect("checked non-empty").top;
            if top.to_bits() != max_z[cell].to_bits() {
                return Err(format!(
                    "cell {cell}: the column's top {top} m is not the cell's max_z {} m",
                    max_z[cell]
                ));
            }
        }
        if partial != self.len() {
            let missing =
                (0..state.len()).find(|&i| state[i] == STATE_PARTIAL && self.runs(i).is_none());
            return Err(format!(
                "cell {} has state 1 (partial) but no column",
                missing.unwrap_or(0)
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const C: [u8; 4] = [10, 20, 30, 255];

    fn run(bottom: f32, top: f32) -> Run {
        Run {
            bottom,
            top,
            colour: C,
        }
    }

    fn arch() -> PageColumns {
        let mut p = PageColumns::default();
        p.push(3, &[run(f32::NEG_INFINITY, 101.0), run(102.0, 103.0)])
            .unwrap();
        p.push(
            4,
            &[
                run(f32::NEG_INFINITY, 100.0),
                Run {
                    bottom: 102.0,
                    top: 103.0,
                    colour: [1, 2, 3, 255],
                },
            ],
        )
        .unwrap();
        p
    }

    #[test]
    fn encode_decode_round_trips_and_lays_out_bytes_as_documented() {
        let p = arch();
        let blob = p.encode();
        assert_eq!(blob.len(), 4 + 2 * (8 + 2 * RUN_BYTES));
        assert_eq!(&blob[..12], &[2, 0, 0, 0, 3, 0, 0, 0, 2, 0, 0, 0]);
        assert_eq!(&blob[12..16], &f32::NEG_INFINITY.to_bits().to_le_bytes());
        assert_eq!(&blob[16..20], &101.0f32.to_le_bytes());
        assert_eq!(&blob[20..24], &C);
        let back = PageColumns::decode(&blob, 16).unwrap();
        assert_eq!(back, p);
        assert_eq!(back.runs(4).unwrap()[1].colour, [1, 2, 3, 255]);
        assert!(back.runs(5).is_none());
        assert_eq!(
            PageColumns::decode(&PageColumns::default().encode(), 16)
                .unwrap()
                .len(),
            0
        );
    }

    #[test]
    fn malformed_blobs_are_rejected_with_a_reason() {
        let blob = arch().encode();
        let bad = |b: &[u8], page_cells: usize, want: &str| {
            let e = PageColumns::decode(b, page_cells).unwrap_err();
            assert!(e.contains(want), "{e} (wanted {want})");
        };
        // Every truncation is an error, never a panic.
        for n in 0..blob.len() {
            assert!(PageColumns::decode(&blob[..n], 16).is_err(), "length {n}");
        }
        bad(&blob[..5], 16, "truncated");
        let mut extra = blob.clone();
        extra.push(0);
        bad(&extra, 16, "after its last column");
        bad(&blob, 4, "beyond the page's 4 cells");
        let patch = |at: usize, v: f32| {
            let mut b = blob.clone();
            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
            b
        };
        bad(&patch(12, 50.0), 16, "expected -inf"); // ground bottom finite
        bad(&patch(24, 100.5), 16, "not strictly above"); // overlaps the ground run
        bad(&patch(24, 101.0), 16, "not strictly above"); // touches: should have been merged
        bad(&patch(28, 101.5), 16, "above its bottom"); // top below bottom
        bad(&patch(28, f32::NAN), 16, "not finite");
        bad(&patch(24, f32::NAN), 16, "not strictly above");
        let mut alpha = blob.clone();
        alpha[35] = 0;
        bad(&alpha, 16, "alpha 0");
        // Cells out of order; a cell with no runs.
        let mut swapped = blob.clone();
        swapped[4] = 5;
        bad(&swapped, 16, "not after cell 5");
        let mut empty = PageColumns::default().encode();
        empty[0] = 1;
        empty.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 0]);
        bad(&empty, 16, "no runs");
        // A huge run count in a short blob is a truncation, not an allocation.
        let mut huge = blob.clone();
        huge[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        bad(&huge, 16, "truncated");
    }

    #[test]
    fn columns_must_match_the_partial_cells_and_their_max_z() {
        let p = arch();
        let mut state = vec![2u8; 16];
        let mut max_z = vec![100.0f32; 16];
        (state[3], state[4], max_z[3], max_z[4]) = (1, 1, 103.0, 103.0);
        p.check_layers(&state, &max_z).unwrap();
        max_z[4] = 103.5;
        assert!(p
            .check_layers(&state, &max_z)
            .unwrap_err()
            .contains("not the cell's max_z"));
        max_z[4] = 103.0;
        state[7] = 1;
        assert!(p
            .check_layers(&state, &max_z)
            .unwrap_err()
            .contains("cell 7 has state 1"));
        state[7] = 2;
        state[3] = 2;
        assert!(p
            .check_layers(&state, &max_z)
            .unwrap_err()
            .contains("cell 3 has a column"));
    }

    proptest! {
        /// Any valid set of columns round-trips bit for bit.
        #[test]
        fn valid_columns_round_trip(cols in proptest::collection::btree_map(0usize..4096, proptest::collection::vec((0.001f32..50.0, 0.001f32..50.0, any::<[u8; 3]>()), 1..6), 0..20)) {
            let mut p = PageColumns::default();
            for (&cell, steps) in &cols {
                let mut z = -20.0f32;
                let mut runs = Vec::new();
                for (k, &(gap, height, [r, g, b])) in steps.iter().enumerate() {
                    let bottom = if k == 0 { f32::NEG_INFINITY } else { z + gap };
                    let top = if k == 0 { z + height } else { bottom + height };
                    runs.push(Run { bottom, top, colour: [r, g, b, 255] });
                    z = top;
                }
                p.push(cell, &runs).unwrap();
            }
            let back = PageColumns::decode(&p.encode(), 4096).unwrap();
            prop_assert_eq!(back.encode(), p.encode());
            prop_assert_eq!(back, p);
        }
    }
}
