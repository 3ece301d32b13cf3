//! Synthetic voxel objects in the same representation as sculpted ones: surfaces of revolution
//! (storage tanks), cone trees with seeded variation, and flat-roofed prisms extruded from
//! GeoJSON footprints (the heights the shadow stage measures).
//!
//! # Invariants
//! * A voxel is solid when its **centre** is inside the solid (same rule as `testing::solids`).
//! * Revolved objects and trees are built in their local frame with the anchor (centre of the
//!   grid's bottom face) at `(0, 0, 0)` and an odd number of voxels across, so the axis runs
//!   through a column of voxel centres and a trunk thinner than a voxel still shows as one column.
//! * Extruded footprints keep their world x, y; z = 0 is the ground.
//! * Randomness is a SplitMix64 stream from the user's seed: same seed, same object.

use super::grid::{try_reserve, VoxelGrid, BYTES_PER_PLAIN_VOXEL, BYTES_PER_SOLID_VOXEL};
use super::object::VoxelObject;
use super::occupancy::AtomicOccupancy;
use crate::error::{Error, Result};
use crate::num::SplitMix;
use rayon::prelude::*;
use std::path::Path;

/// The grid with anchor at the origin for a solid of `radius` and `height` metres.
fn local_grid(radius: f64, height: f64, voxel: f64) -> Result<VoxelGrid> {
    if !(voxel.is_finite() && voxel > 0.0) {
        return Err(
            Error::msg(format!("voxel size {voxel} is not a positive number"))
                .fix("give --voxel a value > 0 (metres)"),
        );
    }
    let across = ((2.0 * radius / voxel - 1e-9).ceil().max(1.0) as u64) | 1; // odd
    let up = (height / voxel - 1e-9).ceil().max(1.0) as u64;
    let dims = [across, across, up].map(|d| d.min(u32::MAX as u64) as u32);
    let half = across as f64 * voxel / 2.0;
    VoxelGrid::new([-half, -half, 0.0], voxel, dims)
}

/// A surface of revolution about the vertical axis: `profile` is a list of `(radius, z)`
/// points (metres, z up from the base) traced from bottom to top; the solid is the closed
/// polygon profile → axis → first point, swept round the axis.
pub fn revolve(profile: &[[f64; 2]], voxel: f64, colour: [u8; 3]) -> Result<VoxelObject> {
    if profile.len() < 2
        || profile.iter().flatten().any(|v| !v.is_finite())
        || profile.iter().any(|p| p[0] < 0.0)
    {
        return Err(
            Error::msg("the profile needs at least two finite R:Z points with R ≥ 0")
                .fix("e.g. --profile 6:0,6:8,0:9.5"),
        );
    }
    let zmin = profile.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let zmax = profile
        .iter()
        .map(|p| p[1])
        .fold(f64::NEG_INFINITY, f64::max);
    let rmax = profile.iter().map(|p| p[0]).fold(0.0, f64::max);
    if !(zmax > zmin && rmax > 0.0) || zmin < 0.0 {
        return Err(Error::msg(
            "the profile must span some height and radius, with z ≥ 0 (z is up from the ground)",
        )
        .fix("e.g. --profile 6:0,6:8,0:9.5"));
    }
    let mut ring: Vec<[f64; 2]> = vec![[0.0, profile[0][1]]];
    ring.extend_from_slice(profile);
    ring.push([0.0, profile[profile.len() - 1][1]]);
    let grid = local_grid(rmax, zmax, voxel)?;
    // At most the cylinder round the profile is solid.
    let cylinder = std::f64::consts::PI * rmax * rmax * zmax / voxel.powi(3);
    grid.check_memory(cylinder, BYTES_PER_SOLID_VOXEL)?;
    solid(VoxelObject::try_from_fn(grid, |p, _| {
        inside_ring(&ring, [p[0].hypot(p[1]), p[2]]).then_some(colour)
    })?)
}

/// `obj`, refused when no voxel is solid: an object smaller than a voxel (no voxel centre inside
/// it) would be written as an empty object that places and renders as nothing, silently.
fn solid(obj: VoxelObject) -> Result<VoxelObject> {
    if obj.is_empty() {
        return Err(Error::msg(format!(
            "no voxel is solid: no voxel centre of the {} m grid falls inside the object",
            obj.grid.voxel_size
        ))
        .fix("use a smaller --voxel: the object is smaller than one voxel"));
    }
    Ok(obj)
}

/// Even-odd point-in-polygon for a closed ring of 2-D points.
fn inside_ring(ring: &[[f64; 2]], q: [f64; 2]) -> bool {
    let mut inside = false;
    let mut j = ring.len() - 1;
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[j]);
        if (a[1] > q[1]) != (b[1] > q[1])
            && q[0] < (b[0] - a[0]) * (q[1] - a[1]) / (b[1] - a[1]) + a[0]
        {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Parameters of a cone tree (metres, colours 8-bit RGB).
#[derive(Debug, Clone, PartialEq)]
pub struct TreeParams {
    /// Nominal total height.
    pub height: f64,
    /// Crown radius at its base.
    pub radius: f64,
    /// Trunk height as a fraction of the total height (the crown starts there).
    pub trunk_fraction: f64,
    /// Trunk radius.
    pub trunk_radius: f64,
    /// Relative variation: height and crown radius are scaled by `1 + vary·u`, the crown shade by
    /// `1 + vary·u'` and each crown voxel by `1 + vary/2·u''` (u uniform in [-1, 1)).
    pub vary: f64,
    /// Nominal crown colour.
    pub crown: [u8; 3],
    /// Trunk colour.
    pub trunk: [u8; 3],
    /// Seed of the variation.
    pub seed: u64,
}

/// A tree: a cone crown on a cylindrical trunk, varied by the seed. Returns the object and the
/// height actually drawn (metres).
pub fn cone_tree(p: &TreeParams, voxel: f64) -> Result<(VoxelObject, f64)> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(positive(p.height) && positive(p.radius) && positive(p.trunk_radius)) {
        return Err(
            Error::msg("tree height, radius and trunk radius must be positive metres")
                .fix("e.g. --height 12 --radius 3"),
        );
    }
    if !(0.0..1.0).contains(&p.trunk_fraction) || !(0.0..1.0).contains(&p.vary) {
        return Err(Error::msg("--trunk and --vary must be fractions in [0, 1)")
            .fix("e.g. --trunk 0.25 --vary 0.2"));
    }
    let mut rng = SplitMix(p.seed);
    let size = 1.0 + p.vary * rng.signed();
    let shade = 1.0 + p.vary * rng.signed();
    let (h, r) = (p.height * size, p.radius * size);
    let base = h * p.trunk_fraction;
    let seed = p.seed;
    let vary = p.vary;
    let grid = local_grid(r.max(p.trunk_radius), h, voxel)?;
    // The crown's cone and the trunk's cylinder (at least one column of voxels).
    let pi = std::f64::consts::PI;
    let volume = pi * r * r * (h - base) / 3.0 + pi * p.trunk_radius.powi(2) * base;
    let solid_voxels = volume / voxel.powi(3) + grid.dims[2] as f64;
    grid.check_memory(solid_voxels, BYTES_PER_SOLID_VOXEL)?;
    let obj = VoxelObject::try_from_fn(grid, |q, index| {
        let rad = q[0].hypot(q[1]);
        if q[2] >= base && q[2] <= h && rad <= r * (h - q[2]) / (h - base) {
            let jitter = 1.0
                + vary / 2.0
                    * SplitMix(seed ^ (index as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93)).signed();
            Some(
                p.crown
                    .map(|c| (c as f64 * shade * jitter).round().clamp(0.0, 255.0) as u8),
            )
        } else if q[2] < base && rad <= p.trunk_radius {
            Some(p.trunk)
        } else {
            None
        }
    })?;
    Ok((solid(obj)?, h))
}

/// A footprint to extrude: polygon rings (outer ring first, then holes; x, y world units) and
/// the height of its flat roof.
#[derive(Debug, Clone, PartialEq)]
pub struct Extrusion {
    /// Rings of `[x, y]` points; inside is the even-odd rule over all rings.
    pub rings: Vec<Vec<[f64; 2]>>,
    /// Height of the flat roof above the ground, metres.
    pub height: f64,
}

/// The footprints to extrude from a GeoJSON FeatureCollection (Polygon and MultiPolygon
/// features), with their height from property `height_field` (a number, metres).
pub fn read_extrusions(path: &Path, height_field: &str) -> Result<Vec<Extrusion>> {
    let features =
        crate::geojson::read_features(path, "give a GeoJSON FeatureCollection of Polygons")?;
    let mut out = Vec::new();
    for (i, f) in features.iter().enumerate() {
        let bad = |what: &str| Error::file(path, format!("feature {i}: {what}"));
        let height =
            f.pointer(&format!("/properties/{height_field}")).and_then(|h| h.as_f64()).filter(|h| h.is_finite() && *h > 0.0).ok_or_else(
                || {
                    bad(&format!("no positive number in property \"{height_field}\""))
                        .fix("give each footprint a height in metres, or name the property with --height-field")
                },
            )?;
        let geometry = f.get("geometry").ok_or_else(|| bad("no geometry"))?;
        for poly in crate::geojson::polygons(geometry)
            .map_err(|e| bad(&e).fix("give footprints as polygons"))?
        {
            if poly.is_empty() || poly.iter().any(|ring| ring.len() < 3) {
                return Err(bad("polygon rings need at least 3 [x, y] positions"));
            }
            let rings = poly
                .into_iter()
                .map(|r| r.into_iter().map(|(x, y)| [x, y]).collect())
                .collect();
            out.push(Extrusion { rings, height });
        }
    }
    if out.is_empty() {
        return Err(Error::file(path, "no footprints in the collection")
            .fix("give at least one Polygon feature"));
    }
    Ok(out)
}

/// Rows of columns in one band of [`extrude`]: the unit of parallel work. Small enough that a
/// band's roof heights are a few MB even 65,535 columns wide, large enough that a typical
/// footprint falls in one or two bands.
const BAND_ROWS: u32 = 16;

/// A footprint with the columns it can cover: those whose centre lies in the bounding box of its
/// outer ring (inclusive), `cols` and `rows` as inclusive index ranges.
struct Prism<'a> {
    footprint: &'a Extrusion,
    lo: [f64; 2],
    hi: [f64; 2],
    cols: [u32; 2],
    rows: [u32; 2],
}

/// The indices `i < n` along axis `a` whose column centre `origin + (i + 0.5)·s` lies in
/// `lo..=hi`, inclusive, or `None`. The centre is computed exactly as [`VoxelGrid::centre`] does,
/// so a column is in the range exactly when the bounding-box test on its centre passes.
fn centre_range(grid: &VoxelGrid, a: usize, lo: f64, hi: f64) -> Option<[u32; 2]> {
    let (o, s, n) = (grid.origin[a], grid.voxel_size, grid.dims[a]);
    let c = |i: u32| o + (i as f64 + 0.5) * s;
    let last = n as f64 - 1.0;
    // An estimate one index wide of the mark each way, then exact steps (centres are monotone).
    let mut i0 = ((lo - o) / s - 1.5).floor().clamp(0.0, last) as u32;
    while i0 > 0 && c(i0 - 1) >= lo {
        i0 -= 1;
    }
    while i0 < n && c(i0) < lo {
        i0 += 1;
    }
    let mut i1 = ((hi - o) / s + 0.5).ceil().clamp(0.0, last) as u32;
    while i1 + 1 < n && c(i1 + 1) <= hi {
        i1 += 1;
    }
    while i1 > 0 && c(i1) > hi {
        i1 -= 1;
    }
    (i0 < n && i0 <= i1 && c(i1) <= hi).then_some([i0, i1])
}

/// The footprints that cover at least one column centre of `grid`, with their column ranges.
fn prisms<'a>(grid: &VoxelGrid, footprints: &'a [Extrusion]) -> Vec<Prism<'a>> {
    footprints
        .iter()
        .filter_map(|f| {
            let outer = &f.rings[0];
            let fold = |a: usize, init: f64, op: fn(f64, f64) -> f64| {
                outer.iter().map(|p| p[a]).fold(init, op)
            };
            let lo = [
                fold(0, f64::INFINITY, f64::min),
                fold(1, f64::INFINITY, f64::min),
            ];
            let hi = [
                fold(0, f64::NEG_INFINITY, f64::max),
                fold(1, f64::NEG_INFINITY, f64::max),
            ];
            Some(Prism {
                footprint: f,
                lo,
                hi,
                cols: centre_range(grid, 0, lo[0], hi[0])?,
                rows: centre_range(grid, 1, lo[1], hi[1])?,
            })
        })
        .collect()
}

/// Roof height of every column of rows `first_row..first_row + out.len() / nx` into `out`
/// (row-major over (y, x), 0 where no footprint covers the column centre), from the prisms
/// listed in `band` (every prism whose rows meet these rows). Only the columns inside each
/// prism's bounding box are tested; returns how many (column, footprint) tests were made.
fn roof_heights(
    grid: &VoxelGrid,
    prisms: &[Prism<'_>],
    band: &[u32],
    first_row: u32,
    out: &mut [f64],
) -> u64 {
    let nx = grid.dims[0] as usize;
    let last_row = first_row + (out.len() / nx) as u32 - 1;
    out.fill(0.0);
    let mut tests = 0u64;
    for p in band.iter().map(|&k| &prisms[k as usize]) {
        let (l, h, f) = (p.lo, p.hi, p.footprint);
        for y in p.rows[0].max(first_row)..=p.rows[1].min(last_row) {
            let row = (y - first_row) as usize * nx;
            for x in p.cols[0]..=p.cols[1] {
                tests += 1;
                let c = grid.centre(x, y, 0);
                if c[0] >= l[0]
                    && c[0] <= h[0]
                    && c[1] >= l[1]
                    && c[1] <= h[1]
                    && f.rings
                        .iter()
                        .filter(|r| inside_ring(r, [c[0], c[1]]))
                        .count()
                        % 2
                        == 1
                {
                    let v = &mut out[row + x as usize];
                    *v = v.max(f.height);
                }
            }
        }
    }
    tests
}

/// Number of solid voxels of a column with roof height `h`: those whose centre is at or below
/// the roof (a prefix of the column, centres rising with `z`).
fn column_voxels(grid: &VoxelGrid, h: f64) -> u32 {
    let nz = grid.dims[2];
    let mut z = 0;
    while z < nz && grid.centre(0, 0, z)[2] <= h {
        z += 1;
    }
    z
}

/// The grid of [`extrude`]: all footprint vertices, from the ground to the tallest roof.
fn extrude_grid(footprints: &[Extrusion], voxel: f64) -> Result<VoxelGrid> {
    let pts = footprints.iter().flat_map(|f| f.rings.iter().flatten());
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let top = footprints.iter().map(|f| f.height).fold(0.0, f64::max);
    VoxelGrid::covering([lo[0], lo[1], 0.0], [hi[0], hi[1], top], voxel).map_err(|e| {
        if !(voxel.is_finite() && voxel > 0.0) {
            e
        } else if (0..2).all(|a| lo[a] < hi[a]) {
            // One object spans every footprint: a city at a fine voxel is over the grid limits.
            e.fix(
                "use a larger --voxel, or split the footprints into several files and extrude each",
            )
        } else {
            Error::msg("the footprints have no area (every vertex on one line)")
                .fix("give footprints as polygons with an area")
        }
    })
}

/// For each band of [`BAND_ROWS`] rows of `grid`, the indices of the prisms whose rows meet it.
fn band_lists(prisms: &[Prism<'_>], grid: &VoxelGrid) -> Vec<Vec<u32>> {
    let mut bands: Vec<Vec<u32>> = vec![Vec::new(); grid.dims[1].div_ceil(BAND_ROWS) as usize];
    for (k, p) in prisms.iter().enumerate() {
        for b in p.rows[0] / BAND_ROWS..=p.rows[1] / BAND_ROWS {
            bands[b as usize].push(k as u32);
        }
    }
    bands
}

/// Flat-roofed prisms standing on z = 0 over `footprints`, in world x, y; roof voxels (the top
/// voxel of each column) take `roof`, the rest `wall`. Where footprints overlap the tallest wins.
///
/// Cost grows with the footprints' area and the solid voxels, not with the grid: each footprint
/// is tested only on the columns inside its bounding box (bands of `BAND_ROWS` rows, in
/// parallel), and empty columns are never visited voxel by voxel. The grid spans all footprints,
/// so its size limits ([`super::grid::MAX_VOXELS`]) bound one object to a district at a fine
/// voxel (10 km × 10 km × 42 m at 1 m).
pub fn extrude(
    footprints: &[Extrusion],
    voxel: f64,
    wall: [u8; 3],
    roof: [u8; 3],
) -> Result<VoxelObject> {
    let grid = extrude_grid(footprints, voxel)?;
    let prisms = prisms(&grid, footprints);
    let bands = band_lists(&prisms, &grid);
    let (nx, ny) = (grid.dims[0] as usize, grid.dims[1]);
    let band_rows = |b: usize| {
        let first = b as u32 * BAND_ROWS;
        (first, BAND_ROWS.min(ny - first))
    };
    // Two passes, so that only one band's heights are ever held per thread: count each band's
    // solid voxels, then fill the colours in place (storage order is band after band).
    let counts: Vec<usize> = bands
        .par_iter()
        .enumerate()
        .map(|(b, list)| {
            let (first, rows) = band_rows(b);
            let mut h = vec![0.0; nx * rows as usize];
            roof_heights(&grid, &prisms, list, first, &mut h);
            h.iter().map(|&h| column_voxels(&grid, h) as usize).sum()
        })
        .collect();
    let total = counts.iter().sum();
    grid.check_memory(total as f64, BYTES_PER_PLAIN_VOXEL)?;
    let mut colours = Vec::new();
    try_reserve(&mut colours, total, "the voxel object's colours")?;
    colours.resize(total, [0u8; 3]);
    let mut slices = Vec::with_capacity(bands.len());
    let mut rest = colours.as_mut_slice();
    for &n in &counts {
        let (head, tail) = rest.split_at_mut(n);
        slices.push(head);
        rest = tail;
    }
    let occ = AtomicOccupancy::try_new(&grid)?;
    let s = grid.voxel_size;
    bands
        .par_iter()
        .zip(slices)
        .enumerate()
        .for_each(|(b, (list, out))| {
            let (first, rows) = band_rows(b);
            let mut heights = vec![0.0; nx * rows as usize];
            roof_heights(&grid, &prisms, list, first, &mut heights);
            let mut k = 0;
            for (j, &h) in heights.iter().enumerate() {
                let n = column_voxels(&grid, h);
                if n == 0 {
                    continue;
                }
                let (x, y) = ((j % nx) as u32, first + (j / nx) as u32);
                occ.set_run(grid.index(x, y, 0), n as usize);
                for z in 0..n {
                    let pz = grid.centre(x, y, z)[2];
                    out[k] = if pz + s > h { roof } else { wall };
                    k += 1;
                }
            }
            debug_assert_eq!(k, out.len());
        });
    solid(VoxelObject::new(grid, occ.finish(), colours))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn revolved_cylinder_tank_has_the_analytic_volume() {
        // A 5 m radius, 8 m tall cylinder: volume 628.3 m³.
        let o = revolve(&[[5.0, 0.0], [5.0, 8.0]], 0.25, [200, 200, 200]).unwrap();
        let vol = o.len() as f64 * 0.25f64.powi(3);
        assert!((vol - PI * 25.0 * 8.0).abs() / (PI * 200.0) < 0.02, "{vol}");
        assert_eq!(o.grid.dims[0] % 2, 1);
        assert!(
            o.anchor().iter().all(|v| v.abs() < 1e-12),
            "anchor at the origin: {:?}",
            o.anchor()
        );
        // A domed tank: profile to a 0-radius apex.
        let dome = revolve(
            &[[5.0, 0.0], [5.0, 8.0], [3.0, 9.5], [0.0, 10.0]],
            0.25,
            [1, 1, 1],
        )
        .unwrap();
        assert!(dome.len() > o.len());
        assert!(revolve(&[[5.0, 0.0]], 0.25, [0; 3]).is_err());
        assert!(revolve(&[[-1.0, 0.0], [1.0, 2.0]], 0.25, [0; 3]).is_err());
    }

    #[test]
    fn trees_are_seeded_and_vary() {
        let p = TreeParams {
            height: 12.0,
            radius: 3.0,
            trunk_fraction: 0.25,
            trunk_radius: 0.1,
            vary: 0.2,
            crown: [40, 100, 40],
            trunk: [90, 60, 30],
            seed: 7,
        };
        let (a, ha) = cone_tree(&p, 0.25).unwrap();
        let (b, hb) = cone_tree(&p, 0.25).unwrap();
        assert_eq!((a.clone(), ha), (b, hb), "same seed, same tree");
        let (c, hc) = cone_tree(
            &TreeParams {
                seed: 8,
                ..p.clone()
            },
            0.25,
        )
        .unwrap();
        assert!(ha != hc && a != c);
        assert!((ha - 12.0).abs() <= 2.4 + 1e-9);
        // The thin trunk (0.1 m < one voxel) is still one column of trunk-coloured voxels.
        let rank = crate::voxel::occupancy::Rank::new(&a.occupancy);
        let mid = a.grid.dims[0] / 2;
        assert_eq!(a.colour_at(&rank, mid, mid, 0), Some([90, 60, 30]));
        let no_vary = TreeParams { vary: 0.0, ..p };
        let (t, h) = cone_tree(&no_vary, 0.25).unwrap();
        assert_eq!(h, 12.0);
        let crown_vol =
            t.colours.iter().filter(|c| **c == [40, 100, 40]).count() as f64 * 0.25f64.powi(3);
        let want = PI * 9.0 * 9.0 / 3.0;
        assert!(
            (crown_vol - want).abs() / want < 0.05,
            "{crown_vol} vs {want}"
        );
    }

    #[test]
    fn extruded_footprints_with_a_hole_and_roofs() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.geojson");
        std::fs::write(
            &p,
            r#"{"type":"FeatureCollection","features":[
            {"type":"Feature","properties":{"height":6},"geometry":{"type":"Polygon","coordinates":[
                [[500000,5000000],[500010,5000000],[500010,5000010],[500000,5000010],[500000,5000000]],
                [[500004,5000004],[500006,5000004],[500006,5000006],[500004,5000006],[500004,5000004]]]}},
            {"type":"Feature","properties":{"height":3},"geometry":{"type":"MultiPolygon","coordinates":[[
                [[500020,5000000],[500024,5000000],[500024,5000004],[500020,5000004],[500020,5000000]]]]}}]}"#,
        )
        .unwrap();
        let fp = read_extrusions(&p, "height").unwrap();
        assert_eq!(fp.len(), 2);
        let o = extrude(&fp, 0.5, [1, 1, 1], [9, 9, 9]).unwrap();
        assert_eq!(o.grid.origin, [500000.0, 5000000.0, 0.0]);
        let want = (100.0 - 4.0) * 6.0 + 16.0 * 3.0;
        assert!((o.len() as f64 * 0.125 - want).abs() < 1e-9, "{}", o.len());
        let rank = crate::voxel::occupancy::Rank::new(&o.occupancy);
        assert_eq!(o.colour_at(&rank, 0, 0, 11), Some([9, 9, 9]), "roof");
        assert_eq!(o.colour_at(&rank, 0, 0, 10), Some([1, 1, 1]), "wall");
        assert_eq!(o.colour_at(&rank, 10, 10, 0), None, "courtyard");
        std::fs::write(&p, r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1]]]}}]}"#).unwrap();
        assert!(read_extrusions(&p, "height")
            .unwrap_err()
            .to_string()
            .contains("feature 0: no positive number in property \"height\""));
    }

    /// The plain extrusion (every footprint tested on every column, every voxel of the grid
    /// visited): the reference the banded one must equal voxel for voxel.
    fn extrude_brute_force(
        footprints: &[Extrusion],
        voxel: f64,
        wall: [u8; 3],
        roof: [u8; 3],
    ) -> Result<VoxelObject> {
        let grid = extrude_grid(footprints, voxel)?;
        let nx = grid.dims[0] as usize;
        let heights: Vec<f64> = (0..nx * grid.dims[1] as usize)
            .map(|k| {
                let c = grid.centre((k % nx) as u32, (k / nx) as u32, 0);
                footprints
                    .iter()
                    .filter(|f| {
                        let o = &f.rings[0];
                        let (lx, hx, ly, hy) = (
                            o.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min),
                            o.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max),
                            o.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min),
                            o.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max),
                        );
                        c[0] >= lx && c[0] <= hx && c[1] >= ly && c[1] <= hy
                    })
                    .filter(|f| {
                        f.rings
                            .iter()
                            .filter(|r| inside_ring(r, [c[0], c[1]]))
                            .count()
                            % 2
                            == 1
                    })
                    .map(|f| f.height)
                    .fold(0.0, f64::max)
            })
            .collect();
        let s = grid.voxel_size;
        solid(VoxelObject::from_fn(grid, |p, index| {
            let [x, y, _] = grid.coords(index);
            let h = heights[y as usize * nx + x as usize];
            (p[2] <= h).then(|| if p[2] + s > h { roof } else { wall })
        }))
    }

    fn rect(x: f64, y: f64, w: f64, d: f64) -> Vec<[f64; 2]> {
        vec![[x, y], [x + w, y], [x + w, y + d], [x, y + d]]
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(96))]
        /// Banded extrusion equals the brute force: overlaps, holes, triangles, edges exactly on
        /// column centres (quarter-metre lattice), footprints spanning many bands.
        #[test]
        fn banded_extrusion_equals_the_brute_force(
            shapes in proptest::collection::vec(
                (0u32..160, 0u32..160, 1u32..60, 1u32..120, 1u32..50, 0u32..3), 1..14),
            voxel in proptest::sample::select(vec![0.25, 0.5, 0.7, 1.0, 3.0]),
        ) {
            let q = 0.25;
            let fp: Vec<Extrusion> = shapes
                .iter()
                .map(|&(x, y, w, d, h, kind)| {
                    let (x, y) = (500_000.0 + x as f64 * q, 5_300_000.0 + y as f64 * q);
                    let (w, d) = (w as f64 * q, d as f64 * q);
                    let rings = match kind {
                        0 => vec![rect(x, y, w, d)],
                        1 => vec![rect(x, y, w, d), rect(x + w / 4.0, y + d / 4.0, w / 2.0, d / 2.0)],
                        _ => vec![vec![[x, y], [x + w, y + d / 3.0], [x + w / 3.0, y + d]]],
                    };
                    Extrusion { rings, height: h as f64 * 0.37 }
                })
                .collect();
            let (wall, roof) = ([1, 2, 3], [7, 8, 9]);
            proptest::prop_assert_eq!(
                extrude(&fp, voxel, wall, roof),
                extrude_brute_force(&fp, voxel, wall, roof)
            );
        }
    }

    /// Each footprint is tested only on the columns inside its bounding box, so the work per
    /// footprint does not grow with the city (testing every footprint on every column of a grid
    /// that grows with the footprints is quadratic).
    #[test]
    fn each_footprint_is_tested_only_on_the_columns_of_its_bounding_box() {
        let work = |n: usize| {
            // 10 m squares on a 31 m lot grid, 100 lots a row, corners on voxel boundaries.
            let fp: Vec<Extrusion> = (0..n)
                .map(|k| Extrusion {
                    rings: vec![rect(
                        500_000.0 + 31.0 * (k % 100) as f64,
                        5_300_000.0 + 31.0 * (k / 100) as f64,
                        10.0,
                        10.0,
                    )],
                    height: 4.0 + (k % 7) as f64,
                })
                .collect();
            let grid = extrude_grid(&fp, 1.0).unwrap();
            let prisms = prisms(&grid, &fp);
            let bands = band_lists(&prisms, &grid);
            let nx = grid.dims[0] as usize;
            let mut tests = 0;
            for (b, list) in bands.iter().enumerate() {
                let first = b as u32 * BAND_ROWS;
                let rows = BAND_ROWS.min(grid.dims[1] - first) as usize;
                let mut h = vec![0.0; nx * rows];
                tests += roof_heights(&grid, &prisms, list, first, &mut h);
                assert_eq!(
                    h.iter().filter(|&&h| h > 0.0).count() as u64,
                    list.iter()
                        .map(|&k| {
                            let r = prisms[k as usize].rows;
                            (r[1].min(first + rows as u32 - 1) - r[0].max(first) + 1) as u64 * 10
                        })
                        .sum::<u64>(),
                    "band {b}: every column of each square is roofed, no other"
                );
            }
            (tests, grid.len() as u64 / grid.dims[2] as u64)
        };
        for n in [100, 2_000] {
            let (tests, columns) = work(n);
            // 10 × 10 column centres in each square; the old scan made `columns × n` tests.
            assert_eq!(tests, 100 * n as u64, "{n} footprints");
            assert!(tests * 100 < columns * n as u64);
        }
    }

    /// An object smaller than a voxel is refused, never written empty.
    #[test]
    fn an_object_smaller_than_a_voxel_is_refused() {
        let tree = TreeParams {
            height: 12.0,
            radius: 3.0,
            trunk_fraction: 0.25,
            trunk_radius: 0.2,
            vary: 0.2,
            crown: [40, 100, 40],
            trunk: [90, 60, 30],
            seed: 1,
        };
        let footprint = Extrusion {
            rings: vec![vec![[0.2, 0.2], [0.8, 0.2], [0.8, 0.8], [0.2, 0.8]]],
            height: 6.0,
        };
        let errors = [
            cone_tree(&tree, 100.0).map(|_| ()),
            revolve(&[[2.0, 0.0], [2.0, 3.0]], 50.0, [1; 3]).map(|_| ()),
            extrude(&[footprint], 2.0, [1; 3], [2; 3]).map(|_| ()),
        ];
        for e in errors {
            let e = e.unwrap_err().to_string();
            assert!(e.starts_with("no voxel is solid"), "{e}");
            assert!(e.contains("use a smaller --voxel"), "{e}");
        }
    }

    /// A footprint file too large for one object at this voxel says how to split it, not
    /// `--bounds` (an option extrude does not have).
    #[test]
    fn a_city_too_large_for_one_object_says_how_to_split_it() {
        let fp = |x: f64, y: f64| Extrusion {
            rings: vec![rect(x, y, 10.0, 10.0)],
            height: 8.0,
        };
        let e = extrude(&[fp(0.0, 0.0), fp(20_000.0, 20_000.0)], 0.1, [1; 3], [2; 3])
            .unwrap_err()
            .to_string();
        assert!(e.contains("too large"), "{e}");
        assert!(e.contains("split the footprints"), "{e}");
        let flat = Extrusion {
            rings: vec![vec![[0.0, 0.0], [5.0, 0.0], [10.0, 0.0]]],
            height: 8.0,
        };
        let e = extrude(&[flat], 1.0, [1; 3], [2; 3])
            .unwrap_err()
            .to_string();
        assert!(e.contains("no area"), "{e}");
    }
}
