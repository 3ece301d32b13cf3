//! Generated scenes with known building heights: the benchmark's and the tests' ground truth.
//!
//! Invariant: a scene is a pure function of its [`SynthSpec`]. The terrain is a plane; the
//! orthophoto is rendered `supersample²` times finer than the database grid and box-averaged
//! down, so shadow and roof edges give mixed cells as in a real photo. Shadows are exact for
//! prisms on a plane: a fine cell centre is shadowed when its ray toward the sun enters a
//! building's rectangle below the roof (walls on the polygon, as in a photo; a raster caster
//! would put them at cell centres, half a fine cell off). Truth heights follow the
//! module's convention: roof above the highest coarse cell centre of terrain under the footprint.

use crate::crs::Crs;
use crate::grid::Grid;
use crate::raster::{Colour, Elevation, Raster};
use crate::shadow_height::Footprint;
use crate::standing::{rasterise_prisms, Prism, RaisedCell};
use crate::sun::Sun;
use rayon::prelude::*;

/// West edge of generated scenes (a UTM-sized easting, to exercise f64 coordinates), metres.
pub const ORIGIN_X: f64 = 500_000.0;
/// South edge of generated scenes, metres.
pub const ORIGIN_Y: f64 = 5_300_000.0;
/// Terrain height at the scene's south-west corner, metres.
pub const BASE_Z: f64 = 400.0;
/// Shadowed colour = lit colour × this.
pub const SHADOW_FACTOR: f64 = 0.45;

/// One building: a rectangle rotated about its centre, extruded `height_m` above the highest
/// ground under it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthBuilding {
    /// Centre, metres from the scene's south-west corner (east, north).
    pub centre: (f64, f64),
    /// Side lengths, metres (along the rotated x, y axes).
    pub size: (f64, f64),
    /// Rotation, degrees counter-clockwise.
    pub rotation_deg: f64,
    /// Roof above the highest ground under the footprint, metres.
    pub height_m: f64,
}

impl SynthBuilding {
    /// Distance (metres, ≥ 0) from world point `p` along the unit horizontal vector `d` to
    /// where the ray first is inside the footprint rectangle (0 when `p` is inside), `None` when
    /// it misses: slab clipping in the rectangle's own frame.
    pub fn ray_entry(&self, p: (f64, f64), d: (f64, f64)) -> Option<f64> {
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let q = (
            p.0 - ORIGIN_X - self.centre.0,
            p.1 - ORIGIN_Y - self.centre.1,
        );
        // Into the rectangle's frame: rotate by −rotation.
        let local = |v: (f64, f64)| (v.0 * c + v.1 * s, -v.0 * s + v.1 * c);
        let (q, d) = (local(q), local(d));
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for (o, v, half) in [(q.0, d.0, self.size.0 / 2.0), (q.1, d.1, self.size.1 / 2.0)] {
            if v == 0.0 {
                if o.abs() > half {
                    return None;
                }
                continue;
            }
            let (a, b) = ((-half - o) / v, (half - o) / v);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1).then_some(t0)
    }

    /// The footprint's corner ring in scene CRS metres, counter-clockwise.
    pub fn ring(&self) -> Vec<(f64, f64)> {
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let (hx, hy) = (self.size.0 / 2.0, self.size.1 / 2.0);
        [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
            .iter()
            .map(|&(x, y)| {
                (
                    ORIGIN_X + self.centre.0 + x * c - y * s,
                    ORIGIN_Y + self.centre.1 + x * s + y * c,
                )
            })
            .collect()
    }
}

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSpec {
    /// Database cell size, metres.
    pub cell: f64,
    /// Grid size in cells (columns, rows).
    pub size: (usize, usize),
    /// Terrain slope: metres of rise per metre east and per metre north.
    pub slope: (f64, f64),
    /// The photo's sun.
    pub sun: Sun,
    /// The buildings.
    pub buildings: Vec<SynthBuilding>,
    /// Photo rendering factor (≥ 1): fine cells per database cell, per axis.
    pub supersample: usize,
}

/// A generated scene: the database layers, footprints and the truth.
pub struct SynthScene {
    /// Terrain (no buildings), metres.
    pub terrain: Elevation,
    /// The photo, with roofs and shadows.
    pub colour: Colour,
    /// One footprint per building.
    pub footprints: Vec<Footprint>,
    /// True height above the highest ground under each footprint, metres.
    pub height_m: Vec<f64>,
    /// True absolute roof height, metres.
    pub roof_z: Vec<f64>,
}

/// Generate a scene. Panics on a spec that makes an invalid footprint (a programming error in
/// the caller, never user input).
pub fn synth_scene(spec: &SynthSpec) -> SynthScene {
    let (w, h) = spec.size;
    let crs = Crs::epsg(32632);
    let top = ORIGIN_Y + h as f64 * spec.cell;
    let grid = Grid::north_up(ORIGIN_X, top, spec.cell, w, h, crs.clone());
    let terrain = Raster::new(
        grid.clone(),
        cells(&grid, |x, y| spec.ground_z(x, y) as f32),
    );
    let rings: Vec<Vec<(f64, f64)>> = spec.buildings.iter().map(|b| b.ring()).collect();
    let footprints: Vec<Footprint> = rings
        .iter()
        .map(|r| Footprint::new(vec![vec![r.clone()]]).expect("valid generated footprint"))
        .collect();
    let roof_z: Vec<f64> = rings
        .iter()
        .zip(&spec.buildings)
        .map(|(r, b)| highest_under(&terrain, r) + b.height_m)
        .collect();

    let k = spec.supersample.max(1);
    let fine = Grid::north_up(ORIGIN_X, top, spec.cell / k as f64, w * k, h * k, crs);
    let roof = roof_mask(&fine, &rings);
    let shadow = shadowed(spec, &fine, &roof, &roof_z);
    let colour = box_average(&fine_photo(&roof, &shadow), &grid, k);
    let height_m = spec.buildings.iter().map(|b| b.height_m).collect();
    SynthScene {
        terrain,
        colour: Raster::new(grid, colour),
        footprints,
        height_m,
        roof_z,
    }
}

impl SynthSpec {
    /// The terrain's height (metres) at world point `(x, y)`: the plane through
    /// [`BASE_Z`] at the scene's south-west corner with the spec's slope.
    fn ground_z(&self, x: f64, y: f64) -> f64 {
        BASE_Z + self.slope.0 * (x - ORIGIN_X) + self.slope.1 * (y - ORIGIN_Y)
    }
}

/// The cells of `grid` whose centre the polygon `ring` (world metres) holds.
fn cells_under(grid: &Grid, ring: &[(f64, f64)]) -> Vec<RaisedCell> {
    rasterise_prisms(
        grid,
        &[Prism {
            rings: vec![ring.to_vec()],
            roof: crate::roof::RoofShape::flat(0.0),
        }],
    )
}

/// The highest terrain (metres) under the footprint `ring` (world metres): the module's
/// convention, over the cell centres it holds.
fn highest_under(terrain: &Elevation, ring: &[(f64, f64)]) -> f64 {
    cells_under(&terrain.grid, ring)
        .iter()
        .map(|c| terrain.data[c.index] as f64)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Per cell of the `fine` grid, the footprint of `rings` that holds its centre (the last
/// one when several do), if any.
fn roof_mask(fine: &Grid, rings: &[Vec<(f64, f64)>]) -> Vec<Option<usize>> {
    let mut roof = vec![None; fine.len()];
    for (k, r) in rings.iter().enumerate() {
        for c in cells_under(fine, r) {
            roof[c.index] = Some(k);
        }
    }
    roof
}

/// Per cell of the `fine` grid, whether its centre is in shadow: its ray toward the sun, from
/// the ground or from the `roof` it is on (`roof_z`, absolute metres), enters another
/// building below that one's roof; or, on the ground, the plane rises toward the sun faster
/// than the rays and shadows itself everywhere.
fn shadowed(spec: &SynthSpec, fine: &Grid, roof: &[Option<usize>], roof_z: &[f64]) -> Vec<bool> {
    let tan_e = spec.sun.elevation_deg.to_radians().tan();
    let toward_sun = spec.sun.direction();
    let plane_dark = spec.slope.0 * toward_sun.0 + spec.slope.1 * toward_sun.1 > tan_e;
    let w = fine.width;
    (0..fine.len())
        .into_par_iter()
        .map(|i| {
            let (x, y) = fine.cell_centre(i % w, i / w);
            let (own, z) = match roof[i] {
                Some(k) => (Some(k), roof_z[k]),
                None if plane_dark => return true,
                None => (None, spec.ground_z(x, y)),
            };
            spec.buildings
                .iter()
                .zip(roof_z)
                .enumerate()
                .filter(|(k, _)| Some(*k) != own)
                .any(|(_, (b, &top))| {
                    b.ray_entry((x, y), toward_sun)
                        .is_some_and(|t| z + t * tan_e < top)
                })
        })
        .collect()
}

/// The photo's RGB (0–255) at each fine cell: roof or [`grass`], darkened by
/// [`SHADOW_FACTOR`] where `shadow` says (a roof in a taller neighbour's shadow too).
fn fine_photo(roof: &[Option<usize>], shadow: &[bool]) -> Vec<[f64; 3]> {
    (0..roof.len())
        .into_par_iter()
        .map(|i| {
            let base = if roof[i].is_some() {
                [170.0, 95.0, 80.0]
            } else {
                grass(i as u64)
            };
            let f = if shadow[i] { SHADOW_FACTOR } else { 1.0 };
            [base[0] * f, base[1] * f, base[2] * f]
        })
        .collect()
}

/// The photo on `grid`: each cell the mean of its `k × k` cells of `fine_rgb` (row-major on a
/// grid `k` times as fine each way), rounded, opaque.
fn box_average(fine_rgb: &[[f64; 3]], grid: &Grid, k: usize) -> Vec<[u8; 4]> {
    let w = grid.width;
    (0..grid.len())
        .into_par_iter()
        .map(|i| {
            let (c, r) = (i % w, i / w);
            let mut sum = [0.0; 3];
            for dr in 0..k {
                for dc in 0..k {
                    let v = fine_rgb[(r * k + dr) * w * k + c * k + dc];
                    (0..3).for_each(|j| sum[j] += v[j]);
                }
            }
            let n = (k * k) as f64;
            [
                (sum[0] / n).round() as u8,
                (sum[1] / n).round() as u8,
                (sum[2] / n).round() as u8,
                255,
            ]
        })
        .collect()
}

/// Grass-like texture: a hashed ±15 % brightness variation per fine cell.
fn grass(i: u64) -> [f64; 3] {
    let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    let v = 0.85 + 0.3 * (x >> 11) as f64 / (1u64 << 53) as f64;
    [95.0 * v, 140.0 * v, 75.0 * v]
}

fn cells<T: Send>(grid: &Grid, f: impl Fn(f64, f64) -> T + Sync) -> Vec<T> {
    (0..grid.len())
        .into_par_iter()
        .map(|i| {
            let (x, y) = grid.cell_centre(i % grid.width, i / grid.width);
            f(x, y)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_entry_clips_the_rotated_rectangle() {
        let b = SynthBuilding {
            centre: (10.0, 10.0),
            size: (4.0, 2.0),
            rotation_deg: 90.0, // 2 m wide east-west, 4 m north-south
            height_m: 5.0,
        };
        let at = |x: f64, y: f64| (ORIGIN_X + x, ORIGIN_Y + y);
        let e = b.ray_entry(at(10.0, 20.0), (0.0, -1.0)).unwrap();
        assert!((e - 8.0).abs() < 1e-9, "{e}");
        let e = b.ray_entry(at(0.0, 10.0), (1.0, 0.0)).unwrap();
        assert!((e - 9.0).abs() < 1e-9, "{e}");
        assert_eq!(b.ray_entry(at(10.0, 10.5), (1.0, 0.0)), Some(0.0));
        assert_eq!(b.ray_entry(at(12.0, 20.0), (0.0, -1.0)), None);
        assert_eq!(b.ray_entry(at(10.0, 20.0), (0.0, 1.0)), None);
    }
}
