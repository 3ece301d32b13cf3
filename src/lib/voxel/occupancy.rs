//! Which voxels of a grid are solid: a dense bitset in the grid's storage order.
//!
//! # Invariant
//! Bit `i` is voxel [`VoxelGrid::coords`]`(i)`; bits past `grid.len()` are always zero, so
//! counts and equality compare exactly what is occupied. A "surface voxel" is an occupied voxel
//! with at least one empty 6-neighbour (a neighbour outside the grid counts as empty).

use super::grid::VoxelGrid;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// Occupancy of every voxel of a grid, one bit each.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Occupancy {
    grid_dims: [u32; 3],
    words: Vec<u64>,
}

impl Occupancy {
    /// All voxels empty.
    pub fn empty(grid: &VoxelGrid) -> Occupancy {
        Occupancy {
            grid_dims: grid.dims,
            words: vec![0; grid.len().div_ceil(64)],
        }
    }

    /// Occupied where `solid(centre)` is true for the voxel's world centre (metres); parallel.
    pub fn from_fn(grid: &VoxelGrid, solid: impl Fn([f64; 3]) -> bool + Sync) -> Occupancy {
        let b = AtomicOccupancy::new(grid);
        (0..grid.dims[1]).into_par_iter().for_each(|y| {
            for x in 0..grid.dims[0] {
                for z in 0..grid.dims[2] {
                    if solid(grid.centre(x, y, z)) {
                        b.set(grid.index(x, y, z));
                    }
                }
            }
        });
        b.finish()
    }

    /// Dimensions of the grid this occupancy belongs to.
    pub fn dims(&self) -> [u32; 3] {
        self.grid_dims
    }

    /// Is the voxel at storage index `i` occupied?
    #[inline]
    pub fn get_index(&self, i: usize) -> bool {
        self.words[i >> 6] >> (i & 63) & 1 == 1
    }

    /// Is voxel `(x, y, z)` occupied? Indices outside the grid read as empty.
    #[inline]
    pub fn get(&self, x: i64, y: i64, z: i64) -> bool {
        let [nx, ny, nz] = self.grid_dims.map(|d| d as i64);
        if x < 0 || y < 0 || z < 0 || x >= nx || y >= ny || z >= nz {
            return false;
        }
        self.get_index(((y * nx + x) * nz + z) as usize)
    }

    /// Mark the voxel at storage index `i` occupied or empty.
    pub fn set_index(&mut self, i: usize, on: bool) {
        if on {
            self.words[i >> 6] |= 1 << (i & 63);
        } else {
            self.words[i >> 6] &= !(1 << (i & 63));
        }
    }

    /// Number of occupied voxels.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// Number of voxels occupied in both `self` and `other` (same dimensions).
    pub fn count_and(&self, other: &Occupancy) -> usize {
        self.words
            .iter()
            .zip(&other.words)
            .map(|(a, b)| (a & b).count_ones() as usize)
            .sum()
    }

    /// Intersection over union with `other` (same dimensions); 1 when both are empty.
    pub fn iou(&self, other: &Occupancy) -> f64 {
        let inter = self.count_and(other);
        let union = self.count() + other.count() - inter;
        if union == 0 {
            1.0
        } else {
            inter as f64 / union as f64
        }
    }

    /// Storage indices of the occupied voxels, ascending.
    pub fn occupied(&self) -> impl Iterator<Item = usize> + '_ {
        self.words.iter().enumerate().flat_map(|(wi, &w)| {
            let mut w = w;
            std::iter::from_fn(move || {
                (w != 0).then(|| {
                    let b = w.trailing_zeros() as usize;
                    w &= w - 1;
                    wi * 64 + b
                })
            })
        })
    }

    /// Is occupied voxel `(x, y, z)` on the surface (some 6-neighbour empty)?
    pub fn is_surface(&self, x: u32, y: u32, z: u32) -> bool {
        let (x, y, z) = (x as i64, y as i64, z as i64);
        self.get(x, y, z)
            && [
                (-1, 0, 0),
                (1, 0, 0),
                (0, -1, 0),
                (0, 1, 0),
                (0, 0, -1),
                (0, 0, 1),
            ]
            .iter()
            .any(|&(dx, dy, dz)| !self.get(x + dx, y + dy, z + dz))
    }

    /// The raw words (64 voxels each, storage order, bit 0 first).
    pub fn words(&self) -> &[u64] {
        &self.words
    }
}

/// Constant-time rank queries over an [`Occupancy`]: the position of an occupied voxel in the
/// ascending list of occupied voxels (how per-voxel colours are addressed).
pub struct Rank<'a> {
    occ: &'a Occupancy,
    before: Vec<u32>,
}

impl<'a> Rank<'a> {
    /// Build the per-word prefix counts.
    pub fn new(occ: &'a Occupancy) -> Rank<'a> {
        let mut acc = 0u32;
        let before = occ
            .words
            .iter()
            .map(|w| {
                let b = acc;
                acc += w.count_ones();
                b
            })
            .collect();
        Rank { occ, before }
    }

    /// Rank of occupied storage index `i`, or `None` when `i` is empty.
    #[inline]
    pub fn of(&self, i: usize) -> Option<usize> {
        self.occ.get_index(i).then(|| {
            self.before[i >> 6] as usize
                + (self.occ.words[i >> 6] & ((1u64 << (i & 63)) - 1)).count_ones() as usize
        })
    }
}

/// An occupancy that many threads fill at once (bits are only ever set, so the result does not
/// depend on the order of the writes).
pub struct AtomicOccupancy {
    dims: [u32; 3],
    len: usize,
    words: Vec<AtomicU64>,
}

impl AtomicOccupancy {
    /// All voxels empty; panics when the memory cannot be had (see [`Self::try_new`]).
    pub fn new(grid: &VoxelGrid) -> AtomicOccupancy {
        Self::try_new(grid).unwrap_or_else(|e| panic!("{e}"))
    }

    /// All voxels empty, or the one-line error of an allocation that fails.
    pub fn try_new(grid: &VoxelGrid) -> crate::error::Result<AtomicOccupancy> {
        let len = grid.len();
        let mut words = Vec::new();
        super::grid::try_reserve(&mut words, len.div_ceil(64), "the voxel occupancy")?;
        words.extend((0..len.div_ceil(64)).map(|_| AtomicU64::new(0)));
        Ok(AtomicOccupancy {
            dims: grid.dims,
            len,
            words,
        })
    }

    /// Mark storage index `i` occupied.
    #[inline]
    pub fn set(&self, i: usize) {
        self.words[i >> 6].fetch_or(1 << (i & 63), Ordering::Relaxed);
    }

    /// Mark the `n` storage indices from `i` occupied (one column run).
    pub fn set_run(&self, i: usize, n: usize) {
        debug_assert!(i + n <= self.len);
        let (mut i, end) = (i, i + n);
        while i < end {
            let bit = i & 63;
            let take = (64 - bit).min(end - i);
            let mask = if take == 64 {
                u64::MAX
            } else {
                ((1u64 << take) - 1) << bit
            };
            self.words[i >> 6].fetch_or(mask, Ordering::Relaxed);
            i += take;
        }
    }

    /// The finished occupancy.
    pub fn finish(self) -> Occupancy {
        Occupancy {
            grid_dims: self.dims,
            words: self.words.into_iter().map(AtomicU64::into_inner).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_ranks_and_surface() {
        let g = VoxelGrid::new([0.0; 3], 1.0, [3, 3, 70]).unwrap();
        let b = AtomicOccupancy::new(&g);
        b.set_run(g.index(1, 1, 0), 70);
        b.set(g.index(0, 0, 5));
        let o = b.finish();
        assert_eq!(o.count(), 71);
        assert!(o.get(1, 1, 0) && o.get(1, 1, 69) && !o.get(1, 1, 70) && !o.get(1, 2, 0));
        let r = Rank::new(&o);
        let occ: Vec<usize> = o.occupied().collect();
        for (k, &i) in occ.iter().enumerate() {
            assert_eq!(r.of(i), Some(k));
        }
        assert_eq!(r.of(g.index(2, 2, 2)), None);
        // A lone column: every voxel has empty side neighbours.
        assert!(o.is_surface(1, 1, 30));
        let full = Occupancy::from_fn(&g, |_| true);
        assert!(full.is_surface(0, 0, 0) && !full.is_surface(1, 1, 1));
        assert_eq!(full.count(), g.len());
        assert!((o.iou(&full) - 71.0 / g.len() as f64).abs() < 1e-12);
    }
}
