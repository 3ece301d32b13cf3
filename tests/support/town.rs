//! A real town for the POV-Ray harness (issue 39): the 472 building footprints of a dense
//! 600 m × 600 m window of Boulder, Colorado (tests/data/boulder/, MTBF-33, MIT), given
//! heights, roofs, trees and vehicles drawn here from a seed and recorded as truth, and cut into
//! square windows that POV-Ray renders ([`window_scene`]).
//!
//! What is real: the footprints (their shapes, sizes and spacing: row houses, neighbours a few
//! metres apart). What is the harness's own: everything else, stated here.
//! * Footprints: each Polygon's outer ring; holes are **filled** (the file's eleven holes are
//!   0.2–4.8 m² raster-tracing artefacts, not courtyards); a MultiPolygon becomes one building
//!   per part of at least [`MIN_PART_M2`] (the slivers of 0.0–0.3 m² are dropped; one feature
//!   has two real parts and so gives two buildings). [`Town::buildings`] keeps the file's order.
//! * Heights: 2–6 storeys (30/25/20/15/10 %) of 3 m × a per-building factor 0.9–1.1, plus a
//!   parapet of 0.3–1.2 m on a flat roof; 3 % of the buildings of at least 150 m² are towers,
//!   flat, 20–45 m. Above the highest ground under the footprint.
//! * Roofs: a footprint whose area is at least 0.9 × its minimum-area bounding rectangle's is
//!   near-rectangular and gets a flat (35 %), gable (35 %) or hip (30 %) roof, the ridge along
//!   the rectangle's long axis, eaves 0.3 m above the top storey, ridge 1.5–5 m above the eaves
//!   (the pitch drawn 20–45° and the rise clamped to that range); any other footprint is flat.
//!   Pitched roofs follow [`Roof`]'s convention exactly.
//! * Trees: crowns (spheres on trunks) 4–18 m tall, radius 1.5–5 m, never over a footprint; a
//!   quarter of them touching a wall (crown 0.05 m off it).
//! * Vehicles: short rows (2–4) of cars and vans in the open ground 2.5–6 m in front of a
//!   building's long side, parked along it, clear of every footprint and trunk.

#![allow(dead_code)]

use super::povray::{Camera, Clutter, PolygonBuilding, Rng, Roof, Scene, Structure};
use std::path::Path;

/// The footprint file, relative to the crate root.
pub const FOOTPRINTS: &str = "tests/data/boulder/boulder_footprints_600m_utm13.geojson";
/// The town's south-west corner, EPSG:32613 metres (east, north).
pub const TOWN_SW: (f64, f64) = (475_669.0, 4_427_987.0);
/// The town's side, metres (a square from [`TOWN_SW`]).
pub const TOWN_SIDE: f64 = 600.0;
/// Ground height at [`TOWN_SW`], metres (Boulder is at about 1630 m).
pub const TOWN_Z0: f64 = 1630.0;
/// MultiPolygon parts smaller than this are slivers and dropped, m².
pub const MIN_PART_M2: f64 = 5.0;

/// Signed area of a ring (counter-clockwise positive), m².
pub fn ring_area(r: &[(f64, f64)]) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum::<f64>()
        / 2.0
}

/// Area centroid of a ring, metres.
pub fn centroid(r: &[(f64, f64)]) -> (f64, f64) {
    let n = r.len();
    let (o, mut cx, mut cy, mut a2) = (r[0], 0.0, 0.0, 0.0);
    for i in 0..n {
        let (a, b) = (
            (r[i].0 - o.0, r[i].1 - o.1),
            (r[(i + 1) % n].0 - o.0, r[(i + 1) % n].1 - o.1),
        );
        let x = a.0 * b.1 - b.0 * a.1;
        a2 += x;
        cx += (a.0 + b.0) * x;
        cy += (a.1 + b.1) * x;
    }
    (o.0 + cx / (3.0 * a2), o.1 + cy / (3.0 * a2))
}

/// Whether `p` is inside ring `r` (even-odd).
pub fn inside(r: &[(f64, f64)], p: (f64, f64)) -> bool {
    let n = r.len();
    let mut c = false;
    for i in 0..n {
        let (a, b) = (r[i], r[(i + 1) % n]);
        if (a.1 > p.1) != (b.1 > p.1) && p.0 < a.0 + (p.1 - a.1) / (b.1 - a.1) * (b.0 - a.0) {
            c = !c;
        }
    }
    c
}

/// Distance from `p` to ring `r`'s boundary, metres.
pub fn boundary_distance(r: &[(f64, f64)], p: (f64, f64)) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % n]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let t = (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / (dx * dx + dy * dy).max(1e-12))
                .clamp(0.0, 1.0);
            (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Signed distance from `p` to a footprint: negative inside, metres.
pub fn signed_distance(r: &[(f64, f64)], p: (f64, f64)) -> f64 {
    let d = boundary_distance(r, p);
    if inside(r, p) {
        -d
    } else {
        d
    }
}

/// The minimum-area bounding rectangle of `pts` (rotating the convex hull's edges): azimuth
/// of its long side (degrees clockwise from grid north, in [0, 180)), long side, short side,
/// metres.
pub fn min_area_rect(pts: &[(f64, f64)]) -> (f64, f64, f64) {
    let mut p: Vec<(f64, f64)> = pts.to_vec();
    p.sort_by(|a, b| a.partial_cmp(b).unwrap());
    p.dedup();
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut hull: Vec<(f64, f64)> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    let mut best = (f64::INFINITY, 0.0, 0.0, 0.0);
    for i in 0..hull.len() {
        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        if len < 1e-9 {
            continue;
        }
        let u = ((b.0 - a.0) / len, (b.1 - a.1) / len);
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for q in &hull {
            let (s, t) = (q.0 * u.0 + q.1 * u.1, -q.0 * u.1 + q.1 * u.0);
            lo = (lo.0.min(s), lo.1.min(t));
            hi = (hi.0.max(s), hi.1.max(t));
        }
        let (du, dv) = (hi.0 - lo.0, hi.1 - lo.1);
        if du * dv < best.0 {
            // Long side's direction: u if du ≥ dv, else u turned 90°.
            let dir = if du >= dv { u } else { (-u.1, u.0) };
            let az = dir.0.atan2(dir.1).to_degrees().rem_euclid(180.0);
            best = (du * dv, az % 180.0, du.max(dv), du.min(dv));
        }
    }
    (best.1, best.2, best.3)
}

/// A ring of points, world metres (east, north), not closed.
pub type Ring = Vec<(f64, f64)>;

/// Read the footprint file: one ring (outer ring, holes filled, not closed, counter-clockwise)
/// per building, and the index of the feature it came from.
pub fn read_footprints(path: &Path) -> Result<Vec<(Ring, usize)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let features = v["features"].as_array().ok_or("no features")?;
    let ring = |r: &serde_json::Value| -> Option<Vec<(f64, f64)>> {
        let mut out: Vec<(f64, f64)> = r
            .as_array()?
            .iter()
            .map(|p| Some((p[0].as_f64()?, p[1].as_f64()?)))
            .collect::<Option<_>>()?;
        if out.len() > 1 && out.first() == out.last() {
            out.pop();
        }
        if ring_area(&out) < 0.0 {
            out.reverse();
        }
        Some(out)
    };
    let mut out = Vec::new();
    for (k, f) in features.iter().enumerate() {
        let g = &f["geometry"];
        let polygons: Vec<&serde_json::Value> = match g["type"].as_str() {
            Some("Polygon") => vec![&g["coordinates"]],
            Some("MultiPolygon") => g["coordinates"]
                .as_array()
                .map(|a| a.iter().collect())
                .unwrap_or_default(),
            t => return Err(format!("feature {k}: geometry {t:?}")),
        };
        for poly in polygons {
            let outer = ring(&poly[0]).ok_or_else(|| format!("feature {k}: bad ring"))?;
            if ring_area(&outer) >= MIN_PART_M2 {
                out.push((outer, k));
            }
        }
    }
    Ok(out)
}

/// A building of the town, relative to the ground (the scene's ground plane makes it
/// absolute: [`Town::building`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TownBuilding {
    /// Footprint (counter-clockwise, not closed), EPSG:32613 metres.
    pub ring: Vec<(f64, f64)>,
    /// The footprint file's feature index it came from.
    pub feature: usize,
    /// `"flat"`, `"gable"` or `"hip"`.
    pub form: &'static str,
    /// Flat roof, or eaves, above the highest ground under the footprint, metres.
    pub eave_m: f64,
    /// Ridge minus eaves (0 for flat), metres.
    pub pitch_m: f64,
    /// Ridge azimuth (the minimum-area rectangle's long side), degrees clockwise from grid
    /// north, in [0, 180).
    pub ridge_azimuth_deg: f64,
    /// Roof colour, linear RGB.
    pub colour: [f64; 3],
    /// A tower (20–45 m).
    pub tower: bool,
    /// Area / minimum-area rectangle's area.
    pub rectangularity: f64,
}

/// The town: buildings, trees and vehicles, drawn once from a seed.
#[derive(Debug, Clone)]
pub struct Town {
    /// Buildings, in the footprint file's order (a two-part feature gives two).
    pub buildings: Vec<TownBuilding>,
    /// Trees and vehicles (ground-relative, as [`Clutter`] always is).
    pub clutter: Vec<Clutter>,
}

fn jitter(rng: &mut Rng, base: [f64; 3]) -> [f64; 3] {
    let j = rng.range(-0.04, 0.04);
    base.map(|c| (c + j).clamp(0.02, 1.0))
}

impl Town {
    /// The town from the footprint file under `root` (the crate root), drawn from `seed`.
    pub fn load(root: &Path, seed: u64) -> Result<Town, String> {
        let rings = read_footprints(&root.join(FOOTPRINTS))?;
        let mut rng = Rng(seed);
        let mut buildings = Vec::new();
        for (ring, feature) in rings {
            let area = ring_area(&ring);
            let (az, long, short) = min_area_rect(&ring);
            let rectangularity = area / (long * short);
            let storeys = match rng.next() {
                x if x < 0.30 => 2.0,
                x if x < 0.55 => 3.0,
                x if x < 0.75 => 4.0,
                x if x < 0.90 => 5.0,
                _ => 6.0,
            };
            let storey = 3.0 * rng.range(0.9, 1.1);
            let tower = area >= 150.0 && rng.next() < 0.03 / 0.5;
            let form_draw = rng.next();
            let pitch_deg = rng.range(20.0, 45.0);
            let parapet = rng.range(0.3, 1.2);
            let tower_h = rng.range(20.0, 45.0);
            let colour_draw = rng.next();
            let form = if tower || rectangularity < 0.9 || form_draw < 0.35 {
                "flat"
            } else if form_draw < 0.70 {
                "gable"
            } else {
                "hip"
            };
            let (eave_m, pitch_m) = match form {
                "flat" if tower => (tower_h, 0.0),
                "flat" => (storeys * storey + parapet, 0.0),
                _ => (
                    storeys * storey + 0.3,
                    (short / 2.0 * pitch_deg.to_radians().tan()).clamp(1.5, 5.0),
                ),
            };
            let base = if form == "flat" {
                match (colour_draw * 3.0) as usize {
                    0 => [0.45, 0.45, 0.43], // grey membrane
                    1 => [0.65, 0.64, 0.60], // light gravel, concrete
                    _ => [0.10, 0.10, 0.11], // tar
                }
            } else {
                match (colour_draw * 3.0) as usize {
                    0 => [0.50, 0.17, 0.11], // red tiles
                    1 => [0.30, 0.27, 0.25], // brown shingle
                    _ => [0.14, 0.14, 0.16], // slate
                }
            };
            let colour = jitter(&mut rng, base);
            buildings.push(TownBuilding {
                ring,
                feature,
                form,
                eave_m,
                pitch_m,
                ridge_azimuth_deg: az,
                colour,
                tower,
                rectangularity,
            });
        }
        let mut town = Town {
            buildings,
            clutter: Vec::new(),
        };
        town.plant(&mut rng);
        town.park(&mut rng);
        Ok(town)
    }

    /// Signed distance from `p` to the nearest footprint (negative inside), metres (only
    /// footprints whose box is within `reach` are looked at; `reach` if none).
    fn clearance(&self, p: (f64, f64), reach: f64) -> f64 {
        let mut d = reach;
        for b in &self.buildings {
            let (lo, hi) = bbox(&b.ring);
            if p.0 < lo.0 - reach || p.0 > hi.0 + reach || p.1 < lo.1 - reach || p.1 > hi.1 + reach
            {
                continue;
            }
            d = d.min(signed_distance(&b.ring, p));
        }
        d
    }

    /// Trees: about one per 600 m² of the town, three quarters in open ground, a quarter
    /// touching a wall.
    fn plant(&mut self, rng: &mut Rng) {
        let n = (TOWN_SIDE * TOWN_SIDE / 600.0) as usize;
        let mut tries = 0;
        let mut planted = 0;
        while planted < n && tries < 50 * n {
            tries += 1;
            let height = rng.range(4.0, 18.0);
            let radius = rng.range(1.5, 5.0).min(height / 2.0);
            let at = if rng.next() < 0.25 {
                // Touching a wall: out from a random edge's point by the radius.
                let b = &self.buildings[(rng.next() * self.buildings.len() as f64) as usize];
                let i = (rng.next() * b.ring.len() as f64) as usize;
                let (p, q) = (b.ring[i], b.ring[(i + 1) % b.ring.len()]);
                let len = (q.0 - p.0).hypot(q.1 - p.1);
                if len < 2.0 {
                    continue;
                }
                let t = rng.range(0.2, 0.8);
                // Counter-clockwise ring: outward is to the right of the edge.
                let out = ((q.1 - p.1) / len, -(q.0 - p.0) / len);
                let r = radius + 0.05;
                (
                    p.0 + t * (q.0 - p.0) + out.0 * r,
                    p.1 + t * (q.1 - p.1) + out.1 * r,
                )
            } else {
                (
                    TOWN_SW.0 + rng.next() * TOWN_SIDE,
                    TOWN_SW.1 + rng.next() * TOWN_SIDE,
                )
            };
            // The crown clears every footprint (touching allowed) and other trees' trunks.
            if self.clearance(at, radius + 1.0) < radius {
                continue;
            }
            let crowded = self.clutter.iter().any(|c| match *c {
                Clutter::Tree {
                    at: o, radius: r, ..
                } => (o.0 - at.0).hypot(o.1 - at.1) < 0.7 * (r + radius),
                _ => false,
            });
            if crowded {
                continue;
            }
            self.clutter.push(Clutter::Tree { at, radius, height });
            planted += 1;
        }
    }

    /// Vehicles: rows of 2–4 in front of a building's long side, for about one building in
    /// four.
    fn park(&mut self, rng: &mut Rng) {
        let trees: Vec<(f64, f64)> = self
            .clutter
            .iter()
            .filter_map(|c| match *c {
                Clutter::Tree { at, .. } => Some(at),
                _ => None,
            })
            .collect();
        let mut cars = Vec::new();
        for k in 0..self.buildings.len() {
            if rng.next() >= 0.25 {
                continue;
            }
            let b = &self.buildings[k];
            let c = centroid(&b.ring);
            let (s, co) = b.ridge_azimuth_deg.to_radians().sin_cos();
            let along = (s, co);
            let side = if rng.next() < 0.5 { 1.0 } else { -1.0 };
            let across = (co * side, -s * side);
            // The wall's distance from the centroid across: the ring's extent that way.
            let reach = b
                .ring
                .iter()
                .map(|p| (p.0 - c.0) * across.0 + (p.1 - c.1) * across.1)
                .fold(f64::NEG_INFINITY, f64::max);
            let off = reach + rng.range(2.5, 6.0);
            let count = 2 + (rng.next() * 3.0) as usize;
            let (len, wid, hgt) = if rng.next() < 0.8 {
                (4.5, 1.8, 1.5)
            } else {
                (5.5, 2.0, 2.2)
            };
            let heading = 90.0 - b.ridge_azimuth_deg; // counter-clockwise from east
            for j in 0..count {
                let t = (j as f64 - (count as f64 - 1.0) / 2.0) * (len + 1.0);
                let at = (
                    c.0 + across.0 * off + along.0 * t,
                    c.1 + across.1 * off + along.1 * t,
                );
                let clear = self.clearance(at, 4.0) >= len / 2.0 + 0.5
                    && trees.iter().all(|o| (o.0 - at.0).hypot(o.1 - at.1) > 1.5)
                    && cars
                        .iter()
                        .all(|&(o, _): &((f64, f64), f64)| (o.0 - at.0).hypot(o.1 - at.1) > len);
                if clear {
                    cars.push((at, 0.0));
                    self.clutter.push(Clutter::Vehicle {
                        at,
                        size: (len, wid, hgt),
                        heading_deg: heading,
                    });
                }
            }
        }
    }

    /// Building `k` over the ground `ground` (absolute metres at a world point): absolute roof
    /// on the highest ground under its footprint.
    pub fn building(&self, k: usize, ground: &dyn Fn((f64, f64)) -> f64) -> PolygonBuilding {
        let b = &self.buildings[k];
        let top = b
            .ring
            .iter()
            .map(|&p| ground(p))
            .fold(f64::NEG_INFINITY, f64::max);
        let eave_z = top + b.eave_m;
        let ridge_z = eave_z + b.pitch_m;
        let roof = match b.form {
            "gable" => Roof::Gable { eave_z, ridge_z },
            "hip" => Roof::Hip { eave_z, ridge_z },
            _ => Roof::Flat { z: eave_z },
        };
        PolygonBuilding {
            outline: b.ring.clone(),
            roof,
            ridge_azimuth_deg: b.ridge_azimuth_deg,
            colour: b.colour,
            listed: true,
        }
    }
}

/// A footprint's bounding box: (min, max), metres.
pub fn bbox(r: &[(f64, f64)]) -> ((f64, f64), (f64, f64)) {
    r.iter().fold(
        (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        ),
        |(lo, hi), p| {
            (
                (lo.0.min(p.0), lo.1.min(p.1)),
                (hi.0.max(p.0), hi.1.max(p.1)),
            )
        },
    )
}

/// A square window of the town and how it is photographed.
#[derive(Debug, Clone, PartialEq)]
pub struct Shot {
    /// The window's south-west corner, EPSG:32613 metres. The buildings scored are those whose
    /// footprint's centroid falls inside ([`WindowScene::core`]).
    pub sw: (f64, f64),
    /// The window's side, metres.
    pub side: f64,
    /// Lit margin rendered around the window, metres (so the core's shadows and those cast
    /// into it from nearby are in the photo). Every building of the town is in the POV-Ray
    /// scene, so shadows from beyond the photo fall into it as they would.
    pub margin: f64,
    /// Cell, metres.
    pub cell: f64,
    /// Sun azimuth, degrees clockwise from grid north.
    pub sun_azimuth_deg: f64,
    /// Sun elevation, degrees.
    pub sun_elevation_deg: f64,
    /// Ground gradient: rise per metre east and north (the plane through [`TOWN_Z0`] at
    /// [`TOWN_SW`]).
    pub gradient: (f64, f64),
    /// The camera (a frame photo only on flat ground).
    pub camera: Camera,
    /// Footprints written moved by this, metres (east, north).
    pub footprint_shift: (f64, f64),
    /// Share of the photo's buildings left out of the footprint file (drawn from `seed`).
    pub unlisted: f64,
    /// Anti-aliasing, POV-Ray's n × n samples a pixel (`povray::antialias_for` of the sun,
    /// normally).
    pub antialias: u32,
    /// Seed of the draw of unlisted buildings.
    pub seed: u64,
}

/// A window's scene and which of its buildings are scored.
pub struct WindowScene {
    /// The scene: every building of the town (index = [`Town::buildings`]'), listed when any of
    /// it is in the photo (minus the [`Shot::unlisted`] ones); the clutter near the photo.
    pub scene: Scene<PolygonBuilding>,
    /// Buildings whose centroid is in the window (indices into `scene.buildings`).
    pub core: Vec<usize>,
}

/// The scene of `shot` over `town`.
pub fn window_scene(town: &Town, shot: &Shot) -> WindowScene {
    let cell = shot.cell;
    let west = ((shot.sw.0 - shot.margin) / cell).floor() * cell;
    let north = ((shot.sw.1 + shot.side + shot.margin) / cell).ceil() * cell;
    let n = ((shot.side + 2.0 * shot.margin) / cell).ceil() as usize + 1;
    let origin = (west, north);
    let (gx, gy) = shot.gradient;
    let ground = |p: (f64, f64)| TOWN_Z0 + gx * (p.0 - TOWN_SW.0) + gy * (p.1 - TOWN_SW.1);
    let (e, s) = (west + n as f64 * cell, north - n as f64 * cell);
    let mut rng = Rng(shot.seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut core = Vec::new();
    let buildings = (0..town.buildings.len())
        .map(|k| {
            let mut b = town.building(k, &ground);
            let (lo, hi) = bbox(&b.outline);
            let seen = hi.0 > west && lo.0 < e && hi.1 > s && lo.1 < north;
            let c = centroid(&b.outline);
            let is_core = c.0 >= shot.sw.0
                && c.0 < shot.sw.0 + shot.side
                && c.1 >= shot.sw.1
                && c.1 < shot.sw.1 + shot.side;
            let drop = rng.next() < shot.unlisted;
            b.listed = seen && !drop;
            if is_core && b.listed {
                core.push(k);
            }
            b
        })
        .collect();
    let near = 60.0;
    let clutter = town
        .clutter
        .iter()
        .filter(|c| {
            let at = match **c {
                Clutter::Tree { at, .. } | Clutter::Vehicle { at, .. } => at,
            };
            at.0 > west - near && at.0 < e + near && at.1 > s - near && at.1 < north + near
        })
        .copied()
        .collect();
    WindowScene {
        scene: Scene {
            origin,
            cell,
            size: (n, n),
            ground: (ground(origin), gx, gy),
            sun_azimuth_deg: shot.sun_azimuth_deg,
            sun_elevation_deg: shot.sun_elevation_deg,
            buildings,
            clutter,
            footprint_shift: shot.footprint_shift,
            camera: shot.camera,
            antialias: shot.antialias,
        },
        core,
    }
}

/// The scene's building `k` is listed (convenience for callers holding only the scene).
pub fn listed(scene: &Scene<PolygonBuilding>, k: usize) -> bool {
    scene.buildings[k].listed()
}

/// Every building's truth in `scene` as GeoJSON (EPSG:32613), its roof in dbms's own
/// property names (`dbms::roof::property`): `roof_z` (the top: the flat roof or the ridge,
/// absolute metres), `roof_form` (`flat`, `gable`, `hip`), and for a pitched roof `eave_z`
/// (absolute metres) and `roof_azimuth_deg` (the ridge, degrees clockwise from grid north, in
/// [0, 180)); also `id` (index in the town and the scene), `feature` (index in the footprint
/// file), `tower`, `listed`; the true (unshifted) footprint.
pub fn truth_geojson(town: &Town, scene: &Scene<PolygonBuilding>) -> String {
    let features: Vec<String> = scene
        .buildings
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let mut ring: Vec<[f64; 2]> = b.outline.iter().map(|p| [p.0, p.1]).collect();
            ring.push(ring[0]);
            let mut p = serde_json::json!({
                "id": k,
                "feature": town.buildings[k].feature,
                "roof_z": b.roof.top_z(),
                "roof_form": b.roof.form(),
                "tower": town.buildings[k].tower,
                "listed": b.listed,
            });
            if !matches!(b.roof, Roof::Flat { .. }) {
                p["eave_z"] = b.roof.eave_z().into();
                p["roof_azimuth_deg"] = b.ridge_azimuth_deg.into();
            }
            serde_json::json!({
                "type": "Feature",
                "properties": p,
                "geometry": { "type": "Polygon", "coordinates": [ring] },
            })
            .to_string()
        })
        .collect();
    format!(
        "{{\"type\":\"FeatureCollection\",\"crs\":{{\"type\":\"name\",\"properties\":{{\"name\":\"urn:ogc:def:crs:EPSG::32613\"}}}},\"features\":[\n{}\n]}}\n",
        features.join(",\n")
    )
}
