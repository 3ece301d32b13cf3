//! Synthetic voxel objects in the same representation as sculpted ones: surfaces of revolution
//! (storage tanks), cone trees with seeded variation, and flat-roofed prisms extruded from
//! GeoJSON footprints (the heights the shadow stage measures).
//!
//! # Invariants
//! * A voxel is solid when its **centre** is inside the solid (same rule as [`super::solids`]).
//! * Revolved objects and trees are built in their local frame with the anchor (centre of the
//!   grid's bottom face) at `(0, 0, 0)` and an odd number of voxels across, so the axis runs
//!   through a column of voxel centres and a trunk thinner than a voxel still shows as one column.
//! * Extruded footprints keep their world x, y; z = 0 is the ground.
//! * Randomness is a SplitMix64 stream from the user's seed: same seed, same object.

use super::grid::VoxelGrid;
use super::object::VoxelObject;
use crate::error::{Error, Result};
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
    solid(VoxelObject::from_fn(grid, |p, _| {
        inside_ring(&ring, [p[0].hypot(p[1]), p[2]]).then_some(colour)
    }))
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

/// A SplitMix64 generator: a tiny, well-mixed, reproducible stream.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[-1, 1)`.
    fn signed(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
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
    let obj = VoxelObject::from_fn(grid, |q, index| {
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
    });
    Ok((solid(obj)?, h))
}

/// A footprint: polygon rings (outer ring first, then holes; x, y world units) and a height.
#[derive(Debug, Clone, PartialEq)]
pub struct Footprint {
    /// Rings of `[x, y]` points; inside is the even-odd rule over all rings.
    pub rings: Vec<Vec<[f64; 2]>>,
    /// Height of the flat roof above the ground, metres.
    pub height: f64,
}

/// Read the footprints of a GeoJSON FeatureCollection (Polygon and MultiPolygon features) with
/// their height from property `height_field` (a number, metres).
pub fn read_footprints(path: &Path, height_field: &str) -> Result<Vec<Footprint>> {
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
            out.push(Footprint { rings, height });
        }
    }
    if out.is_empty() {
        return Err(Error::file(path, "no footprints in the collection")
            .fix("give at least one Polygon feature"));
    }
    Ok(out)
}

/// Flat-roofed prisms standing on z = 0 over `footprints`, in world x, y; roof voxels (the top
/// voxel of each column) take `roof`, the rest `wall`. Where footprints overlap the tallest wins.
pub fn extrude(
    footprints: &[Footprint],
    voxel: f64,
    wall: [u8; 3],
    roof: [u8; 3],
) -> Result<VoxelObject> {
    let pts = footprints.iter().flat_map(|f| f.rings.iter().flatten());
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let top = footprints.iter().map(|f| f.height).fold(0.0, f64::max);
    let grid = VoxelGrid::covering([lo[0], lo[1], 0.0], [hi[0], hi[1], top], voxel)?;
    let bboxes: Vec<([f64; 2], [f64; 2])> = footprints
        .iter()
        .map(|f| {
            let outer = &f.rings[0];
            let fold = |a: usize, init: f64, op: fn(f64, f64) -> f64| {
                outer.iter().map(|p| p[a]).fold(init, op)
            };
            (
                [
                    fold(0, f64::INFINITY, f64::min),
                    fold(1, f64::INFINITY, f64::min),
                ],
                [
                    fold(0, f64::NEG_INFINITY, f64::max),
                    fold(1, f64::NEG_INFINITY, f64::max),
                ],
            )
        })
        .collect();
    // Roof height of each (x, y) column centre, row-major over (y, x).
    let (nx, ny) = (grid.dims[0] as usize, grid.dims[1] as usize);
    let heights: Vec<f64> = (0..nx * ny)
        .into_par_iter()
        .map(|k| {
            let c = grid.centre((k % nx) as u32, (k / nx) as u32, 0);
            footprints
                .iter()
                .zip(&bboxes)
                .filter(|(_, (l, h))| c[0] >= l[0] && c[0] <= h[0] && c[1] >= l[1] && c[1] <= h[1])
                .filter(|(f, _)| {
                    f.rings
                        .iter()
                        .filter(|r| inside_ring(r, [c[0], c[1]]))
                        .count()
                        % 2
                        == 1
                })
                .map(|(f, _)| f.height)
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
        let fp = read_footprints(&p, "height").unwrap();
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
        assert!(read_footprints(&p, "height")
            .unwrap_err()
            .to_string()
            .contains("feature 0: no positive number in property \"height\""));
    }

    /// An object smaller than a voxel is refused, never written empty (issue 14, defect 8).
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
        let footprint = Footprint {
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
}
