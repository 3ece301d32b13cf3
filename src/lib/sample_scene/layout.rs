//! Where the sample's roads and buildings go: a square grid of 36 m lots with roads along two
//! lot boundaries; some lots hold a building (a rectangle, an adjacent pair sharing a wall, or an
//! L-shape) or a house with a pitched roof (gable or hip). Coordinates here are local metres
//! from the scene's south-west corner, snapped to 0.25 m so no orthophoto or DEM cell centre
//! lies exactly on a wall (a house's sides to 0.5 m, so its ridge lies on orthophoto cell
//! edges too).

use super::noise::{mix, Rng};
use crate::roof::RoofForm;

/// Distance between lot boundaries, metres.
const LOT_PITCH: f64 = 36.0;
/// Clear strip inside each lot edge, metres: roads (half-width 3 m) run in it.
const LOT_MARGIN: f64 = 5.0;
/// Road half-width, metres.
pub const ROAD_HALF_WIDTH: f64 = 3.0;
/// Coordinates are multiples of this, metres.
const SNAP: f64 = 0.25;
/// Most lots that get buildings.
const MAX_LOTS: usize = 20;

/// A straight road across the whole scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Road {
    /// True for a north–south road (its centre is an x), false for east–west (a y).
    pub north_south: bool,
    /// Centre line, local metres.
    pub centre: f64,
}

impl Road {
    /// Signed distance (metres) across the road from its centre line to local point `(x, y)`,
    /// and the distance along it.
    pub fn local(&self, x: f64, y: f64) -> (f64, f64) {
        if self.north_south {
            (x - self.centre, y)
        } else {
            (y - self.centre, x)
        }
    }
}

/// The kind of footprint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    /// A lone rectangle.
    Rectangle,
    /// A rectangle sharing one wall with another of a different height.
    Adjacent,
    /// An L: a rectangle with one corner notched out.
    LShape,
}

/// A planned building: footprint and height, before it meets the terrain.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedBuilding {
    /// Exterior ring, local metres, counter-clockwise, not closed.
    pub ring: Vec<(f64, f64)>,
    /// Kind of footprint.
    pub shape: Shape,
    /// Flat roof (a pitched roof's eaves) above the highest ground under the footprint, metres.
    pub height_m: f64,
    /// Roof colour.
    pub roof: [u8; 3],
    /// A house's pitched roof; `None` for a flat roof.
    pub pitch: Option<HouseRoof>,
}

/// A house's pitched roof, before it meets the terrain (its eaves are the building's
/// `height_m`; the ridge follows from the pitch and the footprint's width across the ridge).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HouseRoof {
    /// Gable or hip.
    pub form: RoofForm,
    /// The roof planes' pitch, degrees above the horizontal.
    pub pitch_deg: f64,
    /// The ridge's direction, degrees clockwise from grid north (0 or 90: along the long side).
    pub azimuth_deg: f64,
}

/// A house's eaves above the highest ground: two storeys, metres (range, step).
const HOUSE_EAVES_M: (f64, f64, f64) = (5.5, 7.0, 0.5);
/// A house's sides, metres: along the ridge and across it (ranges), in steps of `HOUSE_STEP`.
const HOUSE_LENGTH_M: (f64, f64) = (10.0, 14.0);
/// See [`HOUSE_LENGTH_M`].
const HOUSE_WIDTH_M: (f64, f64) = (8.0, 10.5);
/// Step of a house's sides, metres: its ridge (the middle) lies on a multiple of `SNAP`.
const HOUSE_STEP: f64 = 0.5;
/// A house's roof pitch, degrees (range, whole degrees).
const HOUSE_PITCH_DEG: (f64, f64) = (30.0, 41.0);

/// Roof colours: terracotta, slate, tar, concrete, weathered copper.
pub const ROOFS: [[u8; 3]; 5] = [
    [156, 74, 58],
    [96, 98, 108],
    [62, 60, 64],
    [176, 172, 160],
    [104, 140, 120],
];

/// Lots per side and the offset of the lot grid for a square scene `extent` metres wide.
fn lot_grid(extent: f64) -> (usize, f64) {
    let n = (extent / LOT_PITCH).floor() as usize;
    let offset = ((extent - n as f64 * LOT_PITCH) / 2.0 / SNAP).floor() * SNAP;
    (n, offset)
}

/// The two roads of a scene `extent` metres wide: on lot boundaries, so they never cross a lot.
pub fn roads(extent: f64) -> Vec<Road> {
    let (n, offset) = lot_grid(extent);
    let at = |k: usize| offset + k.clamp(1, n.max(2) - 1) as f64 * LOT_PITCH;
    vec![
        Road {
            north_south: true,
            centre: at(n / 2),
        },
        Road {
            north_south: false,
            centre: at(n / 3),
        },
    ]
}

/// Buildings for a scene `extent` metres wide: about one lot in ten (at least 4 when there are
/// 4 lots, at most [`MAX_LOTS`]); the first chosen lot holds the L-shape, every fourth an
/// adjacent pair, the second and every fourth after it a gable-roofed house, the fourth and
/// every fourth after it a hip-roofed house, the others a flat-roofed rectangle. A house draws
/// its footprint, eaves and colour from the same stream as the rectangle it replaces (one
/// value each), and its pitch and ridge from a stream of its own, so the other lots are the
/// same whatever the houses are.
pub fn buildings(seed: u64, extent: f64) -> Vec<PlannedBuilding> {
    let (n, offset) = lot_grid(extent);
    let mut rng = Rng::new(seed);
    let mut lots: Vec<(usize, usize)> = (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect();
    rng.shuffle(&mut lots);
    let count = ((lots.len() as f64 * 0.1).round() as usize)
        .max(lots.len().min(4))
        .min(MAX_LOTS);
    let mut plans = Vec::new();
    for (k, &(i, j)) in lots[..count].iter().enumerate() {
        let x0 = offset + i as f64 * LOT_PITCH + LOT_MARGIN;
        let y0 = offset + j as f64 * LOT_PITCH + LOT_MARGIN;
        let room = LOT_PITCH - 2.0 * LOT_MARGIN;
        let height = |rng: &mut Rng| rng.stepped(3.0, 25.0, 0.5);
        let roof = |rng: &mut Rng| ROOFS[(rng.next_u64() % ROOFS.len() as u64) as usize];
        if k == 0 {
            let (w, d) = (rng.stepped(14.0, room, SNAP), rng.stepped(14.0, room, SNAP));
            let (wn, dn) = (
                rng.stepped(6.0, w - 6.0, SNAP),
                rng.stepped(6.0, d - 6.0, SNAP),
            );
            let ring = vec![
                (x0, y0),
                (x0 + w, y0),
                (x0 + w, y0 + d - dn),
                (x0 + w - wn, y0 + d - dn),
                (x0 + w - wn, y0 + d),
                (x0, y0 + d),
            ];
            plans.push(PlannedBuilding {
                ring,
                shape: Shape::LShape,
                height_m: height(&mut rng),
                roof: roof(&mut rng),
                pitch: None,
            });
        } else if k % 4 == 2 {
            let (w1, w2) = (rng.stepped(7.0, 12.0, SNAP), rng.stepped(7.0, 12.0, SNAP));
            let (d1, d2) = (rng.stepped(8.0, 16.0, SNAP), rng.stepped(8.0, 16.0, SNAP));
            let h1 = height(&mut rng);
            // The neighbour differs by at least 3 m, so the shared wall casts a shadow step.
            let h2 = if h1 > 14.0 {
                h1 - rng.stepped(3.0, h1 - 3.0, 0.5)
            } else {
                h1 + rng.stepped(3.0, 25.0 - h1, 0.5)
            };
            plans.push(PlannedBuilding {
                ring: rectangle(x0, y0, w1, d1),
                shape: Shape::Adjacent,
                height_m: h1,
                roof: roof(&mut rng),
                pitch: None,
            });
            plans.push(PlannedBuilding {
                ring: rectangle(x0 + w1, y0, w2, d2),
                shape: Shape::Adjacent,
                height_m: h2,
                roof: roof(&mut rng),
                pitch: None,
            });
        } else if k % 2 == 1 {
            let form = if k % 4 == 1 {
                RoofForm::Gable
            } else {
                RoofForm::Hip
            };
            plans.push(house(&mut rng, mix(seed ^ k as u64), form, (x0, y0), room));
        } else {
            let (w, d) = (rng.stepped(8.0, 20.0, SNAP), rng.stepped(8.0, 16.0, SNAP));
            let (dx, dy) = (
                rng.stepped(0.0, room - w, SNAP),
                rng.stepped(0.0, room - d, SNAP),
            );
            plans.push(PlannedBuilding {
                ring: rectangle(x0 + dx, y0 + dy, w, d),
                shape: Shape::Rectangle,
                height_m: height(&mut rng),
                roof: roof(&mut rng),
                pitch: None,
            });
        }
    }
    plans
}

/// A two-storey house with a `form` roof in the lot whose free square (`room` metres wide)
/// starts at local `(x0, y0)`: its sides, position, eaves and colour take one value each from
/// `rng` (as many as a flat rectangle takes), its pitch and ridge direction come from
/// `own_seed`. The ridge runs along the longer side; its roof is tiles (terracotta or slate).
fn house(
    rng: &mut Rng,
    own_seed: u64,
    form: RoofForm,
    (x0, y0): (f64, f64),
    room: f64,
) -> PlannedBuilding {
    let length = rng.stepped(HOUSE_LENGTH_M.0, HOUSE_LENGTH_M.1, HOUSE_STEP);
    let width = rng.stepped(HOUSE_WIDTH_M.0, HOUSE_WIDTH_M.1, HOUSE_STEP);
    let mut own = Rng::new(own_seed);
    let ridge_north = own.next_u64().is_multiple_of(2);
    let pitch_deg = own.stepped(HOUSE_PITCH_DEG.0, HOUSE_PITCH_DEG.1, 1.0);
    let (w, d) = if ridge_north {
        (width, length)
    } else {
        (length, width)
    };
    let (dx, dy) = (
        rng.stepped(0.0, room - w, HOUSE_STEP),
        rng.stepped(0.0, room - d, HOUSE_STEP),
    );
    let (lo, hi, step) = HOUSE_EAVES_M;
    PlannedBuilding {
        ring: rectangle(x0 + dx, y0 + dy, w, d),
        shape: Shape::Rectangle,
        height_m: rng.stepped(lo, hi, step),
        roof: ROOFS[(rng.next_u64() % 2) as usize],
        pitch: Some(HouseRoof {
            form,
            pitch_deg,
            azimuth_deg: if ridge_north { 0.0 } else { 90.0 },
        }),
    }
}

/// Counter-clockwise ring of an axis-aligned rectangle.
fn rectangle(x0: f64, y0: f64, w: f64, d: f64) -> Vec<(f64, f64)> {
    vec![(x0, y0), (x0 + w, y0), (x0 + w, y0 + d), (x0, y0 + d)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(ring: &[(f64, f64)]) -> f64 {
        (0..ring.len())
            .map(|i| {
                let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                a.0 * b.1 - b.0 * a.1
            })
            .sum::<f64>()
            / 2.0
    }

    #[test]
    fn buildings_fit_their_lots_avoid_roads_and_span_the_shapes() {
        let extent = 512.0;
        let plans = buildings(42, extent);
        let roads = roads(extent);
        assert!((10..=30).contains(&plans.len()), "{}", plans.len());
        for s in [Shape::Rectangle, Shape::Adjacent, Shape::LShape] {
            assert!(plans.iter().any(|p| p.shape == s), "{s:?}");
        }
        for p in &plans {
            assert!(area(&p.ring) > 50.0, "counter-clockwise and not tiny");
            assert!((3.0..=25.0).contains(&p.height_m));
            for &(x, y) in &p.ring {
                assert!(x > 0.0 && y > 0.0 && x < extent && y < extent);
                assert_eq!((x / SNAP).fract(), 0.0);
                for r in &roads {
                    assert!(
                        r.local(x, y).0.abs() > ROAD_HALF_WIDTH + 1.0,
                        "{p:?} on {r:?}"
                    );
                }
            }
        }
        assert_ne!(plans, buildings(43, extent));
        assert_eq!(plans, buildings(42, extent));
        assert_eq!(
            buildings(1, 128.0).len(),
            5,
            "4 lots: L, rectangle, pair, rectangle"
        );
    }
}
