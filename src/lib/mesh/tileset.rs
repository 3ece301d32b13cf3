//! The 3D Tiles 1.1 tileset that lists an export's glTF tiles: a tree of tiles from the
//! coarsest level to the finest, each with a bounding box a viewer culls against its view
//! frustum and the geometric error it would make if shown instead of its children, and the
//! matrix that puts the database's frame on the WGS 84 globe.
//!
//! Frames: tile contents are in the **local frame**, metres from the export's origin (a world
//! point near the database's centre) with x east, y north, z up along the grid's axes (glTF
//! turns them y-up; 3D Tiles turns them back). The root's `transform` maps the local frame to
//! Earth-centred, Earth-fixed WGS 84 (EPSG:4978): the affine map that agrees with the CRS's
//! exact projection at the origin (its columns are the derivatives of ECEF along grid east,
//! grid north and the ellipsoid's normal), so the grid's convergence and scale factor are in
//! it. Away from the origin the flat frame departs from the curved Earth; [`Frame`] carries the
//! largest departure at the database's corners. Heights are taken as ellipsoidal (no geoid is
//! applied). A CRS the default build cannot convert gets no transform: the tileset is then in
//! the local frame alone, which a viewer without a globe shows as it is.
//!
//! Invariants: a tile's box holds its content and its children's boxes; a tile's geometric
//! error is at least each child's; leaves have geometric error 0.

use crate::crs::Crs;
use serde_json::{json, Value};

/// The local frame of an export and its place on the globe.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// World position (CRS units, z metres) of the local frame's origin.
    pub origin: [f64; 3],
    /// The CRS the origin is in, by name (e.g. `EPSG:32632`).
    pub crs: String,
    /// Local frame → ECEF (metres), column-major as 3D Tiles stores `transform`; `None` when
    /// the CRS cannot be converted to latitude and longitude.
    pub to_ecef: Option<[f64; 16]>,
    /// Largest distance (metres) between the transform's and the exact projection's ECEF
    /// position at the corners of the area the frame was made for (at the origin's height).
    pub corner_error_m: Option<f64>,
}

/// WGS 84 semi-major axis, metres.
const A_AXIS: f64 = 6_378_137.0;
/// WGS 84 first eccentricity squared.
const E2: f64 = (2.0 - 1.0 / 298.257_223_563) / 298.257_223_563;

/// ECEF position (metres) of latitude, longitude (degrees) and ellipsoidal height (metres).
pub fn ecef(lat_deg: f64, lon_deg: f64, h: f64) -> [f64; 3] {
    let (sp, cp) = lat_deg.to_radians().sin_cos();
    let (sl, cl) = lon_deg.to_radians().sin_cos();
    let n = A_AXIS / (1.0 - E2 * sp * sp).sqrt();
    [
        (n + h) * cp * cl,
        (n + h) * cp * sl,
        (n * (1.0 - E2) + h) * sp,
    ]
}

impl Frame {
    /// The frame with its origin at `origin` (world), placed on the globe through `crs`, its
    /// departure from the exact projection measured at the corners `[min_x, min_y, max_x,
    /// max_y]` of the area it serves.
    pub fn new(crs: &Crs, origin: [f64; 3], area: [f64; 4]) -> Frame {
        let to_ecef = |x: f64, y: f64, z: f64| {
            crs.to_lat_lon(x, y)
                .map(|(lat, lon)| ecef(lat, lon, z))
                .filter(|_| !crs.geographic)
        };
        let [x0, y0, z0] = origin;
        let Some(t) = to_ecef(x0, y0, z0) else {
            return Frame {
                origin,
                crs: crs.name(),
                to_ecef: None,
                corner_error_m: None,
            };
        };
        // Central differences over ±STEP metres: the derivative to ~1e-12 (the error is the
        // third derivative times STEP², and the Earth bends over thousands of kilometres).
        const STEP: f64 = 10.0;
        let diff = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|k| (b[k] - a[k]) / (2.0 * STEP));
        let (Some(w), Some(e), Some(s), Some(n)) = (
            to_ecef(x0 - STEP, y0, z0),
            to_ecef(x0 + STEP, y0, z0),
            to_ecef(x0, y0 - STEP, z0),
            to_ecef(x0, y0 + STEP, z0),
        ) else {
            unreachable!("the origin converts, so points 10 m from it do");
        };
        let (east, north) = (diff(w, e), diff(s, n));
        let (lat, lon) = crs.to_lat_lon(x0, y0).expect("converted above");
        let (sp, cp) = lat.to_radians().sin_cos();
        let (sl, cl) = lon.to_radians().sin_cos();
        let up = [cp * cl, cp * sl, sp];
        let m = [
            east[0], east[1], east[2], 0.0, north[0], north[1], north[2], 0.0, up[0], up[1], up[2],
            0.0, t[0], t[1], t[2], 1.0,
        ];
        let [ax, ay, bx, by] = area;
        let corner_error_m = [(ax, ay), (bx, ay), (ax, by), (bx, by)]
            .iter()
            .filter_map(|&(x, y)| {
                let exact = to_ecef(x, y, z0)?;
                let l = [x - x0, y - y0, 0.0];
                let placed = [0, 1, 2].map(|k| m[k] * l[0] + m[4 + k] * l[1] + m[12 + k]);
                Some(
                    (0..3)
                        .map(|k| (placed[k] - exact[k]).powi(2))
                        .sum::<f64>()
                        .sqrt(),
                )
            })
            .fold(0.0f64, f64::max);
        Frame {
            origin,
            crs: crs.name(),
            to_ecef: Some(m),
            corner_error_m: Some(corner_error_m),
        }
    }
}

/// A tile of the tree: where its content is, its box, its error, its children.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    /// Content file relative to the tileset (`None`: a tile with nothing to show).
    pub uri: Option<String>,
    /// Box in the local frame (metres): `(min, max)`; holds the content and the children's.
    pub bounds: ([f64; 3], [f64; 3]),
    /// Metres of error a viewer makes showing this tile instead of its children.
    pub geometric_error: f64,
    /// The finer tiles that replace this one.
    pub children: Vec<Tile>,
}

impl Tile {
    /// 3D Tiles JSON of this tile and its subtree.
    fn to_json(&self) -> Value {
        let (lo, hi) = self.bounds;
        let c = [0, 1, 2].map(|k| (lo[k] + hi[k]) / 2.0);
        let h = [0, 1, 2].map(|k| (hi[k] - lo[k]) / 2.0);
        let mut tile = json!({
            "boundingVolume": {"box": [c[0], c[1], c[2], h[0], 0.0, 0.0, 0.0, h[1], 0.0, 0.0, 0.0, h[2]]},
            "geometricError": self.geometric_error,
        });
        if let Some(uri) = &self.uri {
            tile["content"] = json!({ "uri": uri });
        }
        if !self.children.is_empty() {
            tile["children"] = self.children.iter().map(Tile::to_json).collect();
        }
        tile
    }
}

/// The tileset document: version 1.1, its `extras` giving the local frame's origin and CRS, the root replaced by its children as a viewer refines,
/// placed on the globe by `frame`. `generator` names the program and version (the asset's
/// `extras`: 3D Tiles has no property of its own for it).
pub fn tileset_json(frame: &Frame, root: &Tile, generator: &str) -> Value {
    let mut r = root.to_json();
    r["refine"] = json!("REPLACE");
    if let Some(m) = frame.to_ecef {
        r["transform"] = json!(m);
    }
    let (lo, hi) = root.bounds;
    let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    json!({
        "asset": {"version": "1.1", "extras": {"generator": generator}},
        // Showing nothing at all: off by the whole scene.
        "geometricError": diagonal.max(root.geometric_error),
        "root": r,
        // How to go back to the database's coordinates: world = local + origin.
        "extras": {"local_origin": frame.origin, "crs": frame.crs},
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ECEF of known points: the equator at the prime meridian, the north pole, and a height.
    #[test]
    fn ecef_of_known_points() {
        let p = ecef(0.0, 0.0, 0.0);
        assert!((p[0] - A_AXIS).abs() < 1e-6 && p[1].abs() < 1e-6 && p[2].abs() < 1e-6);
        let b = A_AXIS * (1.0 - 1.0 / 298.257_223_563);
        let q = ecef(90.0, 0.0, 100.0);
        assert!((q[2] - (b + 100.0)).abs() < 1e-6, "{q:?}");
        let r = ecef(0.0, 90.0, 0.0);
        assert!((r[1] - A_AXIS).abs() < 1e-6 && r[0].abs() < 1e-6);
    }

    /// The sample's frame (UTM 32N): the transform's columns are unit-ish (scale factor
    /// 0.9996 on the central meridian's side), orthogonal, and the 512 m square's corners are
    /// placed within 2 cm of the exact projection (the flat frame against the Earth's bend:
    /// 362² / 2R ≈ 1 cm).
    #[test]
    fn utm_frame_is_conformal_and_close_at_the_corners() {
        let crs = Crs::epsg(32632);
        let origin = [500256.0, 5300256.0, 380.0];
        let f = Frame::new(&crs, origin, [500000.0, 5300000.0, 500512.0, 5300512.0]);
        let m = f.to_ecef.unwrap();
        let col = |k: usize| [m[4 * k], m[4 * k + 1], m[4 * k + 2]];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let (e, n, u) = (col(0), col(1), col(2));
        // On the central meridian the UTM scale is 0.9996: a grid metre is 1/0.9996 true ones
        // on the ellipsoid, and (R + h) / R of that 380 m above it (R ≈ 6.37e6 m here).
        let grid_m = 1.0 / 0.9996 * (1.0 + 380.0 / 6.37e6);
        for axis in [e, n] {
            let len = dot(axis, axis).sqrt();
            assert!((len - grid_m).abs() < 2e-6, "{len} vs {grid_m}");
        }
        assert!((dot(u, u) - 1.0).abs() < 1e-12);
        assert!(dot(e, n).abs() < 1e-9 && dot(e, u).abs() < 1e-9 && dot(n, u).abs() < 1e-9);
        let err = f.corner_error_m.unwrap();
        assert!(err > 0.002 && err < 0.02, "corner error {err}");
    }

    /// A CRS the default build cannot convert: no transform, said as `None`, never a guess.
    #[test]
    fn unknown_crs_gets_no_transform() {
        let f = Frame::new(&Crs::unknown(), [0.0; 3], [0.0, 0.0, 1.0, 1.0]);
        assert_eq!(f.to_ecef, None);
        let root = Tile {
            uri: Some("a.glb".into()),
            bounds: ([0.0; 3], [1.0; 3]),
            geometric_error: 0.0,
            children: vec![],
        };
        let j = tileset_json(&f, &root, "dbms test");
        assert!(j["root"].get("transform").is_none());
        assert_eq!(j["asset"]["version"], "1.1");
    }
}
