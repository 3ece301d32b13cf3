//! A voxel object: a grid, which voxels are solid, and an RGB colour per solid voxel.
//!
//! # Invariant
//! `colours.len() == occupancy.count()`, and `colours[k]` belongs to the `k`-th occupied voxel in
//! ascending storage order ([`VoxelGrid::index`]); address it with [`Rank`].
//! The object's **anchor** is the centre of the bottom face of its grid: the point placement puts
//! on the ground.

use super::grid::{try_reserve, VoxelGrid};
use super::occupancy::{AtomicOccupancy, Occupancy, Rank};
use crate::error::Result;
use rayon::prelude::*;

/// A coloured voxel object (see the module invariant).
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelObject {
    /// Where the voxels are.
    pub grid: VoxelGrid,
    /// Which voxels are solid.
    pub occupancy: Occupancy,
    /// 8-bit sRGB colour of each solid voxel, in storage order.
    pub colours: Vec<[u8; 3]>,
}

impl VoxelObject {
    /// Wrap an occupancy and its colours; panics when the counts differ (a programming error).
    pub fn new(grid: VoxelGrid, occupancy: Occupancy, colours: Vec<[u8; 3]>) -> VoxelObject {
        assert_eq!(
            occupancy.dims(),
            grid.dims,
            "occupancy does not match its grid"
        );
        assert_eq!(
            colours.len(),
            occupancy.count(),
            "one colour per occupied voxel"
        );
        VoxelObject {
            grid,
            occupancy,
            colours,
        }
    }

    /// The object whose voxel at centre `p` (world metres) is solid with colour `c` when
    /// `shade(p, index)` is `Some(c)`; `index` is the voxel's storage index (for seeded
    /// per-voxel variation). Evaluated in parallel, once per voxel. Panics when the memory
    /// cannot be had ([`Self::try_from_fn`] returns the error).
    pub fn from_fn(
        grid: VoxelGrid,
        shade: impl Fn([f64; 3], usize) -> Option<[u8; 3]> + Sync,
    ) -> VoxelObject {
        Self::try_from_fn(grid, shade).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Self::from_fn`], every large allocation fallible: memory that cannot be had (a memory
    /// limit) is the one-line error [`super::grid::out_of_memory`], not an abort.
    pub fn try_from_fn(
        grid: VoxelGrid,
        shade: impl Fn([f64; 3], usize) -> Option<[u8; 3]> + Sync,
    ) -> Result<VoxelObject> {
        let what = "the voxel object's colours";
        let occ = AtomicOccupancy::try_new(&grid)?;
        // One y-slab per task; slabs are contiguous in storage order, so concatenating them in y
        // order keeps the colours in storage order.
        let slabs: Vec<Vec<[u8; 3]>> = (0..grid.dims[1])
            .into_par_iter()
            .map(|y| {
                let mut out = Vec::new();
                for x in 0..grid.dims[0] {
                    for z in 0..grid.dims[2] {
                        let i = grid.index(x, y, z);
                        if let Some(c) = shade(grid.centre(x, y, z), i) {
                            occ.set(i);
                            if out.len() == out.capacity() {
                                let more = out.len().max(64); // doubling, as push would
                                try_reserve(&mut out, more, what)?;
                            }
                            out.push(c);
                        }
                    }
                }
                Ok(out)
            })
            .collect::<Result<_>>()?;
        let mut colours = Vec::new();
        try_reserve(&mut colours, slabs.iter().map(Vec::len).sum(), what)?;
        for slab in slabs {
            colours.extend_from_slice(&slab);
        }
        Ok(VoxelObject::new(grid, occ.finish(), colours))
    }

    /// Number of solid voxels.
    pub fn len(&self) -> usize {
        self.colours.len()
    }

    /// True when no voxel is solid.
    pub fn is_empty(&self) -> bool {
        self.colours.is_empty()
    }

    /// Solid voxels as `(indices, colour)`, ascending storage order.
    pub fn voxels(&self) -> impl Iterator<Item = ([u32; 3], [u8; 3])> + '_ {
        self.occupancy
            .occupied()
            .zip(&self.colours)
            .map(|(i, &c)| (self.grid.coords(i), c))
    }

    /// Colour of voxel `(x, y, z)`, or `None` when it is empty.
    pub fn colour_at(&self, rank: &Rank<'_>, x: u32, y: u32, z: u32) -> Option<[u8; 3]> {
        rank.of(self.grid.index(x, y, z)).map(|k| self.colours[k])
    }

    /// Number of surface voxels (solid with an empty 6-neighbour).
    pub fn surface_count(&self) -> usize {
        self.occupancy
            .occupied()
            .filter(|&i| {
                let [x, y, z] = self.grid.coords(i);
                self.occupancy.is_surface(x, y, z)
            })
            .count()
    }

    /// World position (metres) of the anchor: centre of the grid's bottom face.
    pub fn anchor(&self) -> [f64; 3] {
        let max = self.grid.max_corner();
        let o = self.grid.origin;
        [(o[0] + max[0]) / 2.0, (o[1] + max[1]) / 2.0, o[2]]
    }

    /// Tight bounds `(min voxel, max voxel)` of the solid voxels, or `None` when empty.
    pub fn occupied_extent(&self) -> Option<([u32; 3], [u32; 3])> {
        self.voxels().fold(None, |acc, (v, _)| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((
                [0, 1, 2].map(|a| lo[a].min(v[a])),
                [0, 1, 2].map(|a| hi[a].max(v[a])),
            )),
        })
    }
}

/// Parse an 8-bit colour `R,G,B` (the `--colour` and `--fill` options).
pub fn parse_rgb(s: &str) -> crate::error::Result<[u8; 3]> {
    let bad = || {
        crate::error::Error::msg(format!("colour {s}: expected R,G,B with each 0..255"))
            .fix("e.g. 128,128,128")
    };
    let v: Vec<u8> = s
        .split(',')
        .map(|t| t.trim().parse::<u8>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    v.try_into().map_err(|_| bad())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_fn_keeps_colours_in_storage_order() {
        let g = VoxelGrid::new([10.0, 20.0, 0.0], 0.5, [4, 3, 5]).unwrap();
        let o = VoxelObject::from_fn(g, |p, _| {
            (p[2] < 1.0).then(|| [(p[0] * 4.0) as u8, (p[1] * 4.0) as u8, (p[2] * 4.0) as u8])
        });
        assert_eq!(o.len(), 4 * 3 * 2);
        let rank = Rank::new(&o.occupancy);
        for (v, c) in o.voxels() {
            let p = g.centre(v[0], v[1], v[2]);
            assert_eq!(
                c,
                [(p[0] * 4.0) as u8, (p[1] * 4.0) as u8, (p[2] * 4.0) as u8]
            );
            assert_eq!(o.colour_at(&rank, v[0], v[1], v[2]), Some(c));
        }
        assert_eq!(o.colour_at(&rank, 0, 0, 4), None);
        assert_eq!(o.anchor(), [11.0, 20.75, 0.0]);
        assert_eq!(o.occupied_extent(), Some(([0, 0, 0], [3, 2, 1])));
        assert_eq!(
            o.surface_count(),
            o.len(),
            "a two-voxel-thick slab is all surface"
        );
    }

    #[test]
    fn rgb_parsing() {
        assert_eq!(parse_rgb("1, 2,255").unwrap(), [1, 2, 255]);
        assert!(
            parse_rgb("1,2").is_err()
                && parse_rgb("1,2,256").is_err()
                && parse_rgb("a,b,c").is_err()
        );
    }
}
