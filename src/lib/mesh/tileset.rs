//! The 3D Tiles 1.1 tileset that lists an export's glTF tiles: a tree of tiles from the
//! coarsest level to the finest, each with a bounding box a viewer culls against its view
//! frustum, the geometric error it would make if shown instead of its children, and the matrix
//! that puts its content on the WGS 84 globe.
//!
//! **A frame per tile.** A tile's content is in its own **local frame**: metres from the tile's
//! origin (a world point at the centre of its cells) with x east, y north, z up along the
//! grid's axes (glTF turns them y-up; 3D Tiles turns them back). [`Frame`] maps a local frame
//! to Earth-centred, Earth-fixed WGS 84 (EPSG:4978) by the affine map that agrees with the CRS's
//! exact projection at the origin (its columns are the derivatives of ECEF along grid east,
//! grid north and the ellipsoid's normal), so the grid's convergence and scale factor are in
//! it. A flat frame departs from the curved Earth by about d²/2R at a distance d from its origin,
//! so each tile gets its own: a finest tile of 64 m is placed within a millimetre wherever it
//! lies in a gaming area of tens of kilometres, where one frame for the whole area would put
//! the terrain 10 km out 7.8 m off. 3D Tiles composes transforms down the tree, so a tile's
//! `transform` is its parent's frame inverted times its own ([`relative`]); the root's is its
//! own. Heights are taken as ellipsoidal (no geoid is applied). A CRS the default build cannot
//! convert gets translations between the tiles' origins instead, and no transform at the root:
//! the tileset is then in the root's local frame, which a viewer without a globe shows as it is.
//!
//! Each tile's `extras.origin` gives its origin in the database's CRS (the tileset's
//! `extras.crs`): world = origin + local, for a tool that reads the content back.
//!
//! Invariants: a tile's box holds its content and its children's boxes (carried into its
//! frame); a tile's geometric error is at least each child's; leaves have geometric error 0.

use crate::crs::Crs;
use serde_json::{json, Value};

/// A local frame and its place on the globe.
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

/// A 4 × 4 affine matrix, column-major, as 3D Tiles stores `transform`.
pub type Matrix = [f64; 16];

/// The matrix that moves by `t`.
pub fn translation(t: [f64; 3]) -> Matrix {
    let mut m = [0.0; 16];
    (0..4).for_each(|k| m[5 * k] = 1.0);
    m[12..15].copy_from_slice(&t);
    m
}

/// `m` applied to point `p`.
pub fn apply(m: &Matrix, p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
}

/// `a · b` (first `b`, then `a`) of affine matrices.
fn multiply(a: &Matrix, b: &Matrix) -> Matrix {
    let mut m = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            m[4 * c + r] = (0..4).map(|k| a[4 * k + r] * b[4 * c + k]).sum();
        }
    }
    m
}

/// The inverse of affine `m` (its 3 × 3 part by cofactors; `m` must be invertible, as a frame's
/// is).
fn inverse(m: &Matrix) -> Matrix {
    let a = |r: usize, c: usize| m[4 * c + r];
    let cof = |r: usize, c: usize| {
        let (r0, r1) = ((r + 1) % 3, (r + 2) % 3);
        let (c0, c1) = ((c + 1) % 3, (c + 2) % 3);
        a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)
    };
    let det = (0..3).map(|c| a(0, c) * cof(0, c)).sum::<f64>();
    let mut inv = [0.0; 16];
    for r in 0..3 {
        for c in 0..3 {
            // (A⁻¹)[r][c] = cofactor(c, r) / det.
            inv[4 * c + r] = cof(c, r) / det;
        }
    }
    for r in 0..3 {
        inv[12 + r] = -(0..3).map(|k| inv[4 * k + r] * m[12 + k]).sum::<f64>();
    }
    inv[15] = 1.0;
    inv
}

/// The transform of a tile whose frame is `child` under a tile whose frame is `parent` (both
/// local → the same outer frame): `parent⁻¹ · child`, what 3D Tiles composes back to `child`.
pub fn relative(parent: &Matrix, child: &Matrix) -> Matrix {
    multiply(&inverse(parent), child)
}

/// A tile of the tree: where its content is, its frame, its box, its error, its children.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    /// Content file relative to the tileset (`None`: a tile with nothing to show).
    pub uri: Option<String>,
    /// World position (CRS units, z metres) of the tile's local frame's origin.
    pub origin: [f64; 3],
    /// The tile's frame → its parent's (the root's: → ECEF), when it has one.
    pub transform: Option<Matrix>,
    /// Box in the tile's local frame (metres): `(min, max)`; holds the content and the
    /// children's boxes.
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
            "extras": {"origin": self.origin},
        });
        if let Some(m) = self.transform {
            tile["transform"] = json!(m);
        }
        if let Some(uri) = &self.uri {
            tile["content"] = json!({ "uri": uri });
        }
        if !self.children.is_empty() {
            tile["children"] = self.children.iter().map(Tile::to_json).collect();
        }
        tile
    }
}

/// The tileset document: version 1.1, the root replaced by its children as a viewer refines,
/// `crs` (the tiles' origins' CRS, by name) in its `extras`. `generator` names the program and
/// version (the asset's `extras`: 3D Tiles has no property of its own for it).
pub fn tileset_json(root: &Tile, crs: &str, generator: &str) -> Value {
    let mut r = root.to_json();
    r["refine"] = json!("REPLACE");
    let (lo, hi) = root.bounds;
    let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    json!({
        "asset": {"version": "1.1", "extras": {"generator": generator}},
        // Showing nothing at all: off by the whole scene.
        "geometricError": diagonal.max(root.geometric_error),
        "root": r,
        "extras": {"crs": crs},
    })
}

/// Every content of a tileset document with its tile's origin (world, CRS units): what
/// [`super::gltf::read_glb`] needs to give a content's positions back in world coordinates.
pub fn content_origins(tileset: &Value) -> Vec<(String, [f64; 3])> {
    fn walk(t: &Value, out: &mut Vec<(String, [f64; 3])>) {
        if let (Some(uri), Some(o)) = (
            t.pointer("/content/uri").and_then(Value::as_str),
            t.pointer("/extras/origin").and_then(Value::as_array),
        ) {
            let o: Vec<f64> = o.iter().filter_map(Value::as_f64).collect();
            if let [x, y, z] = o[..] {
                out.push((uri.to_string(), [x, y, z]));
            }
        }
        for c in t["children"].as_array().into_iter().flatten() {
            walk(c, out);
        }
    }
    let mut out = Vec::new();
    walk(&tileset["root"], &mut out);
    out
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
            origin: [0.0; 3],
            transform: None,
            bounds: ([0.0; 3], [1.0; 3]),
            geometric_error: 0.0,
            children: vec![],
        };
        let j = tileset_json(&root, "unknown CRS", "dbms test");
        assert!(j["root"].get("transform").is_none());
        assert_eq!(j["asset"]["version"], "1.1");
        assert_eq!(content_origins(&j), vec![("a.glb".to_string(), [0.0; 3])]);
    }

    /// Two tiles' frames 20 km apart on UTM 32N: the child's transform composed with the
    /// parent's places the child's points where its own frame does (to a micrometre), and
    /// inverting a frame undoes it.
    #[test]
    fn relative_transforms_compose_back_to_the_childs_frame() {
        let crs = Crs::epsg(32632);
        let parent = Frame::new(&crs, [500_000.0, 5_300_000.0, 400.0], [0.0; 4]);
        let child = Frame::new(&crs, [520_000.0, 5_290_000.0, 400.0], [0.0; 4]);
        let (p, c) = (parent.to_ecef.unwrap(), child.to_ecef.unwrap());
        let rel = relative(&p, &c);
        for q in [[0.0, 0.0, 0.0], [32.0, -32.0, 15.0], [-100.0, 250.0, -3.0]] {
            let direct = apply(&c, q);
            let composed = apply(&p, apply(&rel, q));
            let d = (0..3)
                .map(|k| (direct[k] - composed[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(d < 1e-6, "{d} m at {q:?}");
            let back = apply(&inverse(&c), direct);
            assert!((0..3).all(|k| (back[k] - q[k]).abs() < 1e-6), "{back:?}");
        }
        // The same point 20 km away in the parent's one flat frame is metres off.
        let far = [20_000.0, -10_000.0, 0.0];
        let exact = apply(&c, [0.0; 3]);
        let flat = apply(&p, far);
        let off = (0..3)
            .map(|k| (exact[k] - flat[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(off > 10.0, "one frame would be {off} m off at 22 km");
    }
}
