//! Roof shapes a building can state: flat, or pitched — gable, hip, shed — over any footprint.
//!
//! One convention, shared by everything that reads or writes a roof (the buildings layer,
//! `dbms shadow-height`'s fit, the pyramid's columns, the mesh export's roof planes):
//!
//! A pitched roof has a direction, `azimuth_deg` (degrees clockwise from grid north): for a
//! gable or hip roof the ridge's (taken in `[0, 180)`), for a shed roof the way it rises. The
//! footprint's vertices projected on that direction (`a`, "along") and across it (`c`,
//! clockwise from it) span the **extent** `[a0, a1] × [c0, c1]`: half-length
//! `l = (a1 − a0)/2`, half-width `w = (c1 − c0)/2`, centre `(a_m, c_m)`. With `rise = top_z −
//! eave_z` (metres, ≥ 0), the roof's height at a point `p` is `eave_z + rise · profile(p)`,
//! the profile in `[0, 1]`:
//! * **gable**: `1 − |c(p) − c_m| / w` — two planes meeting at the ridge line `c = c_m`, the
//!   eaves on the extent's long sides;
//! * **hip**: `min(gable, (l − |a(p) − a_m|) / w)` — the gable's two planes and two hips of the
//!   same pitch at the ends (the ridge is `2(l − w)` long; a roof no longer than wide is a
//!   pyramid whose top is below `top_z`);
//! * **shed**: `(a(p) − a0) / (2l)` — one plane rising from the eaves at `a0` to `top_z` at `a1`.
//!
//! For a rectangle whose side lies along `azimuth_deg` this is the ordinary roof of that form;
//! for any other outline it is that roof over the outline's extent, cut by its walls. The
//! profile is piecewise linear; its creases are [`RoofShape::creases`] (ridge and hips), so
//! a triangulation that keeps them as edges represents the roof exactly.
//!
//! Invariant: `RoofShape::z_at` is at most `top_z` and at least `eave_z` everywhere (profile
//! clamped to `[0, 1]` outside the extent); a flat roof is `top_z` everywhere.

use crate::choice::Choice;

crate::choice! {
    /// The form of a pitched roof (a flat roof has none).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum RoofForm {
        /// Two planes meeting at a ridge; gable walls at the ends.
        Gable = "gable",
        /// Four planes of one pitch: a gable's two and a hip at each end.
        Hip = "hip",
        /// One plane rising toward the roof's azimuth.
        Shed = "shed",
    }
}

/// What makes a roof pitched: its form, its eaves and its direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pitch {
    /// The form.
    pub form: RoofForm,
    /// Height of the eaves (the roof's lowest edge), absolute metres.
    pub eave_z: f64,
    /// Gable and hip: the ridge's direction; shed: the way the roof rises; degrees clockwise
    /// from grid north.
    pub azimuth_deg: f64,
}

/// The steepest roof face (degrees from the horizontal) a drop between two neighbouring cells of
/// buildings is read as; a steeper drop is a wall (between two buildings, or a roof's step).
pub const MAX_PITCH_DEG: f64 = 70.0;

/// The property names of a roof in GeoJSON (the buildings layer, `dbms shadow-height`'s output).
pub mod property {
    /// `"flat"`, `"gable"`, `"hip"` or `"shed"`; absent means flat.
    pub const FORM: &str = "roof_form";
    /// The eaves, absolute metres (pitched roofs).
    pub const EAVE_Z: &str = "eave_z";
    /// The pitch's direction, degrees clockwise from grid north (pitched roofs; see [`super`]).
    pub const AZIMUTH: &str = "roof_azimuth_deg";
}

impl Pitch {
    /// The pitch a GeoJSON feature's `properties` state, for a roof whose top is `top_z`
    /// (absolute metres): `None` for a flat roof (no `roof_form`, or `"flat"`); an error that
    /// names the property for an unknown form, a missing or non-finite `eave_z` or azimuth, or
    /// eaves above the top.
    pub fn from_properties(
        properties: &serde_json::Value,
        top_z: f64,
    ) -> Result<Option<Pitch>, String> {
        let form = match properties.get(property::FORM) {
            None | Some(serde_json::Value::Null) => return Ok(None),
            Some(v) => v
                .as_str()
                .ok_or_else(|| format!("{} is not a string", property::FORM))?,
        };
        if form == "flat" {
            return Ok(None);
        }
        let form = RoofForm::named(form).ok_or_else(|| {
            format!(
                "{} {form:?} is not one of flat, {}",
                property::FORM,
                RoofForm::ALL
                    .iter()
                    .map(|f| f.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })?;
        let number = |name: &str| {
            properties
                .get(name)
                .and_then(|v| v.as_f64())
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("a {} roof needs a finite numeric {name}", form.name()))
        };
        let eave_z = number(property::EAVE_Z)?;
        let azimuth_deg = number(property::AZIMUTH)?;
        if eave_z > top_z {
            return Err(format!(
                "{} {eave_z} is above roof_z {top_z}",
                property::EAVE_Z
            ));
        }
        Ok(Some(Pitch {
            form,
            eave_z,
            azimuth_deg,
        }))
    }

    /// Write this pitch's properties into a GeoJSON `properties` object.
    pub fn to_properties(&self, properties: &mut serde_json::Map<String, serde_json::Value>) {
        properties.insert(property::FORM.into(), self.form.name().into());
        properties.insert(property::EAVE_Z.into(), self.eave_z.into());
        properties.insert(property::AZIMUTH.into(), self.azimuth_deg.into());
    }
}

/// A pitched roof's direction and its footprint's extent along and across it
/// (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Unit vector along the pitch's direction (east, north).
    pub along: (f64, f64),
    /// Unit vector across it, clockwise from `along` (east, north).
    pub across: (f64, f64),
    /// The world point the along and across coordinates are measured from (an outline
    /// vertex: coordinates stay small, and exact to the outline's own precision).
    pub origin: (f64, f64),
    /// Centre of the extent: along and across coordinates from `origin`, metres.
    pub centre: (f64, f64),
    /// Half-length along and half-width across, metres.
    pub half: (f64, f64),
}

impl Extent {
    /// The extent of the outline `rings` (world metres) along `azimuth_deg` (degrees clockwise
    /// from grid north). `None` when the rings hold no vertex.
    pub fn new(rings: &[Vec<(f64, f64)>], azimuth_deg: f64) -> Option<Extent> {
        let (s, c) = azimuth_deg.to_radians().sin_cos();
        let along = (s, c);
        let across = (c, -s);
        let origin = *rings.iter().flatten().next()?;
        let dot = |p: (f64, f64), d: (f64, f64)| (p.0 - origin.0) * d.0 + (p.1 - origin.1) * d.1;
        let mut lo = (f64::INFINITY, f64::INFINITY);
        let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        for &p in rings.iter().flatten() {
            let (a, c) = (dot(p, along), dot(p, across));
            lo = (lo.0.min(a), lo.1.min(c));
            hi = (hi.0.max(a), hi.1.max(c));
        }
        Some(Extent {
            along,
            across,
            origin,
            centre: ((lo.0 + hi.0) / 2.0, (lo.1 + hi.1) / 2.0),
            half: ((hi.0 - lo.0) / 2.0, (hi.1 - lo.1) / 2.0),
        })
    }

    /// World point `p` as (along, across) offsets from the extent's centre, metres.
    pub fn local(&self, p: (f64, f64)) -> (f64, f64) {
        let (x, y) = (p.0 - self.origin.0, p.1 - self.origin.1);
        (
            x * self.along.0 + y * self.along.1 - self.centre.0,
            x * self.across.0 + y * self.across.1 - self.centre.1,
        )
    }

    /// The world point at (along, across) offsets `(a, c)` from the centre, metres.
    pub fn world(&self, (a, c): (f64, f64)) -> (f64, f64) {
        let (a, c) = (a + self.centre.0, c + self.centre.1);
        (
            self.origin.0 + a * self.along.0 + c * self.across.0,
            self.origin.1 + a * self.along.1 + c * self.across.1,
        )
    }

    /// The profile of a `form` roof at world point `p`, in `[0, 1]` (module docs). A zero
    /// width (or length, for a shed) gives 1: a roof of no extent is its top.
    pub fn profile(&self, form: RoofForm, p: (f64, f64)) -> f64 {
        let (a, c) = self.local(p);
        let (l, w) = self.half;
        let ratio = |num: f64, den: f64| {
            if den > 0.0 {
                (num / den).clamp(0.0, 1.0)
            } else {
                1.0
            }
        };
        let gable = ratio(w - c.abs(), w);
        match form {
            RoofForm::Gable => gable,
            RoofForm::Hip => gable.min(ratio(l - a.abs(), w)),
            RoofForm::Shed => ratio(a + l, 2.0 * l),
        }
    }
}

/// A roof over a footprint: flat at `top_z`, or pitched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoofShape {
    /// The highest point (the ridge; a flat roof's height), absolute metres.
    pub top_z: f64,
    /// The pitch and the footprint's extent along it; `None` for a flat roof.
    pub pitch: Option<(Pitch, Extent)>,
}

impl RoofShape {
    /// A flat roof at `top_z` metres.
    pub fn flat(top_z: f64) -> RoofShape {
        RoofShape { top_z, pitch: None }
    }

    /// The roof `pitch` (or flat, `None`) with its top at `top_z` over the outline `rings`
    /// (world metres).
    pub fn new(rings: &[Vec<(f64, f64)>], top_z: f64, pitch: Option<Pitch>) -> RoofShape {
        let pitch = pitch.and_then(|p| Some((p, Extent::new(rings, p.azimuth_deg)?)));
        RoofShape { top_z, pitch }
    }

    /// The roof's height at world point `p` (inside the footprint), absolute metres.
    pub fn z_at(&self, p: (f64, f64)) -> f64 {
        match self.pitch {
            None => self.top_z,
            Some((pitch, extent)) => {
                pitch.eave_z + (self.top_z - pitch.eave_z) * extent.profile(pitch.form, p)
            }
        }
    }

    /// The lowest height of the roof, absolute metres: the eaves, or a flat roof's height.
    pub fn eave_z(&self) -> f64 {
        self.pitch.map_or(self.top_z, |(p, _)| p.eave_z)
    }

    /// The roof's creases, world metres: the segments (within the extent, not cut to the
    /// footprint) along which its planes meet — a gable's ridge; a hip's ridge and its four
    /// hips; none for a shed or flat roof. Between them the roof is one plane.
    pub fn creases(&self) -> Vec<[(f64, f64); 2]> {
        let Some((pitch, e)) = self.pitch else {
            return Vec::new();
        };
        let (l, w) = e.half;
        let at = |a: f64, c: f64| e.world((a, c));
        match pitch.form {
            RoofForm::Shed => Vec::new(),
            RoofForm::Gable => vec![[at(-l, 0.0), at(l, 0.0)]],
            RoofForm::Hip => {
                // Where the side planes meet (the ridge, along the centre line) or, on a roof
                // wider than long, where the end planes meet (across it); then a hip from each
                // end of that crease to the extent's corners on its side.
                let r = l - w;
                let (p, q) = if r >= 0.0 {
                    (at(-r, 0.0), at(r, 0.0))
                } else {
                    (at(0.0, r), at(0.0, -r))
                };
                let mut out = Vec::new();
                if r != 0.0 {
                    out.push([p, q]);
                }
                if r >= 0.0 {
                    out.extend([
                        [p, at(-l, -w)],
                        [p, at(-l, w)],
                        [q, at(l, -w)],
                        [q, at(l, w)],
                    ]);
                } else {
                    out.extend([
                        [p, at(-l, -w)],
                        [p, at(l, -w)],
                        [q, at(-l, w)],
                        [q, at(l, w)],
                    ]);
                }
                out
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rectangle `2l × 2w` centred at `(x, y)`, its long side along `azimuth_deg`.
    fn rect(x: f64, y: f64, l: f64, w: f64, azimuth_deg: f64) -> Vec<Vec<(f64, f64)>> {
        let (s, c) = azimuth_deg.to_radians().sin_cos();
        let (along, across) = ((s, c), (c, -s));
        let corner = |a: f64, b: f64| {
            (
                x + a * along.0 + b * across.0,
                y + a * along.1 + b * across.1,
            )
        };
        vec![vec![
            corner(-l, -w),
            corner(l, -w),
            corner(l, w),
            corner(-l, w),
        ]]
    }

    fn shape(form: RoofForm, azimuth_deg: f64, l: f64, w: f64) -> RoofShape {
        RoofShape::new(
            &rect(500_000.0, 5_300_000.0, l, w, azimuth_deg),
            110.0,
            Some(Pitch {
                form,
                eave_z: 104.0,
                azimuth_deg,
            }),
        )
    }

    // World points near UTM coordinates are exact to about 1e-9 m, so heights are compared to
    // 1e-7 m.

    #[test]
    fn a_gable_is_its_ridge_on_the_centre_line_and_its_eaves_on_the_long_sides() {
        for az in [0.0, 45.0, 90.0, 137.3, 180.0, 359.9] {
            let s = shape(RoofForm::Gable, az, 10.0, 4.0);
            let (_, e) = s.pitch.unwrap();
            for a in [-10.0, -3.0, 0.0, 9.99] {
                assert!((s.z_at(e.world((a, 0.0))) - 110.0).abs() < 1e-7);
                assert!((s.z_at(e.world((a, 4.0))) - 104.0).abs() < 1e-7);
                assert!((s.z_at(e.world((a, -4.0))) - 104.0).abs() < 1e-7);
                assert!((s.z_at(e.world((a, 2.0))) - 107.0).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn a_hip_has_equal_pitch_on_all_four_faces() {
        let s = shape(RoofForm::Hip, 30.0, 10.0, 4.0);
        let (_, e) = s.pitch.unwrap();
        // Ridge from a = −6 to 6; one metre in from any eave is 1.5 m up.
        assert!((s.z_at(e.world((0.0, 3.0))) - 105.5).abs() < 1e-7);
        assert!((s.z_at(e.world((9.0, 0.0))) - 105.5).abs() < 1e-7);
        assert!((s.z_at(e.world((-9.0, 0.0))) - 105.5).abs() < 1e-7);
        assert!((s.z_at(e.world((6.0, 0.0))) - 110.0).abs() < 1e-7);
        assert!((s.z_at(e.world((7.0, 0.0))) - 108.5).abs() < 1e-7);
        assert_eq!(s.creases().len(), 5);
        // Each crease is where two planes meet: the roof is linear along it, from the top
        // (or the wide roof's crest) down to an eave corner.
        for wide in [false, true] {
            let s = if wide {
                shape(RoofForm::Hip, 30.0, 3.0, 5.0)
            } else {
                s
            };
            for [p, q] in s.creases() {
                let m = ((p.0 + q.0) / 2.0, (p.1 + q.1) / 2.0);
                assert!((s.z_at(m) - (s.z_at(p) + s.z_at(q)) / 2.0).abs() < 1e-7);
            }
            let corners = s
                .creases()
                .iter()
                .filter(|[_, q]| (s.z_at(*q) - 104.0).abs() < 1e-7)
                .count();
            assert_eq!(corners, 4, "wide {wide}");
        }
    }

    #[test]
    fn a_shed_rises_toward_its_azimuth() {
        let s = shape(RoofForm::Shed, 90.0, 5.0, 3.0);
        // Rising east: the west wall at 104, the east wall at 110.
        assert!((s.z_at((499_995.0, 5_300_000.0)) - 104.0).abs() < 1e-7);
        assert!((s.z_at((500_005.0, 5_300_000.0)) - 110.0).abs() < 1e-7);
        assert!((s.z_at((500_000.0, 5_300_002.0)) - 107.0).abs() < 1e-7);
        assert!(s.creases().is_empty());
    }

    #[test]
    fn the_roof_stays_between_its_eaves_and_its_top_anywhere() {
        for form in RoofForm::ALL.iter().copied() {
            for az in [0.0, 45.0, 90.0, f64::from_bits(45f64.to_bits() + 2), 211.0] {
                let s = shape(form, az, 7.0, 5.0);
                for i in -30..30 {
                    for j in -30..30 {
                        let p = (500_000.0 + i as f64 * 0.7, 5_300_000.0 + j as f64 * 0.7);
                        let z = s.z_at(p);
                        assert!((104.0..=110.0).contains(&z), "{form:?} {az} {p:?}: {z}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_roof_is_linear_between_its_creases() {
        // Midpoints of short segments that cross no crease are the mean of their ends.
        for form in RoofForm::ALL.iter().copied() {
            let s = shape(form, 20.0, 9.0, 4.0);
            let (_, e) = s.pitch.unwrap();
            for (a, c) in [
                (1.0, 2.0),
                (-3.0, -2.5),
                (8.0, 0.5),
                (-7.5, -1.0),
                (0.5, 3.5),
            ] {
                let p = e.world((a, c));
                let q = e.world((a + 0.01, c + 0.013));
                let m = e.world((a + 0.005, c + 0.0065));
                let (zp, zq, zm) = (s.z_at(p), s.z_at(q), s.z_at(m));
                assert!((zm - (zp + zq) / 2.0).abs() < 1e-7, "{form:?} at {a},{c}");
            }
        }
    }

    #[test]
    fn properties_round_trip_and_bad_ones_name_the_property() {
        let p = Pitch {
            form: RoofForm::Hip,
            eave_z: 104.5,
            azimuth_deg: 33.0,
        };
        let mut map = serde_json::Map::new();
        p.to_properties(&mut map);
        let v = serde_json::Value::Object(map);
        assert_eq!(Pitch::from_properties(&v, 110.0).unwrap(), Some(p));
        let flat = serde_json::json!({"roof_form": "flat"});
        assert_eq!(Pitch::from_properties(&flat, 110.0).unwrap(), None);
        assert_eq!(
            Pitch::from_properties(&serde_json::json!({}), 1.0).unwrap(),
            None
        );
        let e = Pitch::from_properties(&serde_json::json!({"roof_form": "dome"}), 1.0);
        assert!(e.unwrap_err().contains("roof_form"));
        let e = Pitch::from_properties(&serde_json::json!({"roof_form": "gable"}), 1.0);
        assert!(e.unwrap_err().contains("eave_z"));
        let high =
            serde_json::json!({"roof_form": "gable", "eave_z": 120.0, "roof_azimuth_deg": 0.0});
        assert!(Pitch::from_properties(&high, 110.0)
            .unwrap_err()
            .contains("above"));
    }
}
