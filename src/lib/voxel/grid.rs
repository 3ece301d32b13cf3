//! The geometry of a voxel grid: where it is, how big a voxel is, how many there are.
//!
//! # Invariant
//! Voxel `(x, y, z)` (indices, `0 ≤ x < nx` …) covers the world box
//! `origin + [x, x+1) · s × [y, y+1) · s × [z, z+1) · s` (metres, object axes aligned with the
//! world's east, north, up); its **centre** is at `origin + (index + 0.5) · s`, computed without
//! accumulation so UTM-sized origins keep sub-millimetre precision. Storage order is
//! column-major: `index = (y · nx + x) · nz + z`, so one (x, y) column is contiguous, lowest
//! voxel first.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// Largest number of voxels on one axis (indices must fit the `u16` runs of the object format).
pub const MAX_DIM: u32 = 65_535;

/// Largest number of voxels in one grid (keeps the dense occupancy bitset below 512 MiB).
pub const MAX_VOXELS: u64 = 1 << 32;

/// Most memory one voxel object may take while it is made and written (`dbms object`), bytes:
/// 6 GiB. An object estimated above it is refused up front with the voxel size that fits
/// ([`VoxelGrid::check_memory`]).
pub const MEMORY_BUDGET: u64 = 6 << 30;

/// Bytes a solid voxel takes while its object is made and written when its colours do not
/// compress (a tree's crown, each voxel's shade jittered): its colour (3), and its share of the
/// file's body before compression, compressed and in the file (3 each).
pub const BYTES_PER_SOLID_VOXEL: f64 = 12.0;

/// [`BYTES_PER_SOLID_VOXEL`] for objects of a few colours (extruded walls and roofs), whose
/// body compresses to little: measured 7.7 on 522 M voxels (docs/sculpt.md).
pub const BYTES_PER_PLAIN_VOXEL: f64 = 8.0;

/// Bytes in a GiB.
const GIB: f64 = (1u64 << 30) as f64;

/// The one-line error of an allocation of `bytes` for `what` that failed (a memory limit,
/// `ulimit -v`): made instead of the abort an infallible allocation ends in.
pub fn out_of_memory(what: &str, bytes: usize) -> Error {
    Error::msg(format!(
        "out of memory for {what} ({:.1} MB could not be allocated)",
        bytes as f64 / 1e6
    ))
    .fix("use a larger --voxel, or give dbms more memory")
}

/// Reserve room for `more` items in `v`, or [`out_of_memory`] for `what`.
pub fn try_reserve<T>(v: &mut Vec<T>, more: usize, what: &str) -> Result<()> {
    v.try_reserve_exact(more)
        .map_err(|_| out_of_memory(what, more.saturating_mul(std::mem::size_of::<T>())))
}

/// Position, voxel size and dimensions of a voxel grid (see the module invariant).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VoxelGrid {
    /// World position (metres) of the minimum corner of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Edge length of a voxel, metres, > 0.
    pub voxel_size: f64,
    /// Number of voxels along x (east), y (north), z (up).
    pub dims: [u32; 3],
}

impl VoxelGrid {
    /// A grid of `dims` voxels of edge `voxel_size` metres with its minimum corner at `origin`.
    /// Errors on a non-positive voxel size, a zero or too large dimension.
    pub fn new(origin: [f64; 3], voxel_size: f64, dims: [u32; 3]) -> Result<VoxelGrid> {
        if !(voxel_size.is_finite() && voxel_size > 0.0) {
            return Err(
                Error::msg(format!("voxel size {voxel_size} is not a positive number"))
                    .fix("give --voxel a value > 0 (metres)"),
            );
        }
        if origin.iter().any(|v| !v.is_finite()) {
            return Err(Error::msg("voxel grid origin is not finite"));
        }
        let total = dims
            .iter()
            .fold(1u64, |acc, &d| acc.saturating_mul(d as u64));
        if dims.iter().any(|&d| d == 0 || d > MAX_DIM) || total > MAX_VOXELS {
            return Err(Error::msg(format!(
                "voxel grid of {}×{}×{} voxels is empty or too large (at most {MAX_DIM} per axis and {MAX_VOXELS} in all)",
                dims[0], dims[1], dims[2]
            ))
            .fix("use a larger --voxel or smaller bounds"));
        }
        Ok(VoxelGrid {
            origin,
            voxel_size,
            dims,
        })
    }

    /// The grid of `voxel_size` voxels covering the box `min..max` (metres), snapped outward so
    /// every point of the box is in a voxel; its minimum corner is `min`.
    pub fn covering(min: [f64; 3], max: [f64; 3], voxel_size: f64) -> Result<VoxelGrid> {
        if (0..3).any(|a| !(min[a].is_finite() && max[a].is_finite() && min[a] < max[a])) {
            return Err(Error::msg(format!(
                "bounds {min:?}..{max:?}: each minimum must be below its maximum"
            ))
            .fix("give --bounds MINX,MINY,MINZ,MAXX,MAXY,MAXZ"));
        }
        if !(voxel_size.is_finite() && voxel_size > 0.0) {
            return Err(
                Error::msg(format!("voxel size {voxel_size} is not a positive number"))
                    .fix("give --voxel a value > 0 (metres)"),
            );
        }
        // Tolerate floating noise: 2.0000000001 / 0.5 is 4 voxels, not 5.
        let n = |a: usize| {
            ((max[a] - min[a]) / voxel_size - 1e-9)
                .ceil()
                .clamp(1.0, u32::MAX as f64) as u32
        };
        VoxelGrid::new(min, voxel_size, [n(0), n(1), n(2)])
    }

    /// Refuse an object on this grid with about `solid` solid voxels when making and writing it
    /// would take more than [`MEMORY_BUDGET`] (its occupancy, a bit per voxel of the grid, and
    /// `per_solid` bytes a solid voxel: [`BYTES_PER_SOLID_VOXEL`] or [`BYTES_PER_PLAIN_VOXEL`]);
    /// the error names the voxel size that fits (memory falls with its cube).
    pub fn check_memory(&self, solid: f64, per_solid: f64) -> Result<()> {
        let bytes = self.len() as f64 / 8.0 + solid * per_solid;
        let budget = MEMORY_BUDGET as f64;
        if bytes <= budget {
            return Ok(());
        }
        let fits = self.voxel_size * (bytes / budget).cbrt();
        let [nx, ny, nz] = self.dims;
        Err(Error::msg(format!(
            "a {nx}×{ny}×{nz} grid of {} m voxels, about {solid:.3e} of them solid, would take \
             about {:.1} GiB to make and write, over the {} GiB budget",
            self.voxel_size,
            bytes / GIB,
            MEMORY_BUDGET >> 30
        ))
        .fix(format!(
            "use a larger --voxel ({} m or more fits)",
            (fits * 1000.0).ceil() / 1000.0
        )))
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// Always false: a grid has at least one voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Storage index of voxel `(x, y, z)` (column-major, see module docs).
    #[inline]
    pub fn index(&self, x: u32, y: u32, z: u32) -> usize {
        (y as usize * self.dims[0] as usize + x as usize) * self.dims[2] as usize + z as usize
    }

    /// Voxel indices of a storage index; inverse of [`index`](Self::index).
    #[inline]
    pub fn coords(&self, index: usize) -> [u32; 3] {
        let nz = self.dims[2] as usize;
        let col = index / nz;
        let nx = self.dims[0] as usize;
        [(col % nx) as u32, (col / nx) as u32, (index % nz) as u32]
    }

    /// World position (metres) of the centre of voxel `(x, y, z)`.
    #[inline]
    pub fn centre(&self, x: u32, y: u32, z: u32) -> [f64; 3] {
        let s = self.voxel_size;
        [
            self.origin[0] + (x as f64 + 0.5) * s,
            self.origin[1] + (y as f64 + 0.5) * s,
            self.origin[2] + (z as f64 + 0.5) * s,
        ]
    }

    /// World position (metres) of the maximum corner of the grid.
    pub fn max_corner(&self) -> [f64; 3] {
        let s = self.voxel_size;
        [
            self.origin[0] + self.dims[0] as f64 * s,
            self.origin[1] + self.dims[1] as f64 * s,
            self.origin[2] + self.dims[2] as f64 * s,
        ]
    }
}

/// Parse `MINX,MINY,MINZ,MAXX,MAXY,MAXZ` (metres; the `--bounds` option of `dbms sculpt`).
pub fn parse_box(s: &str) -> Result<[f64; 6]> {
    let bad = || {
        Error::msg(format!(
            "--bounds {s}: expected six numbers MINX,MINY,MINZ,MAXX,MAXY,MAXZ"
        ))
        .fix("e.g. --bounds -1,-1,0,1,1,2")
    };
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    let b: [f64; 6] = v.try_into().map_err(|_| bad())?;
    if b.iter().any(|x| !x.is_finite()) {
        return Err(bad());
    }
    if (0..3).any(|a| b[a] >= b[a + 3]) {
        return Err(Error::msg(format!(
            "--bounds {s}: each minimum must be below its maximum"
        ))
        .fix("give MINX,MINY,MINZ,MAXX,MAXY,MAXZ"));
    }
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The memory budget: the cone of issue 40 (100 m tall, 80 m crown radius, 0.1 m voxels:
    /// 5.4 GB) is refused, naming a voxel size that fits; at that size the same cone fits, and
    /// so does an ordinary tree.
    #[test]
    fn the_memory_budget_refuses_what_would_not_fit_and_names_a_voxel_that_does() {
        let cone = |voxel: f64| {
            let n = |m: f64| (m / voxel).ceil() as u32 | 1;
            let grid = VoxelGrid::new([0.0; 3], voxel, [n(164.0), n(164.0), n(102.7)]).unwrap();
            let solid = std::f64::consts::PI * 82.0 * 82.0 * 77.0 / 3.0 / voxel.powi(3);
            grid.check_memory(solid, BYTES_PER_SOLID_VOXEL)
        };
        let e = cone(0.1).unwrap_err();
        assert!(e.problem.contains("over the 6 GiB budget"), "{}", e.problem);
        let fix = e.fix.clone().unwrap_or_default();
        let fits: f64 = fix
            .split_once('(')
            .and_then(|(_, rest)| rest.split(' ').next()?.parse().ok())
            .unwrap_or_else(|| panic!("no voxel size in {fix:?}"));
        assert!(fits > 0.1 && fits < 0.11, "{fix}");
        cone(fits).unwrap();
        assert!(cone(fits * 0.97).is_err());
        let tree = VoxelGrid::new([0.0; 3], 0.25, [21, 21, 40]).unwrap();
        tree.check_memory(2000.0, BYTES_PER_SOLID_VOXEL).unwrap();
        // The city of docs/sculpt.md (100 000 footprints at 1 m, 522 M voxels, 4.0 GB) fits.
        let city = VoxelGrid::new([0.0; 3], 1.0, [9986, 10018, 30]).unwrap();
        city.check_memory(522e6, BYTES_PER_PLAIN_VOXEL).unwrap();
    }

    #[test]
    fn index_and_coords_are_inverse_and_columns_contiguous() {
        let g = VoxelGrid::new([0.0; 3], 1.0, [3, 4, 5]).unwrap();
        for i in 0..g.len() {
            let [x, y, z] = g.coords(i);
            assert_eq!(g.index(x, y, z), i);
        }
        assert_eq!(g.index(1, 0, 1), g.index(1, 0, 0) + 1);
    }

    #[test]
    fn covering_snaps_outward_and_keeps_utm_precision() {
        let g = VoxelGrid::covering(
            [500_000.0, 5_000_000.0, 100.0],
            [500_010.0, 5_000_004.1, 102.0],
            0.5,
        )
        .unwrap();
        assert_eq!(g.dims, [20, 9, 4]);
        let c = g.centre(19, 8, 3);
        assert!(
            (c[0] - 500_009.75).abs() < 1e-9
                && (c[1] - 5_000_004.25).abs() < 1e-9
                && (c[2] - 101.75).abs() < 1e-12
        );
        // A voxel larger than the box still gives one voxel.
        assert_eq!(
            VoxelGrid::covering([0.0; 3], [1.0; 3], 5.0).unwrap().dims,
            [1, 1, 1]
        );
        assert!(VoxelGrid::covering([0.0; 3], [1.0; 3], 0.0).is_err());
        assert!(VoxelGrid::covering([0.0; 3], [1.0, -1.0, 1.0], 0.1).is_err());
        assert!(VoxelGrid::covering([0.0; 3], [1e6; 3], 1e-3).is_err());
    }

    #[test]
    fn parse_box_accepts_six_ordered_numbers_only() {
        assert_eq!(
            parse_box("-1,-2,0,1,2,3.5").unwrap(),
            [-1.0, -2.0, 0.0, 1.0, 2.0, 3.5]
        );
        assert!(parse_box("0,0,0,1,1").is_err());
        assert!(parse_box("0,0,1,1,1,1").is_err());
        assert!(parse_box("0,0,0,1,1,nan").is_err());
        assert!(parse_box("a,0,0,1,1,1").is_err());
    }
}
