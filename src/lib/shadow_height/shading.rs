//! A pitched roof's pitch from its faces' shading (issue 39). Where the shadow cannot tell a
//! pitched roof from a flat one at its eaves — a hip roof, or a gable with the sun across its
//! ridge, pitched below the sun, casts exactly its eaves' shadow — the photo of the roof still
//! shows its faces lit differently, and how differently says how steep they are.
//!
//! **Model** (Lambert's law under a uniform sky): a face of albedo `b` whose normal makes the
//! angle θ with the sun reads `b·(A + S·max(cos θ, 0))` in linear light (the photo's bytes
//! decoded as their [`PhotoEncoding`] says), per channel; open ground of albedo `a` reads `a·(A + S·sin e)` lit and
//! `a·A` in shadow. So the ratio `k = S/A` of each channel is `(lit/shadow − 1)/sin e` over the
//! medians of the open ground around the building ([`Light::from_ground`]). Every face of a
//! gable or hip roof in [`crate::roof`]'s convention has the same pitch `p` and slopes down
//! across the ridge (either way) or, on a hip's ends, along it. For each `p` the albedo that fits
//! best is a least-squares ratio per channel, and the squared residual over the roof's cells
//! scores `p` ([`Faces::residual`]); the pitch is the best `p` in `[0, MAX_PITCH_DEG]`, by whole
//! degrees, then by [`STEP_DEG`] around the best.
//!
//! **Invariants.** Cells within a cell of a crease are left out (they mix two faces; the caller
//! leaves out those within a cell of the outline). At `p = 0` every face reads alike, so the
//! flat roof's residual is the roof's whole variance: a pitch is reported only where the faces
//! explain at least [`MIN_EXPLAINED`] of it, differ by at least [`MIN_CONTRAST`] at that pitch,
//! and each face that tells the pitch has [`MIN_FACE_CELLS`] cells.
//!
//! **Uncertainty.** The sky's share is read off other materials than the roof's, and a real
//! photo's sky is not uniform nor its tone curve exactly sRGB: all of that acts on `k`. The
//! 68 % and 95 % pitch intervals reach the best pitches with `k` divided and multiplied by
//! [`K_SPREAD`] and by its square, widened in quadrature by [`PITCH_SE_DEG`] (one and 1.96
//! standard errors) for what `k` does not explain (calibrated on the town bench:
//! docs/shadow-height.md, "Pitch from the faces' shading").

use super::pitched::MAX_PITCH_DEG;
use crate::raster::srgb_to_linear;
use crate::roof::{Extent, RoofForm};

/// Pitches tried, degrees apart (near the best whole degree).
pub const STEP_DEG: f64 = 0.25;
/// Least share of the roof's variance of brightness the faces must explain for a pitch.
pub const MIN_EXPLAINED: f64 = 0.5;
/// Least contrast between the faces the fitted pitch predicts, as a share of their mean
/// light: below it the faces are alike to within a photo's few levels, and what they
/// "explain" is rounding.
pub const MIN_CONTRAST: f64 = 0.04;
/// Fewest cells of a face for it to count.
pub const MIN_FACE_CELLS: usize = 4;
/// The factor `k` (direct over sky light) is uncertain by, one standard error (see the module
/// docs).
pub const K_SPREAD: f64 = 1.4;
/// The pitch's own standard error, degrees, beyond what `k` explains: the faces' texture, the
/// cells that mix a face and a crease, the photo's noise. Calibrated on the town bench, where
/// the shading's rises came within 0.12 m (one standard deviation) of the truth on roofs 3–5 m
/// wide with `k` read well.
pub const PITCH_SE_DEG: f64 = 2.0;
/// Fewest open ground cells, lit and in shadow each, to read the light from.
const MIN_GROUND_CELLS: usize = 16;
/// Darkest linear shadow level used as a divisor (an all-black shadow would make `k` infinite:
/// then the faces read as direct light alone, to within this).
const DARKEST: f64 = 1.0 / 1024.0;

/// The light a photo was taken under, as the roof's faces see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    /// Unit vector toward the sun (east, north, up).
    pub toward_sun: [f64; 3],
    /// Direct sunlight over sky light (`S/A`), per channel (red, green, blue).
    pub k: [f64; 3],
}

impl Light {
    /// The light from open ground lit (`lit`) and in shadow (`shadow`) around a building, under
    /// a sun toward `toward_sun` (unit horizontal vector, east and north) at `elevation_rad`
    /// radians. `None` with fewer than `MIN_GROUND_CELLS` of either, or where the lit ground
    /// is not brighter than the shadow in every channel.
    pub fn from_ground(
        toward_sun: (f64, f64),
        elevation_rad: f64,
        lit: &[[u8; 4]],
        shadow: &[[u8; 4]],
        encoding: PhotoEncoding,
    ) -> Option<Light> {
        if lit.len() < MIN_GROUND_CELLS || shadow.len() < MIN_GROUND_CELLS {
            return None;
        }
        let (sin_e, cos_e) = elevation_rad.sin_cos();
        let mut k = [0.0; 3];
        for (ch, k) in k.iter_mut().enumerate() {
            let level =
                |px: &[[u8; 4]]| median(px.iter().map(|p| encoding.linear(p[ch])).collect());
            let (l, s) = (level(lit), level(shadow).max(DARKEST));
            if l <= s {
                return None;
            }
            *k = (l / s - 1.0) / sin_e;
        }
        Some(Light {
            toward_sun: [toward_sun.0 * cos_e, toward_sun.1 * cos_e, sin_e],
            k,
        })
    }

    /// `cos θ` of faces pitched `p` radians that slope down toward `down` (unit vectors, east
    /// and north), clamped at 0 (a face turned from the sun is lit by the sky alone).
    fn cos_incidence(&self, p: f64, down: &[(f64, f64); 4]) -> [f64; 4] {
        let (s, c) = p.sin_cos();
        let [x, y, z] = self.toward_sun;
        down.map(|d| (s * (d.0 * x + d.1 * y) + c * z).max(0.0))
    }
}

crate::choice! {
    /// How a photo's bytes encode light (named as on the command line in scene files too).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
    #[serde(rename_all = "lowercase")]
    pub enum PhotoEncoding {
        /// sRGB (IEC 61966-2-1): the usual 8-bit photo, and what a camera or a renderer writes
        /// unless told otherwise (the default).
        Srgb = "srgb",
        /// Linear: bytes proportional to the light.
        Linear = "linear",
    }
}

impl PhotoEncoding {
    /// Byte `v` as linear light in [0, 1].
    pub fn linear(self, v: u8) -> f64 {
        match self {
            PhotoEncoding::Linear => f64::from(v) / 255.0,
            PhotoEncoding::Srgb => {
                static TABLE: std::sync::OnceLock<[f64; 256]> = std::sync::OnceLock::new();
                TABLE.get_or_init(|| std::array::from_fn(|v| srgb_to_linear(v as u8)))
                    [usize::from(v)]
            }
        }
    }
}

/// The median of `v` (the upper one of an even count); 0 for none.
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// A roof's cells as the photo shows them: world centres (metres, on the footprint: a leaning
/// roof's cells moved back by the lean) and linear colours.
#[derive(Debug, Clone, Default)]
pub struct Roof {
    /// `(centre, [red, green, blue])` per cell.
    pub samples: Vec<((f64, f64), [f64; 3])>,
    /// Cell edge, metres.
    pub cell: f64,
}

impl Roof {
    /// The roof from `(centre, colour)` cells (bytes as `encoding` says), on cells `cell`
    /// metres wide.
    pub fn new(
        cells: impl Iterator<Item = ((f64, f64), [u8; 4])>,
        cell: f64,
        encoding: PhotoEncoding,
    ) -> Roof {
        let lin = |v| encoding.linear(v);
        Roof {
            samples: cells
                .map(|(p, c)| (p, [lin(c[0]), lin(c[1]), lin(c[2])]))
                .collect(),
            cell,
        }
    }

    /// Whether the roof's cells differ at all (a roof of one colour shows no faces).
    pub fn varies(&self) -> bool {
        let mut it = self.samples.iter().map(|s| s.1);
        let Some(first) = it.next() else {
            return false;
        };
        it.any(|c| c != first)
    }
}

/// A roof's cells summed per face of one pitched shape: a gable's two faces and a hip's two
/// ends, each with the way it slopes down.
#[derive(Debug, Clone, PartialEq)]
pub struct Faces {
    /// Unit vector down each face (east, north): across the ridge either way, along it either
    /// way.
    down: [(f64, f64); 4],
    /// Cells per face.
    n: [f64; 4],
    /// Sum of linear colour per face and channel.
    sum: [[f64; 3]; 4],
    /// Sum of squared linear colour per face and channel.
    sum_sq: [[f64; 3]; 4],
}

impl Faces {
    /// The cells of `roof` on each face of a `form` roof over `extent` (a shed's one face is no
    /// shape to tell a pitch from shading: it gives no faces).
    pub fn new(roof: &Roof, extent: &Extent, form: RoofForm) -> Faces {
        let (along, across) = (extent.along, extent.across);
        let neg = |d: (f64, f64)| (-d.0, -d.1);
        let mut f = Faces {
            down: [across, neg(across), along, neg(along)],
            n: [0.0; 4],
            sum: [[0.0; 3]; 4],
            sum_sq: [[0.0; 3]; 4],
        };
        let (l, w) = extent.half;
        let margin = roof.cell;
        for &(p, colour) in &roof.samples {
            let (a, c) = extent.local(p);
            // Distances (metres of profile) to the ridge's and the hip's heights.
            let to_side = w - c.abs();
            let face = match form {
                RoofForm::Gable => (c.abs() >= margin).then_some(usize::from(c < 0.0)),
                RoofForm::Hip => {
                    let to_end = l - a.abs();
                    if (to_side - to_end).abs() < margin {
                        None
                    } else if to_side < to_end {
                        (c.abs() >= margin).then_some(usize::from(c < 0.0))
                    } else {
                        Some(2 + usize::from(a < 0.0))
                    }
                }
                RoofForm::Shed => None,
            };
            let Some(face) = face else { continue };
            f.n[face] += 1.0;
            for (ch, v) in colour.into_iter().enumerate() {
                f.sum[face][ch] += v;
                f.sum_sq[face][ch] += v * v;
            }
        }
        f
    }

    /// The squared residual of the best albedo per channel for faces pitched `p` radians under
    /// `light`, with its `k` scaled by `k_scale`. Faces with fewer than [`MIN_FACE_CELLS`]
    /// cells are left out.
    pub fn residual(&self, light: &Light, p: f64, k_scale: f64) -> f64 {
        let cos = light.cos_incidence(p, &self.down);
        let mut r = 0.0;
        for ch in 0..3 {
            let (mut sg, mut gg, mut sq) = (0.0, 0.0, 0.0);
            for f in (0..4).filter(|&f| self.counts(f)) {
                let g = 1.0 + k_scale * light.k[ch] * cos[f];
                sg += self.sum[f][ch] * g;
                gg += self.n[f] * g * g;
                sq += self.sum_sq[f][ch];
            }
            if gg > 0.0 {
                r += sq - sg * sg / gg;
            }
        }
        r.max(0.0)
    }

    /// Whether face `f` has the cells to count.
    fn counts(&self, f: usize) -> bool {
        self.n[f] >= MIN_FACE_CELLS as f64
    }

    /// The contrast of the faces pitched `p` radians under `light`: the spread of their
    /// predicted light over its mean, averaged over the channels (the albedo cancels).
    fn contrast(&self, light: &Light, p: f64) -> f64 {
        let faces: Vec<usize> = (0..4).filter(|&f| self.counts(f)).collect();
        let cos = light.cos_incidence(p, &self.down);
        let mut sum = 0.0;
        for k in light.k {
            let g: Vec<f64> = faces.iter().map(|&f| 1.0 + k * cos[f]).collect();
            let (lo, hi) = g
                .iter()
                .fold((f64::INFINITY, 0f64), |(l, h), &v| (l.min(v), h.max(v)));
            sum += (hi - lo) / (g.iter().sum::<f64>() / g.len() as f64);
        }
        sum / 3.0
    }

    /// The pitch (radians) whose shading fits best with `k` scaled by `k_scale`, and its
    /// residual.
    /// Whole degrees first, then [`STEP_DEG`] steps within a degree of the best: the residual
    /// is smooth in the pitch.
    fn best(&self, light: &Light, k_scale: f64) -> (f64, f64) {
        let at = |deg: f64| {
            let p = deg.to_radians();
            (p, self.residual(light, p, k_scale))
        };
        let least = |b: (f64, f64), t: (f64, f64)| if t.1 < b.1 { t } else { b };
        let coarse = (0..=MAX_PITCH_DEG as usize)
            .map(|d| at(d as f64))
            .fold((0.0, f64::INFINITY), least);
        let centre = coarse.0.to_degrees();
        let fine = (1..(1.0 / STEP_DEG) as usize).flat_map(|j| {
            let d = j as f64 * STEP_DEG;
            [centre - d, centre + d]
        });
        fine.filter(|d| (0.0..=MAX_PITCH_DEG).contains(d))
            .map(at)
            .fold(coarse, least)
    }
}

/// A pitch read from the faces' shading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The pitch, degrees from horizontal.
    pub pitch_deg: f64,
    /// Its 68 % and 95 % intervals, degrees.
    pub intervals_deg: [(f64, f64); 2],
    /// Share of the roof's variance of brightness the faces explain, in [0, 1].
    pub explained: f64,
}

/// The pitch `faces` show under `light`, or `None` where they do not tell one (module docs).
pub fn estimate(faces: &Faces, light: &Light) -> Option<Estimate> {
    let flat = faces.residual(light, 0.0, 1.0);
    let (p, r) = faces.best(light, 1.0);
    if flat.is_nan()
        || flat <= 0.0
        || r > (1.0 - MIN_EXPLAINED) * flat
        || p <= 0.0
        || faces.contrast(light, p) < MIN_CONTRAST
    {
        return None;
    }
    let deg = p.to_degrees();
    let intervals_deg = [(K_SPREAD, 1.0), (K_SPREAD * K_SPREAD, 1.96)].map(|(s, z)| {
        let (a, b) = (faces.best(light, 1.0 / s).0, faces.best(light, s).0);
        let (a, b) = (a.to_degrees(), b.to_degrees());
        let own = z * PITCH_SE_DEG;
        let lo = deg - (deg - a.min(b)).max(0.0).hypot(own);
        let hi = deg + (a.max(b) - deg).max(0.0).hypot(own);
        (lo.max(0.0), hi.min(MAX_PITCH_DEG))
    });
    Some(Estimate {
        pitch_deg: deg,
        intervals_deg,
        explained: 1.0 - r / flat,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 12 m × 8 m rectangle centred on the origin, its long side along `ridge_deg` (degrees
    /// clockwise from grid north).
    fn extent(ridge_deg: f64) -> Extent {
        let (s, c) = ridge_deg.to_radians().sin_cos();
        let (along, across) = ((s, c), (c, -s));
        let corner = |a: f64, b: f64| (a * along.0 + b * across.0, a * along.1 + b * across.1);
        let ring = vec![
            corner(-6.0, -4.0),
            corner(6.0, -4.0),
            corner(6.0, 4.0),
            corner(-6.0, 4.0),
        ];
        Extent::new(&[ring], ridge_deg).unwrap()
    }

    /// The light of a sun at `az`/`el` degrees with direct-over-sky ratio `k` in every channel.
    fn light(az: f64, el: f64, k: f64) -> Light {
        let (s, c) = az.to_radians().sin_cos();
        let e = el.to_radians();
        Light {
            toward_sun: [s * e.cos(), c * e.cos(), e.sin()],
            k: [k; 3],
        }
    }

    /// The roof over `x` (a `form` roof pitched `pitch_deg`) on 0.25 m cells, each cell's
    /// linear colour `value(cell centre, lambert)`, where `lambert` is Lambert's law under
    /// `l` for albedo 0.3 (the face's, from its own normal: the roof as a renderer sees it).
    fn roof(
        x: &Extent,
        form: RoofForm,
        pitch_deg: f64,
        l: &Light,
        value: impl Fn((f64, f64), f64) -> f64,
    ) -> Roof {
        let tan_p = pitch_deg.to_radians().tan();
        let mut samples = Vec::new();
        for i in 0..48 {
            for j in 0..32 {
                let (a, c) = (-5.875 + 0.25 * i as f64, -3.875 + 0.25 * j as f64);
                // The face is the lowest plane's: gradient of the profile there.
                let side = 4.0 - c.abs();
                let end = 6.0 - a.abs();
                let (ga, gc) = if form == RoofForm::Hip && end < side {
                    (-a.signum(), 0.0)
                } else {
                    (0.0, -c.signum())
                };
                // Normal of z = tan p · (g · (a, c)) + const: (−tan p · g, 1), normalised.
                let g = (
                    ga * x.along.0 + gc * x.across.0,
                    ga * x.along.1 + gc * x.across.1,
                );
                let n = [-tan_p * g.0, -tan_p * g.1, 1.0];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                let cos = (0..3).map(|k| n[k] / len * l.toward_sun[k]).sum::<f64>();
                let lambert = 0.3 * (1.0 + l.k[0] * cos.max(0.0)) / (1.0 + l.k[0]);
                let p = x.world((a, c));
                samples.push((p, [value(p, lambert); 3]));
            }
        }
        Roof {
            samples,
            cell: 0.25,
        }
    }

    fn pitch_of(x: &Extent, form: RoofForm, r: &Roof, l: &Light) -> Option<f64> {
        estimate(&Faces::new(r, x, form), l).map(|e| e.pitch_deg)
    }

    #[test]
    fn hard_case_a_pitch_comes_back_from_its_faces_at_axes_diagonals_and_ulps_off() {
        let diag = 135f64;
        let ulps_off = f64::from_bits(diag.to_bits() + 3);
        for (form, ridge) in [
            (RoofForm::Hip, 0.0),
            (RoofForm::Gable, 90.0),
            (RoofForm::Hip, 30.0),
        ] {
            let x = extent(ridge);
            for az in [90.0, 180.0, diag, ulps_off, 200.0] {
                for pitch in [15.0, 30.0, 45.0] {
                    let l = light(az, 40.0, 2.2);
                    // A gable with the sun exactly along its ridge: both faces alike.
                    let along = (az - ridge).rem_euclid(180.0) == 0.0;
                    let r = roof(&x, form, pitch, &l, |_, v| v);
                    let got = pitch_of(&x, form, &r, &l);
                    if form == RoofForm::Gable && along {
                        assert_eq!(got, None, "{form:?} {ridge} sun {az}");
                        continue;
                    }
                    let got = got.unwrap_or_else(|| panic!("{form:?} {ridge} sun {az} {pitch}"));
                    assert!(
                        (got - pitch).abs() <= STEP_DEG,
                        "{form:?} ridge {ridge} sun {az}: {got} for {pitch}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_intervals_hold_the_pitch_when_the_sky_is_misread() {
        // The ground said k = 2.2; the roof was lit with k 1.5 times larger.
        let x = extent(0.0);
        let (told, truth) = (light(135.0, 40.0, 2.2), light(135.0, 40.0, 3.3));
        let r = roof(&x, RoofForm::Hip, 30.0, &truth, |_, v| v);
        let e = estimate(&Faces::new(&r, &x, RoofForm::Hip), &told).unwrap();
        assert!((e.pitch_deg - 30.0).abs() > 1.0, "misread: {e:?}");
        let [i68, i95] = e.intervals_deg;
        assert!(i95.0 <= 30.0 && 30.0 <= i95.1, "{e:?}");
        assert!(i95.0 <= i68.0 && i68.1 <= i95.1, "nested: {e:?}");
    }

    #[test]
    fn a_flat_roof_tells_no_pitch_textured_or_shaded_on_its_sunny_side() {
        let x = extent(0.0);
        let l = light(135.0, 40.0, 2.2);
        let noise = |p: (f64, f64)| 0.02 * ((p.0 * 7.3 + p.1 * 13.1).sin());
        let r = roof(&x, RoofForm::Hip, 0.0, &l, |p, v| v + noise(p));
        assert_eq!(pitch_of(&x, RoofForm::Hip, &r, &l), None, "texture");
        assert_eq!(pitch_of(&x, RoofForm::Gable, &r, &l), None, "texture");
        // Uniform: what the faces "explain" is rounding.
        let r = roof(&x, RoofForm::Hip, 0.0, &l, |_, _| 0.3);
        assert_eq!(pitch_of(&x, RoofForm::Hip, &r, &l), None, "uniform");
        // A neighbour's (or a parapet's) shadow darkens the side toward the sun (south-east):
        // Lambert's law makes a face that way brighter, never darker.
        let r = roof(&x, RoofForm::Hip, 0.0, &l, |p, v| {
            if p.0 - p.1 > 6.0 {
                v * 0.4
            } else {
                v
            }
        });
        for form in [RoofForm::Hip, RoofForm::Gable] {
            let got = estimate(&Faces::new(&r, &x, form), &l);
            assert!(
                got.is_none_or(|e| e.intervals_deg[1].0 < 5.0),
                "{form:?}: {got:?}"
            );
        }
    }

    #[test]
    fn the_light_is_read_off_the_ground_in_either_encoding() {
        let (e, k) = (35f64.to_radians(), 2.5);
        for encoding in [PhotoEncoding::Srgb, PhotoEncoding::Linear] {
            // Bytes whose linear light is `v`, exactly the nearest byte.
            let byte = |v: f64| {
                (0..=255u8).min_by(|&a, &b| {
                    (encoding.linear(a) - v)
                        .abs()
                        .total_cmp(&(encoding.linear(b) - v).abs())
                })
            };
            let (sky, albedo) = (0.2, 0.8);
            let shadow = byte(albedo * sky).unwrap();
            let lit = byte(albedo * sky * (1.0 + k * e.sin())).unwrap();
            let l = Light::from_ground(
                (0.0, -1.0),
                e,
                &[[lit; 4]; 20],
                &[[shadow; 4]; 20],
                encoding,
            )
            .unwrap();
            assert!((l.k[1] - k).abs() < 0.1, "{encoding:?}: {:?}", l.k);
            assert!(
                (l.toward_sun[1] + e.cos()).abs() < 1e-12
                    && (l.toward_sun[2] - e.sin()).abs() < 1e-12
            );
        }
        // Lit no brighter than the shadow; too few lit cells.
        for (lit, shadow) in [
            (vec![[90; 4]; 20], [[90; 4]; 20]),
            (vec![[200; 4]; 3], [[90; 4]; 20]),
        ] {
            let l = Light::from_ground((0.0, -1.0), e, &lit, &shadow, PhotoEncoding::Srgb);
            assert_eq!(l, None, "{lit:?}");
        }
    }

    #[test]
    fn the_encodings_have_the_same_names_in_files_and_on_the_command_line() {
        use crate::choice::Choice;
        for &e in PhotoEncoding::ALL {
            assert_eq!(serde_json::to_value(e).unwrap(), e.name());
        }
    }
}
