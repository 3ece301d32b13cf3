//! The moon module against references nobody here made: Meeus's worked examples and PyEphem.

use super::*;
use crate::sun::parse_time;
use chrono::{Duration, TimeZone};
use proptest::prelude::*;

fn at(s: &str) -> DateTime<Utc> {
    parse_time(s).unwrap()
}

fn obs(latitude_deg: f64, longitude_deg: f64, height_m: f64) -> Observer {
    Observer {
        latitude_deg,
        longitude_deg,
        height_m,
    }
}

fn airless(delta_t_s: Option<f64>) -> MoonOptions {
    MoonOptions {
        refraction: false,
        delta_t_s,
        ..MoonOptions::default()
    }
}

/// Meeus example 48.a through the public API: 1992 April 12, 0h TD (ΔT = 0 makes UTC = TT).
/// The book gives k = 0.6786 (its Sun from ch. 25; ours is the SPA's, within 0.01″ of it).
#[test]
fn meeus_example_48a_fraction() {
    let p = moon_position(
        &obs(0.0, 0.0, 0.0),
        at("1992-04-12T00:00:00Z"),
        &airless(Some(0.0)),
    )
    .unwrap();
    assert!((p.illuminated_fraction - 0.6786).abs() < 5e-5, "{p:?}");
    assert!((p.phase_angle_deg - 69.0756).abs() < 2e-3, "{p:?}");
}

/// PyEphem 4.2.1 (`pip install ephem==4.2.1`; libastro's own lunar theory, no code shared with
/// Meeus ch. 47 here), generated once by a script whose essence is:
///
/// ```text
/// o = ephem.Observer(); o.date = T; o.lat = str(LAT); o.lon = str(LON); o.elevation = H
/// o.pressure = 0                       # airless: no refraction
/// m = ephem.Moon(); m.compute(o)       # alt/az are apparent topocentric
/// row = (T, LAT, LON, H, ephem.delta_t(o.date), deg(m.alt), deg(m.az), m.phase / 100)
/// ```
///
/// 18 random sites (heights 0–4000 m) and times over 1950–2050 (seed 18), then the North and
/// South Poles, the date line from both sides, 70° N, the Moon 0.7° above the horizon (Munich,
/// found by scanning) and 0.7° from the zenith (25° N near the 2006 major lunar standstill).
/// Columns: UTC, latitude, longitude, height m, PyEphem's ΔT s, elevation, azimuth, fraction.
type EphemCase = (&'static str, f64, f64, f64, f64, f64, f64, f64);
const PYEPHEM: [EphemCase; 25] = [
    (
        "1973-02-22T14:21:15Z",
        -51.3503,
        -3.7745,
        1976.1,
        43.53641763793692,
        -17.209131189352565,
        207.86392565256344,
        0.7334620666503906,
    ),
    (
        "2011-05-15T08:12:16Z",
        67.8697,
        -137.52,
        2088.4,
        66.4191351505828,
        6.448635593068798,
        196.57224325632,
        0.9348629760742188,
    ),
    (
        "2047-03-28T07:10:15Z",
        -50.9616,
        -48.4071,
        2031.0,
        102.87229056893489,
        -41.93215348463615,
        122.01839254093468,
        0.031331686973571776,
    ),
    (
        "2036-08-07T22:19:16Z",
        -83.8673,
        171.2447,
        881.8,
        85.67368693935029,
        8.603546188942659,
        223.36625574757963,
        0.9940934753417969,
    ),
    (
        "2043-07-18T11:37:36Z",
        4.5451,
        117.1904,
        2399.7,
        96.37817399419096,
        49.92031926615453,
        144.93647758388718,
        0.8722901153564453,
    ),
    (
        "1988-09-04T09:30:36Z",
        71.9021,
        -127.7272,
        2735.7,
        56.14194381633825,
        26.910450141135414,
        82.51774200459347,
        0.3745872497558594,
    ),
    (
        "2030-03-07T06:41:43Z",
        52.128,
        -132.7074,
        2053.9,
        77.76338260626783,
        -5.620897774159647,
        297.0742694965289,
        0.08991052627563477,
    ),
    (
        "2023-02-23T06:37:16Z",
        5.8161,
        -57.7314,
        3246.3,
        71.61360906251443,
        -80.05321850675611,
        359.14364089977647,
        0.12198922157287598,
    ),
    (
        "2034-09-16T02:31:09Z",
        -3.8149,
        -3.78,
        998.3,
        83.1296466182313,
        -77.0674764431659,
        188.95285304846897,
        0.11197452545166016,
    ),
    (
        "1961-09-12T06:59:58Z",
        48.2138,
        -38.4056,
        2315.3,
        33.87372642215448,
        -31.001251925636566,
        53.27609707331393,
        0.044736170768737794,
    ),
    (
        "2018-11-25T16:00:08Z",
        46.4127,
        125.0852,
        348.6,
        69.31226666601584,
        56.49463930457485,
        130.47508197875925,
        0.9227613830566406,
    ),
    (
        "2001-07-06T12:26:08Z",
        -38.9499,
        -37.0972,
        2807.5,
        64.2019925047218,
        -17.299764384544048,
        220.62957653207394,
        0.9923455810546875,
    ),
    (
        "1968-06-11T23:54:39Z",
        -33.7599,
        -134.6197,
        3977.4,
        38.68627973351467,
        -24.212931815235994,
        155.10169786145542,
        0.9781197357177734,
    ),
    (
        "2019-01-19T13:09:49Z",
        -57.3248,
        85.9553,
        2608.7,
        69.37449873787027,
        -1.747174022355192,
        49.010329747939146,
        0.9588959503173828,
    ),
    (
        "2004-01-17T17:35:52Z",
        -6.9827,
        -143.5654,
        3074.7,
        64.57491651495314,
        75.46366606377687,
        176.69204877127078,
        0.22690271377563476,
    ),
    (
        "2048-05-14T23:25:30Z",
        18.7764,
        -10.0856,
        1661.3,
        104.96454526848927,
        -31.81665015403644,
        314.5733234331283,
        0.0394035792350769,
    ),
    (
        "1969-04-06T05:23:46Z",
        21.8083,
        -1.5392,
        3119.8,
        39.45170693492371,
        31.09472989461736,
        218.25398209723014,
        0.8517374420166015,
    ),
    (
        "1961-06-25T17:47:11Z",
        80.365,
        8.5276,
        3720.4,
        33.78595575448935,
        -8.585360810277498,
        135.0397383822138,
        0.8951891326904297,
    ),
    (
        "2001-06-15T03:00:00Z",
        90.0,
        0.0,
        0.0,
        64.1896690270778,
        -3.7428779245962263,
        121.72575991613466,
        0.4065208435058594,
    ),
    (
        "1975-03-02T18:30:00Z",
        -90.0,
        45.0,
        2800.0,
        45.6398853236522,
        17.314517593151276,
        100.87359536124677,
        0.7146444702148438,
    ),
    (
        "2020-11-30T09:45:00Z",
        -12.5,
        180.0,
        0.0,
        70.2642748329722,
        44.08879596035144,
        43.062365377165676,
        0.9999198913574219,
    ),
    (
        "2033-08-08T22:10:00Z",
        35.0,
        -180.0,
        50.0,
        81.72552918871017,
        -71.74542719283782,
        351.204884706714,
        0.9535781097412109,
    ),
    (
        "2015-01-20T12:00:00Z",
        70.0,
        25.0,
        100.0,
        67.66212823267176,
        1.7939434225317368,
        203.15267972914208,
        0.0018202558159828186,
    ),
    (
        "2040-05-05T02:06:00Z",
        48.1,
        11.6,
        500.0,
        91.18347508847975,
        0.7067168452960161,
        116.2074588403846,
        0.3615726470947266,
    ),
    (
        "2006-03-10T02:06:20Z",
        25.0,
        -80.0,
        0.0,
        64.89856130137206,
        89.27133060306453,
        2.091987264701706,
        0.7994779205322265,
    ),
];

/// Worst differences (ours − PyEphem's) over the cases: elevation, azimuth × cos(elevation),
/// fraction.
fn worst_against_pyephem(delta_t: impl Fn(&EphemCase) -> Option<f64>) -> (f64, f64, f64) {
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for case in &PYEPHEM {
        let (t, lat, lon, h, _, e, a, k) = *case;
        let p = moon_position(&obs(lat, lon, h), at(t), &airless(delta_t(case))).unwrap();
        let de = (p.elevation_deg - e).abs();
        let da = (p.azimuth_deg - a).abs();
        // At a pole every direction is south (or north): the azimuth is a convention there.
        let da = if lat.abs() == 90.0 {
            0.0
        } else {
            da.min(360.0 - da) * e.to_radians().cos()
        };
        let dk = (p.illuminated_fraction - k).abs();
        eprintln!("{t} {lat} {lon}: d_el {de:.5} d_az·cos {da:.5} d_k {dk:.6}");
        worst = (worst.0.max(de), worst.1.max(da), worst.2.max(dk));
    }
    worst
}

/// The agreement goal: 0.01° in elevation and in azimuth (scaled by cos elevation), 0.001 in the
/// illuminated fraction, with PyEphem's own ΔT so that only the lunar theories differ.
#[test]
fn matches_pyephem() {
    let (de, da, dk) = worst_against_pyephem(|c| Some(c.4));
    eprintln!("worst with PyEphem's ΔT: elevation {de}, azimuth {da}, fraction {dk}");
    assert!(de < 0.01 && da < 0.01 && dk < 0.001, "{de} {da} {dk}");
}

/// With our own ΔT model (Espenak & Meeus) instead: the two ΔT differ by up to a few seconds, in
/// which the Moon moves under 0.001°, so the goal still holds.
#[test]
fn matches_pyephem_with_our_delta_t() {
    let (de, da, dk) = worst_against_pyephem(|_| None);
    eprintln!("worst with our ΔT: elevation {de}, azimuth {da}, fraction {dk}");
    assert!(de < 0.01 && da < 0.01 && dk < 0.001, "{de} {da} {dk}");
}

/// Angle in degrees between two unit vectors.
fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot: f64 = a.iter().zip(b.iter()).map(|(x, y)| x * y).sum();
    dot.clamp(-1.0, 1.0).acos().to_degrees()
}

/// The sky turns 0.2507° a minute and the Moon lags it; refraction stretches elevation by at most
/// its steepest slope, in the sun's fade band just below the horizon (0.6° over 1°: slope 0.6).
/// So 0.2507 × 1.7 = 0.43° per minute bounds an honest step; SPA's own switch-off (a 0.6° step)
/// would show as 0.85°.
const MAX_DEG_PER_MINUTE: f64 = 0.43;

/// One-minute steps over two days at the poles, the equator, 70° N and a mid-latitude site,
/// with refraction: the direction never jumps (moonrise and moonset included).
#[test]
fn direction_is_continuous_minute_by_minute() {
    let t0 = at("2025-06-10T00:00:00Z");
    for (lat, lon) in [
        (90.0, 0.0),
        (-90.0, 0.0),
        (0.0, 179.9),
        (70.0, 25.0),
        (48.1, 11.6),
    ] {
        let o = obs(lat, lon, 0.0);
        let mut prev = moon_position(&o, t0, &MoonOptions::default()).unwrap();
        for m in 1..=2 * 24 * 60 {
            let p = moon_position(&o, t0 + Duration::minutes(m), &MoonOptions::default()).unwrap();
            let moved = angle_between(prev.direction_enu(), p.direction_enu());
            assert!(
                moved <= MAX_DEG_PER_MINUTE,
                "lat {lat} minute {m}: moved {moved}° ({prev:?} -> {p:?})"
            );
            assert!((p.illuminated_fraction - prev.illuminated_fraction).abs() < 1e-4);
            prev = p;
        }
    }
}

/// Full and new moons of January 2026 from PyEphem (`ephem.next_full_moon("2026/1/1")` =
/// 2026-01-03 10:02:51 UTC, `next_new_moon` = 2026-01-18 19:51:55 UTC): nearly all lit and
/// nearly all dark (the Moon passes up to 5° from the exact opposition and conjunction).
#[test]
fn fraction_at_full_and_new_moon() {
    let o = obs(0.0, 0.0, 0.0);
    let full = moon_position(&o, at("2026-01-03T10:02:51Z"), &MoonOptions::default()).unwrap();
    let new = moon_position(&o, at("2026-01-18T19:51:55Z"), &MoonOptions::default()).unwrap();
    assert!(full.illuminated_fraction > 0.998, "{full:?}");
    assert!(new.illuminated_fraction < 0.002, "{new:?}");
    // PyEphem's own phases at those instants: 99.861 % and 0.0868 %.
    assert!((full.illuminated_fraction - 0.99861).abs() < 1e-3);
    assert!((new.illuminated_fraction - 0.000868).abs() < 1e-3);
}

/// That full moon (declination +26.4°, near perigee at 365 947 km) seen high from 26.4° N where
/// it transits: within the commonly cited 0.1–0.3 lux (Krieg 2021 measured up to 0.2 lux on the
/// ground); and 0 lux where it is below the horizon.
#[test]
fn full_moon_lux_and_none_below_the_horizon() {
    let t = at("2026-01-03T10:02:51Z");
    let highest = (-180..180)
        .map(|lon| {
            moon_position(&obs(26.4, f64::from(lon), 0.0), t, &MoonOptions::default()).unwrap()
        })
        .max_by(|a, b| a.elevation_deg.total_cmp(&b.elevation_deg))
        .unwrap();
    assert!(highest.elevation_deg > 85.0, "{highest:?}");
    let lux = highest
        .light(DEFAULT_EXTINCTION_MAG_PER_AIRMASS)
        .unwrap()
        .horizontal_lux;
    assert!((0.1..0.3).contains(&lux), "{lux} lux from {highest:?}");
    // The antipode of the sub-lunar point sees no Moon.
    let below = moon_position(&obs(-26.4, 0.0, 0.0), t, &MoonOptions::default()).unwrap();
    let below = if below.elevation_deg < 0.0 {
        below
    } else {
        moon_position(&obs(-26.4, 180.0, 0.0), t, &MoonOptions::default()).unwrap()
    };
    assert!(below.elevation_deg < 0.0);
    assert_eq!(below.light(0.2).unwrap().horizontal_lux, 0.0);
}

#[test]
fn bad_inputs_are_one_line_errors() {
    let t = at("2026-06-21T10:00:00Z");
    for (o, what) in [
        (obs(95.0, 0.0, 0.0), "latitude"),
        (obs(0.0, f64::NAN, 0.0), "longitude"),
        (obs(0.0, 0.0, 1e7), "height"),
    ] {
        let e = moon_position(&o, t, &MoonOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(what) && e.contains("; ") && !e.contains('\n'),
            "{e}"
        );
    }
    let far = Utc.with_ymd_and_hms(7000, 1, 1, 0, 0, 0).unwrap();
    assert!(moon_position(&obs(0.0, 0.0, 0.0), far, &MoonOptions::default()).is_err());
}

proptest! {
    /// Anywhere, any time in 1950–2050: every field in its documented range, the direction a
    /// unit vector that agrees with elevation and azimuth.
    #[test]
    fn in_range_everywhere(
        lat in -90.0f64..=90.0,
        lon in -180.0f64..=180.0,
        height in 0.0f64..5000.0,
        secs in -1_577_880_000i64..1_577_880_000i64,
    ) {
        let t = Utc.timestamp_opt(946_728_000 + secs, 0).unwrap();
        let p = moon_position(&obs(lat, lon, height), t, &MoonOptions::default()).unwrap();
        prop_assert!((-90.0..=90.0).contains(&p.elevation_deg), "{:?}", p);
        prop_assert!((0.0..360.0).contains(&p.azimuth_deg), "{:?}", p);
        prop_assert!((0.0..=1.0).contains(&p.illuminated_fraction), "{:?}", p);
        prop_assert!((0.0..=180.0).contains(&p.phase_angle_deg), "{:?}", p);
        prop_assert!((350_000.0..414_000.0).contains(&p.distance_km), "{:?}", p);
        let d = p.direction_enu();
        prop_assert!((d.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12);
        prop_assert!((d[2].asin().to_degrees() - p.elevation_deg).abs() < 1e-6);
        let l = p.light(DEFAULT_EXTINCTION_MAG_PER_AIRMASS).unwrap();
        prop_assert!(l.horizontal_lux >= 0.0 && l.horizontal_lux < 0.4, "{:?}", l);
        prop_assert_eq!(l.horizontal_lux == 0.0, p.elevation_deg <= 0.0);
    }
}
