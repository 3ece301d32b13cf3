//! `dbms shadow-height` on a real town's layout photographed by POV-Ray (issue 39, item 4): the
//! CI slice of `cargo bench --bench shadow_height_town` (tests/support/town.rs: Boulder's real
//! footprints with drawn heights, flat, gable and hip roofs, towers, trees and vehicles). Two
//! 100 m windows at 0.5 m cells under a soft sun (the 0.53° disc as an area light), sRGB, one of
//! them JPEG-compressed; and checks of the harness itself: the soft sun has penumbrae as wide as
//! the solar disc predicts, and the pitched roofs POV-Ray renders follow the stated convention.
//!
//! The thresholds guard what today's dbms achieves (each is commented with the value measured
//! on 2026-11-28), not the goals: they fail when dbms gets worse here, or when the
//! harness stops making what it should.
//!
//! Needs `povray` on PATH (`apt-get install povray`); without it the test says so and passes,
//! except under CI (`CI` set), where it fails: `.ci/run` installs it.

#[path = "support/povray.rs"]
mod povray;
#[path = "support/shadow_truth.rs"]
mod shadow_truth;
#[path = "support/town.rs"]
mod town;

use povray::{Camera, Clutter, Photo, Roof, UTM13N_WKT};
use shadow_truth::{measure_prepared, prepare_scene_photo, Outcome, Prepared};
use std::path::Path;
use town::{window_scene, Shot, Town, WindowScene, TOWN_SIDE, TOWN_SW};

/// Window side, metres.
const SIDE: f64 = 100.0;

/// The slice's two windows, from the `SIDE` lattice over the town (from its south-west
/// corner), densest first: the densest whose core holds a tower, a gable and a hip roof, and the
/// densest other one holding a gable and a hip.
fn windows(town: &Town) -> Vec<(f64, f64)> {
    let n = (TOWN_SIDE / SIDE) as usize;
    let count = |sw: (f64, f64), want: &dyn Fn(&town::TownBuilding) -> bool| {
        town.buildings
            .iter()
            .filter(|b| {
                let c = town::centroid(&b.ring);
                c.0 >= sw.0 && c.0 < sw.0 + SIDE && c.1 >= sw.1 && c.1 < sw.1 + SIDE && want(b)
            })
            .count()
    };
    let mut lattice: Vec<(f64, f64)> = (0..n * n)
        .map(|k| {
            (
                TOWN_SW.0 + SIDE * (k % n) as f64,
                TOWN_SW.1 + SIDE * (k / n) as f64,
            )
        })
        .collect();
    lattice.sort_by_key(|&sw| std::cmp::Reverse(count(sw, &|_| true)));
    let mut out = Vec::new();
    for sw in lattice {
        let pitched = count(sw, &|b| b.form == "gable") > 0 && count(sw, &|b| b.form == "hip") > 0;
        if pitched && (!out.is_empty() || count(sw, &|b| b.tower) > 0) {
            out.push(sw);
            if out.len() == 2 {
                break;
            }
        }
    }
    out
}

/// A 0.5 m orthophoto of the `side`-metre window at `sw` (a lit `margin` around it) of the
/// flat town under a sun from `az` degrees, `el` high: footprints exact, every one listed (so
/// `seed` draws nothing), anti-aliased as the sun needs.
fn ortho_shot(sw: (f64, f64), side: f64, margin: f64, (az, el): (f64, f64), seed: u64) -> Shot {
    Shot {
        sw,
        side,
        margin,
        cell: 0.5,
        sun_azimuth_deg: az,
        sun_elevation_deg: el,
        gradient: (0.0, 0.0),
        camera: Camera::Ortho,
        footprint_shift: (0.0, 0.0),
        unlisted: 0.0,
        antialias: povray::antialias_for(el),
        seed,
    }
}

/// The bench's photo: the soft sun (the 0.53° disc as a 9 × 9 area light), sRGB, and JPEG at
/// quality `jpeg` if given.
fn soft_photo(jpeg: Option<u8>) -> Photo {
    Photo {
        sun_disc_deg: Some(0.53),
        area_samples: 9,
        srgb: true,
        jpeg_quality: jpeg,
        crs_wkt: UTM13N_WKT,
    }
}

/// A window photographed, ingested and measured ([`measure`]).
struct Measured {
    /// Where the scene, photo, database and heights are (removed when this is dropped).
    dir: tempfile::TempDir,
    prepared: Prepared,
    /// One outcome per listed building, in scene order.
    out: Vec<Outcome>,
    /// `dbms shadow-height`'s wall clock, seconds.
    secs: f64,
}

impl Measured {
    /// The outcomes of the buildings scored: those of the window's core.
    fn scored(&self, ws: &WindowScene) -> Vec<&Outcome> {
        self.out
            .iter()
            .filter(|o| ws.core.contains(&o.building))
            .collect()
    }
}

/// Photograph `ws` as `photo` into a new directory, ingest it and measure it.
fn measure(ws: &WindowScene, photo: &Photo) -> Measured {
    let dir = tempfile::tempdir().unwrap();
    let prepared = prepare_scene_photo(&ws.scene, dir.path(), photo).unwrap();
    let (out, secs) = measure_prepared(&ws.scene, &prepared).unwrap();
    Measured {
        dir,
        prepared,
        out,
        secs,
    }
}

#[test]
fn a_real_town_under_a_soft_sun_is_measured_as_well_as_today() {
    if !povray::available() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(root, 39).unwrap();
    let sws = windows(&town);
    assert_eq!(sws.len(), 2, "two windows with every roof form");
    let mut totals = (0usize, 0usize, 0usize, 0usize, 0usize); // scored, measured, within 1 m, flagged or null, silent gross
    let mut forms = [0usize; 3];
    let (mut trees, mut vehicles, mut towers) = (0, 0, 0);
    for (k, (sw, az, el, jpeg)) in [
        (sws[0], 150.0, 35.0, None),
        (sws[1], 210.0, 45.0, Some(80u8)),
    ]
    .into_iter()
    .enumerate()
    {
        let ws = window_scene(&town, &ortho_shot(sw, SIDE, 20.0, (az, el), k as u64));
        let (w, _, e, n) = ws.scene.extent();
        let s = n - (e - w);
        for c in &ws.scene.clutter {
            match *c {
                Clutter::Tree { at, .. } if at.0 > w && at.0 < e && at.1 > s && at.1 < n => {
                    trees += 1
                }
                Clutter::Vehicle { at, .. } if at.0 > w && at.0 < e && at.1 > s && at.1 < n => {
                    vehicles += 1
                }
                _ => {}
            }
        }
        for &b in &ws.core {
            forms[match ws.scene.buildings[b].roof {
                Roof::Flat { .. } => 0,
                Roof::Gable { .. } => 1,
                Roof::Hip { .. } => 2,
            }] += 1;
            towers += town.buildings[b].tower as usize;
        }
        let m = measure(&ws, &soft_photo(jpeg));
        let pov = std::fs::read_to_string(m.dir.path().join("scene.pov")).unwrap();
        assert!(pov.contains("area_light"), "a soft sun");
        if jpeg.is_some() {
            assert_eq!(m.prepared.written.ortho.extension().unwrap(), "jpg");
            assert!(m.dir.path().join("ortho.jgw").exists());
        }
        let (out, secs, scored) = (&m.out, m.secs, m.scored(&ws));
        let measured = scored.iter().filter(|o| o.roof_z.is_some()).count();
        let within = scored
            .iter()
            .filter(|o| o.error_m().is_some_and(|e| e.abs() <= 1.0))
            .count();
        let flagged = scored
            .iter()
            .filter(|o| o.flagged() || o.roof_z.is_none())
            .count();
        let silent = scored
            .iter()
            .filter(|o| !o.flagged() && o.error_m().is_some_and(|e| e.abs() > 1.0))
            .count();
        eprintln!(
            "window {k} at {sw:?}, sun {az}° / {el}°{}: {} footprints in the file, {} scored, {measured} measured, {within} within 1 m, {flagged} flagged or null, {silent} unflagged > 2 cells off; dbms {secs:.1} s",
            if jpeg.is_some() { ", JPEG q80" } else { "" },
            out.len(),
            scored.len()
        );
        totals.0 += scored.len();
        totals.1 += measured;
        totals.2 += within;
        totals.3 += flagged;
        totals.4 += silent;
    }
    eprintln!(
        "scored {} (flat {}, gable {}, hip {}, towers {}), trees {trees}, vehicles {vehicles}; measured {}, within 1 m {}, flagged or null {}, silent gross {}",
        totals.0, forms[0], forms[1], forms[2], towers, totals.1, totals.2, totals.3, totals.4
    );
    // Every feature is there.
    assert!(
        forms.iter().all(|&f| f > 0) && towers > 0,
        "{forms:?} {towers}"
    );
    assert!(
        trees >= 10 && vehicles >= 5,
        "{trees} trees, {vehicles} vehicles"
    );
    // What today's dbms achieves (commit a885019, 2026-11-28; the town and windows are fixed,
    // so these move only with dbms or the harness).
    let (n, measured, within) = (totals.0 as f64, totals.1 as f64, totals.2 as f64);
    // 40 buildings scored (20 + 20).
    assert!(n >= 36.0, "{n} buildings scored");
    // 36 of 40 measured (0.90).
    assert!(measured / n >= 0.80, "measured {measured} of {n}");
    // 23 of 40 within 1 m of the truth (0.575; the rest are mostly the pitched roofs, whose
    // ridge dbms does not measure yet, and shadows ending on neighbours).
    assert!(within / n >= 0.45, "within 1 m: {within} of {n}");
    // No unflagged height more than 2 cells off (0).
    assert!(totals.4 <= 1, "{} silent gross errors", totals.4);
}

/// A 12° sun from the south-west over the slice's densest window: in an sRGB photo the shadow
/// is barely darker than lit grass (0.82 of it) and the tree crowns and dark cars in it darker
/// still (0.72 of the shadow); Otsu split them off as the shadow and every scan line ended at
/// its first cell (the bench's two 150 m windows: `no_shadow` on 61 of 70, 62 with neither a
/// height nor a lower bound). The cells behind the walls say which split is the shadow: most
/// buildings get a height or a lower bound, no silent gross error, no lower bound above the
/// truth by more than two cells.
#[test]
fn a_twelve_degree_sun_gives_heights_or_lower_bounds() {
    if !povray::available() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(root, 39).unwrap();
    let (sw, el) = (windows(&town)[0], 12.0);
    let ws = window_scene(&town, &ortho_shot(sw, SIDE, 20.0, (225.0, el), 0));
    let m = measure(&ws, &soft_photo(None));
    let scored = m.scored(&ws);
    let n = scored.len();
    let no_shadow = scored
        .iter()
        .filter(|o| o.flags.iter().any(|f| f == "no_shadow"))
        .count();
    let numbered = scored
        .iter()
        .filter(|o| o.roof_z.is_some() || o.at_least().is_some())
        .count();
    let silent = scored
        .iter()
        .filter(|o| !o.flagged() && o.error_m().is_some_and(|e| e.abs() > 1.0))
        .count();
    let bound_above = scored
        .iter()
        .filter(|o| o.at_least().is_some_and(|z| z > o.truth_z + 1.0))
        .count();
    eprintln!(
        "sun 225° / {el}° at {sw:?}: {n} scored, {numbered} with a height or a lower bound, {no_shadow} no_shadow, {silent} silent gross, {bound_above} lower bounds above the truth"
    );
    assert!(n >= 15, "{n} buildings scored");
    assert!(
        2 * numbered >= n,
        "a height or a bound for {numbered} of {n}"
    );
    assert!(4 * no_shadow <= n, "no_shadow on {no_shadow} of {n}");
    assert_eq!(silent, 0, "silent gross errors");
    assert!(
        bound_above <= 1,
        "{bound_above} lower bounds above the truth"
    );
}

/// The bench's second 12° window (`shadow_height_town`, `az 225° · el 12°`, window 12 of the
/// 150 m lattice, its seed): the town nearly all shadow, the shadow only ~18 % darker than lit
/// grass, and the shaded grass's brightest patches as bright as the split (index 90–95 for a
/// threshold of 88.5). Scan lines ended on them: building 71 (17.3 m) came back 14.3 m low
/// from 10 lines ending 8–9 m out on one 7-cell patch, its 95 % interval 13.6 m below the
/// truth; 4 of the 33 buildings with a number had the truth outside it, 10 of the 17 heights
/// within 1 m. Lit specks ringed by a weak shadow are shadow (`shadow_height::specks`).
#[test]
fn a_twelve_degree_sun_s_shaded_grass_does_not_end_the_shadows() {
    if !povray::available() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(root, 39).unwrap();
    let el = 12.0;
    let sw = (TOWN_SW.0, TOWN_SW.1 + 450.0);
    let ws = window_scene(&town, &ortho_shot(sw, 150.0, 25.0, (225.0, el), 1041));
    let m = measure(&ws, &soft_photo(None));
    let scored = m.scored(&ws);
    // Truth outside the 95 % interval, or below the lower bound.
    let outside = |o: &shadow_truth::Outcome| match (o.roof_z, o.at_least()) {
        (Some(_), _) => o
            .pair("roof_z_interval_95")
            .is_some_and(|(lo, hi)| o.truth_z < lo || o.truth_z > hi),
        (None, Some(lo)) => o.truth_z < lo,
        (None, None) => false,
    };
    let numbered = scored
        .iter()
        .filter(|o| o.roof_z.is_some() || o.at_least().is_some())
        .count();
    let out95 = scored.iter().filter(|o| outside(o)).count();
    let heights = scored.iter().filter(|o| o.roof_z.is_some()).count();
    let within = scored
        .iter()
        .filter(|o| o.error_m().is_some_and(|e| e.abs() <= 1.0))
        .count();
    eprintln!(
        "sun 225° / {el}°: {} scored, {numbered} numbered, truth outside the 95 % interval for {out95}, {within} of {heights} heights within 1 m",
        scored.len()
    );
    let b71 = scored
        .iter()
        .find(|o| o.building == 71)
        .expect("building 71 scored");
    assert!(!outside(b71), "building 71: {:?}", b71.properties);
    assert!(10 * out95 <= numbered, "{out95} of {numbered} outside");
    assert!(
        10 * within >= 7 * heights,
        "{within} of {heights} within 1 m"
    );
}

/// The roof planes written for POV-Ray, as (a, b, c, d) of `a x + b y + c z = d` (local x east,
/// y up, z north; the solid is below every plane).
fn planes(pov: &str) -> Vec<[f64; 4]> {
    pov.lines()
        .filter_map(|l| {
            let l = l.trim().strip_prefix("plane { <")?.strip_suffix(" }")?;
            let v: Vec<f64> = l
                .replace(['<', '>'], "")
                .split(',')
                .map(|x| x.trim().parse().unwrap())
                .collect();
            Some([v[0], v[1], v[2], v[3]])
        })
        .collect()
}

/// Height of the roof written for POV-Ray at local point (x, z): the lowest plane there.
fn pov_roof(planes: &[[f64; 4]], x: f64, z: f64, top: f64) -> f64 {
    planes
        .iter()
        .map(|p| (p[3] - p[0] * x - p[2] * z) / p[1])
        .fold(top, f64::min)
}

#[test]
fn pitched_roofs_follow_the_stated_convention() {
    use povray::{Building, PolygonBuilding, Rng, Scene, Structure};
    // The roof POV-Ray renders (its half-spaces) is the convention's formula
    // (PolygonBuilding::roof_z_at) at every point of the footprint, for the town's pitched
    // roofs, and so is dbms's own (dbms::roof::RoofShape, from the truth file's properties);
    // and a rectangle's Gable/Hip (rotation_deg from east) is the same roof as the
    // polygon one with the ridge azimuth 90° − rotation_deg.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(root, 39).unwrap();
    let origin = (TOWN_SW.0, TOWN_SW.1 + TOWN_SIDE);
    let scene = |buildings: Vec<PolygonBuilding>| Scene {
        origin,
        cell: 1.0,
        size: (600, 600),
        ground: (1630.0, 0.0, 0.0),
        sun_azimuth_deg: 135.0,
        sun_elevation_deg: 40.0,
        buildings,
        clutter: vec![],
        footprint_shift: (0.0, 0.0),
        camera: Camera::Ortho,
        antialias: 1,
    };
    let mut rng = Rng(5);
    let mut checked = 0;
    for k in 0..town.buildings.len() {
        if town.buildings[k].form == "flat" {
            continue;
        }
        let b = town.building(k, &|_| 1630.0);
        let s = scene(vec![b.clone()]);
        let pl = planes(&b.pov(&s));
        let (lo, hi) = town::bbox(&b.outline);
        let mut n = 0;
        while n < 50 {
            let p = (rng.range(lo.0, hi.0), rng.range(lo.1, hi.1));
            if !town::inside(&b.outline, p) {
                continue;
            }
            n += 1;
            let want = b.roof_z_at(p);
            let got = pov_roof(&pl, p.0 - origin.0, p.1 - origin.1, b.roof.top_z());
            assert!(
                (want - got).abs() < 1e-4, // 9 decimals in the POV file
                "building {k} at {p:?}: {want} vs {got}"
            );
            assert!(want <= b.roof.top_z() + 1e-9 && want >= b.roof.eave_z() - 1e-9);
        }
        checked += 1;
    }
    assert!(checked > 100, "{checked} pitched roofs");
    // dbms's own statement of the same roofs (dbms::roof, read from the truth file's
    // properties as the buildings layer would be) gives the same heights.
    let ws = window_scene(
        &town,
        &Shot {
            sw: TOWN_SW,
            side: TOWN_SIDE,
            margin: 0.0,
            cell: 1.0,
            sun_azimuth_deg: 135.0,
            sun_elevation_deg: 40.0,
            gradient: (0.02, -0.01),
            camera: Camera::Ortho,
            footprint_shift: (0.0, 0.0),
            unlisted: 0.0,
            antialias: 1,
            seed: 0,
        },
    );
    let truth: serde_json::Value =
        serde_json::from_str(&town::truth_geojson(&town, &ws.scene)).unwrap();
    let mut pitched = 0;
    for (f, b) in truth["features"]
        .as_array()
        .unwrap()
        .iter()
        .zip(&ws.scene.buildings)
    {
        let p = &f["properties"];
        let top = p["roof_z"].as_f64().unwrap();
        let pitch = dbms::roof::Pitch::from_properties(p, top).unwrap();
        pitched += pitch.is_some() as usize;
        let shape = dbms::roof::RoofShape::new(std::slice::from_ref(&b.outline), top, pitch);
        let (lo, hi) = town::bbox(&b.outline);
        let mut n = 0;
        while n < 20 {
            let q = (rng.range(lo.0, hi.0), rng.range(lo.1, hi.1));
            if !town::inside(&b.outline, q) {
                continue;
            }
            n += 1;
            let (ours, theirs) = (b.roof_z_at(q), shape.z_at(q));
            assert!(
                (ours - theirs).abs() < 1e-6,
                "{p}: at {q:?} the harness says {ours}, dbms::roof {theirs}"
            );
        }
    }
    assert_eq!(pitched, checked, "every pitched roof stated to dbms");
    for (rot, roof) in [
        (
            30.0,
            Roof::Gable {
                eave_z: 10.0,
                ridge_z: 13.0,
            },
        ),
        (
            -70.0,
            Roof::Hip {
                eave_z: 10.0,
                ridge_z: 12.0,
            },
        ),
    ] {
        let r = Building {
            centre: (origin.0 + 50.0, origin.1 - 50.0),
            size: (18.0, 9.0),
            rotation_deg: rot,
            roof,
            colour: [0.5; 3],
        };
        let p = PolygonBuilding {
            outline: r.corners().to_vec(),
            roof,
            ridge_azimuth_deg: (90.0 - rot).rem_euclid(180.0),
            colour: [0.5; 3],
            listed: true,
        };
        let s = scene(vec![p.clone()]);
        let (pr, pp) = (planes(&r.pov(&s)), planes(&p.pov(&s)));
        for _ in 0..200 {
            let q = (
                origin.0 + 50.0 + rng.range(-9.0, 9.0),
                origin.1 - 50.0 + rng.range(-9.0, 9.0),
            );
            let (x, z) = (q.0 - origin.0, q.1 - origin.1);
            let (a, b) = (pov_roof(&pr, x, z, 13.0), pov_roof(&pp, x, z, 13.0));
            assert!(
                (a - b).abs() < 1e-4,
                "{roof:?} at {q:?}: rectangle {a}, polygon {b}"
            );
        }
    }
}

#[test]
fn the_soft_sun_casts_penumbrae_as_wide_as_the_solar_disc_predicts() {
    if !povray::available() {
        return;
    }
    use povray::{Building, Scene};
    // A 40 m tower under a 30° sun from the south, 0.2 m cells: the shadow's tip is 80 m of ray
    // from the roof edge, so the 0.53° disc blurs it over 80 · 0.00925 / sin 30° = 1.48 m of
    // ground, 7.4 cells. The same scene under the hard sun and the soft one differ only there
    // (the ground texture is the same): count the cells along the shadow's axis where they
    // differ by more than a tenth of the lit-to-shadow contrast.
    let scene = Scene {
        origin: (500_000.0, 5_300_100.0),
        cell: 0.2,
        size: (500, 500),
        ground: (250.0, 0.0, 0.0),
        sun_azimuth_deg: 180.0,
        sun_elevation_deg: 30.0,
        buildings: vec![Building {
            centre: (500_050.0, 5_300_015.0),
            size: (6.0, 6.0),
            rotation_deg: 0.0,
            roof: Roof::Flat { z: 290.0 },
            colour: [0.5, 0.5, 0.5],
        }],
        clutter: vec![],
        footprint_shift: (0.0, 0.0),
        camera: Camera::Ortho,
        antialias: 1,
    };
    let column = |soft: bool| -> Vec<f64> {
        let dir = tempfile::tempdir().unwrap();
        let photo = Photo {
            sun_disc_deg: soft.then_some(0.53),
            ..Photo::default()
        };
        let w = scene.write_photo(dir.path(), &photo).unwrap();
        let img = image::open(&w.ortho).unwrap().to_luma8();
        // Column x = 500 050 (col 250), rows y = 5 300 099 … 5 300 030 (north to south).
        (5..355)
            .map(|r| img.get_pixel(250, r).0[0] as f64)
            .collect()
    };
    let (hard, soft) = (column(false), column(true));
    // Contrast: lit (the first rows, north of the tip at 5 300 087.3) over shadow (the last).
    let lit = hard[..40].iter().sum::<f64>() / 40.0;
    let dark = hard[hard.len() - 40..].iter().sum::<f64>() / 40.0;
    assert!(lit > 1.5 * dark, "lit {lit}, shadow {dark}");
    let differ: Vec<usize> = (0..hard.len())
        .filter(|&i| (soft[i] - hard[i]).abs() > 0.1 * (lit - dark))
        .collect();
    eprintln!(
        "lit {lit:.0}, shadow {dark:.0}; soft differs from hard at {} cells: {differ:?}",
        differ.len()
    );
    // Measured 2026-11-28: 5 cells, contiguous at the tip. The disc predicts 7.4 cells of
    // blur, of which the outer parts differ by less than a tenth.
    assert!(
        (3..=12).contains(&differ.len()),
        "penumbra {} cells",
        differ.len()
    );
    assert!(
        differ.last().unwrap() - differ[0] < 15,
        "the differences are one penumbra: {differ:?}"
    );
}

/// A hip roof pitched below the sun casts its eaves' shadow whatever its rise but where a jog
/// in its outline stands inside the roof's rectangle (there the roof meets the wall above the
/// eaves): building 21 of the town (a 15 × 10.6 m hip pitched 32°) under a 70° sun from 250°,
/// as in the bench's `az 250° · el 70°` setting. Its shadow alone chose a rise of 5.2 m (a
/// 44° pitch, seen on about 20 cells along the jog: one step of shadow as height is 1.4 m
/// there), the ridge 1.4–1.8 m high; its faces tell 33.7° (3.5 m). With the two combined by
/// their errors, the ridge comes within two cells, inside its 95 % interval.
#[test]
fn a_hip_below_a_high_sun_takes_its_rise_from_its_faces() {
    if !povray::available() {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(root, 39).unwrap();
    let shot = ortho_shot((476_169.0, 4_428_498.0), 40.0, 20.0, (250.0, 70.0), 0);
    let ws = window_scene(&town, &shot);
    assert!(ws.core.contains(&21), "building 21 in the window");
    let m = measure(&ws, &soft_photo(None));
    let tol = 2.0 * shot.cell;
    for o in m.scored(&ws) {
        let pitched = !matches!(ws.scene.buildings[o.building].roof, Roof::Flat { .. });
        eprintln!(
            "building {}: truth {:.2}, roof_z {:?}, 95 % {}, form {}, flags {:?}",
            o.building,
            o.truth_z,
            o.roof_z,
            o.properties["roof_z_interval_95"],
            o.properties["roof_form"],
            o.flags
        );
        if pitched && !o.flagged() {
            assert!(
                o.error_m().is_some_and(|e| e.abs() <= tol),
                "silently wrong: {o:?}"
            );
        }
        if o.building == 21 {
            assert!(o.error_m().is_some_and(|e| e.abs() <= tol), "{o:?}");
            let (lo, hi) = o.pair("roof_z_interval_95").expect("a 95 % interval");
            assert!((lo..=hi).contains(&o.truth_z), "{o:?}");
        }
    }
}

/// A frame camera: its nadir (world metres) and its height above the ground, metres.
type Camera500 = ((f64, f64), f64);

/// The bench's 500 m setting, its first window (`cargo bench --bench shadow_height_town --
/// frame`, row 15, window 0): footprints exact, the nadir 300 m south-west of the window's
/// centre, so every building leans north-east. Returns the window's south-west corner, its
/// scene, and the nadir (world metres) with the camera's height above the ground, metres.
fn frame_500_m_window() -> ((f64, f64), WindowScene, Camera500) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(root, 39).unwrap();
    let sw = (TOWN_SW.0 + 450.0, TOWN_SW.1 + 450.0);
    let nadir = (sw.0 + 75.0 - 212.0, sw.1 + 75.0 - 212.0);
    let shot = Shot {
        camera: Camera::Perspective {
            nadir,
            height_m: 500.0,
        },
        ..ortho_shot(sw, 150.0, 25.0, (135.0, 40.0), 1150)
    };
    (sw, window_scene(&town, &shot), (nadir, 500.0))
}

#[test]
fn a_frame_photo_from_500_m_keeps_exact_footprints_in_place_and_meets_the_leans() {
    if !povray::available() {
        return;
    }
    // The 500 m window ([`frame_500_m_window`]). A few clear registration estimates on a
    // neighbour's edges (2–4 m across their lean) once tilted the scene's shift to (1.6, 1.0) m
    // along the leans: every footprint moved 1.9 m, most flagged `footprint_off_photo`, the
    // heights wrong. Now the shift stays within a cell of none, and the roofs the lean measures
    // precisely meet the shadow's height.
    let (sw, ws, _) = frame_500_m_window();
    let m = measure(&ws, &soft_photo(None));
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(m.prepared.written.dir.join("heights.geojson")).unwrap(),
    )
    .unwrap();
    let g = &v["footprint_shift"];
    let g = (
        g["east_m"].as_f64().unwrap_or(0.0),
        g["north_m"].as_f64().unwrap_or(0.0),
    );
    let scored = m.scored(&ws);
    let n = scored.len();
    let within = scored
        .iter()
        .filter(|o| o.error_m().is_some_and(|e| e.abs() <= 1.0))
        .count();
    let silent = scored
        .iter()
        .filter(|o| !o.flagged() && o.error_m().is_some_and(|e| e.abs() > 1.0))
        .count();
    eprintln!(
        "500 m at {sw:?}: scene shift ({:.2}, {:.2}) m, {n} scored, {within} within 1 m, {silent} silent gross",
        g.0, g.1
    );
    assert!(
        g.0.hypot(g.1) <= 0.5,
        "scene shift {g:?} for exact footprints"
    );
    assert!(n >= 20, "{n} buildings scored");
    // 2026-11-29: 25 of 41 (before the consensus and the lean's height, the shift 1.9 m off: 6).
    assert!(2 * within >= n, "{within} of {n} within 1 m");
    assert_eq!(silent, 0, "silent gross errors");
}

#[test]
fn a_frame_photo_from_500_m_registers_footprints_on_their_leaning_roofs() {
    if !povray::available() {
        return;
    }
    // The 500 m window ([`frame_500_m_window`]): a roof `h` above the ground at `r` from the
    // nadir is seen `r·h / (Z − h)` radially outward, the eaves' lean up to the ridge's. The
    // broad search along each lean once latched on a neighbour's edges 2–4 m across it, or on
    // another building 40–100 m along it: 19 of 41 footprints registered on their roofs, 21
    // flagged `footprint_off_photo` (their shadows mostly measured right). Those are now sought
    // again along their leans alone: 2026-11-29, 22 on their roofs, 14 flagged (still: roofs
    // matched 35–100 m along the lean; the goal is every one on its roof).
    let (_, ws, (nadir, z)) = frame_500_m_window();
    let m = measure(&ws, &soft_photo(None));
    let cell = ws.scene.cell;
    let scored = m.scored(&ws);
    let n = scored.len();
    let (mut on_roof, mut off) = (0, 0);
    for o in &scored {
        let b = &ws.scene.buildings[o.building];
        let (x0, y0, x1, y1) = b.outline.iter().fold(
            (
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ),
            |a, p| (a.0.min(p.0), a.1.min(p.1), a.2.max(p.0), a.3.max(p.1)),
        );
        let (dx, dy) = ((x0 + x1) / 2.0 - nadir.0, (y0 + y1) / 2.0 - nadir.1);
        let r = dx.hypot(dy);
        let ground = ws.scene.ground.0;
        let lean = |top: f64| r * (top - ground) / (z - (top - ground));
        let own = &o.properties["own_shift_m"];
        let (e, nn) = (own["east"].as_f64(), own["north"].as_f64());
        let right = e.zip(nn).is_some_and(|(e, nn)| {
            let along = (e * dx + nn * dy) / r;
            let across = (nn * dx - e * dy) / r;
            across.abs() <= cell
                && along >= lean(b.roof.eave_z()) - cell
                && along <= lean(b.roof.top_z()) + cell
        });
        let flagged_off = o.flags.iter().any(|f| f == "footprint_off_photo");
        on_roof += usize::from(right);
        off += usize::from(flagged_off);
        eprintln!(
            "{} own ({:?}, {:?}) eaves lean {:.2} ridge {:.2} right {right} off {flagged_off} truth {:.2} roof {:?} {:?}",
            o.building,
            e,
            nn,
            lean(b.roof.eave_z()),
            lean(b.roof.top_z()),
            o.truth_z,
            o.roof_z,
            o.flags
        );
    }
    eprintln!(
        "500 m: {on_roof} of {n} registered on their roofs, {off} flagged footprint_off_photo"
    );
    assert!(2 * on_roof >= n, "{on_roof} of {n} on their roofs");
    assert!(5 * off <= 2 * n, "{off} of {n} flagged footprint_off_photo");
}
