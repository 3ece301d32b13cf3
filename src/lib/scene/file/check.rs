//! The scene file's checks: every key known, every value in its range, every reference
//! declared, no output an input or another step's output (the invariant of [`super`]).

use super::*;
use crate::error::{Error, Result};
use crate::voxel::place::{valid_scale, valid_scale_range};

impl Scene {
    /// Every check that needs no file system.
    pub(super) fn check(&self) -> Result<()> {
        if self.version != VERSION {
            return Err(key_error(
                "version",
                format!("is {}, this dbms reads version {VERSION}", self.version),
                "write version = 1",
            ));
        }
        if let Some(cell) = self.database.cell {
            positive("database.cell", cell)?;
        }
        if let Some([x0, y0, x1, y1]) = self.database.bounds {
            if !(x0 < x1 && y0 < y1) || [x0, y0, x1, y1].iter().any(|v| !v.is_finite()) {
                return Err(key_error(
                    "database.bounds",
                    "is not [min_x, min_y, max_x, max_y] with min < max".into(),
                    "give the extent's corners, west-south first",
                ));
            }
        }
        if let Some(t) = &self.terrain.photo_time {
            check_time("terrain.photo_time", t)?;
        }
        if let Some(m) = &self.materials {
            if m.landcover.is_some() != m.legend.is_some() {
                return Err(key_error(
                    "materials",
                    "gives one of landcover and legend: a land-cover raster's codes need their legend".into(),
                    "give both, e.g. landcover = \"worldcover.tif\" and legend = \"esa_worldcover\"",
                ));
            }
        }
        if self.buildings.is_some() && self.terrain.photo_time.is_none() {
            return Err(key_error(
                "buildings",
                "measures heights from the photo's shadows, but terrain.photo_time is not given"
                    .into(),
                "give terrain.photo_time, the UTC time the orthophoto was taken",
            ));
        }
        self.check_insets()?;
        for (name, object) in &self.objects {
            object.check(&format!("objects.{name}"))?;
        }
        for (k, p) in self.placements.iter().enumerate() {
            let key = format!("placements[{k}]");
            if !self.objects.contains_key(&p.object) {
                return Err(key_error(
                    &format!("{key}.object"),
                    format!("names {:?}, which [objects] does not declare", p.object),
                    "declare it as [objects.NAME], or fix the name",
                ));
            }
            p.check(&key)?;
        }
        if self.products.is_empty() {
            return Err(key_error(
                "products",
                "is empty: the build would deliver nothing".into(),
                "add a [products.NAME] with sensor = \"visual\" and tiles = \"FILE.dbt\"",
            ));
        }
        for (name, product) in &self.products {
            product.check(&format!("products.{name}"))?;
        }
        if let Some(BuildSpec { shards }) = self.build {
            if !(1..=MAX_SHARDS).contains(&shards) {
                return Err(key_error(
                    "build.shards",
                    format!("is {shards}, not from 1 to {MAX_SHARDS}"),
                    "give the number of jobs each visual product is cut into (1: one job)",
                ));
            }
        }
        Ok(())
    }

    /// Each inset's own keys; parents declared, no inset nested in itself; siblings given by
    /// bounds apart, and a child given by bounds inside its parent's bounds (the rest, which
    /// needs the grid, `dbms ingest --inset` checks).
    fn check_insets(&self) -> Result<()> {
        for (name, inset) in &self.insets {
            inset.check(name)?;
            if let Some(p) = inset
                .parent
                .as_ref()
                .filter(|p| !self.insets.contains_key(*p))
            {
                return Err(key_error(
                    &format!("insets.{name}.parent"),
                    format!("names {p:?}, which [insets] does not declare"),
                    "declare it as [insets.NAME], or leave parent out to refine the base grid",
                ));
            }
        }
        self.inset_order()?;
        let with_bounds: Vec<(&String, &Inset, &[f64; 4])> = self
            .insets
            .iter()
            .filter_map(|(n, i)| Some((n, i, i.bounds.as_ref()?)))
            .collect();
        for (k, (name, inset, b)) in with_bounds.iter().enumerate() {
            let parent = inset.parent.as_ref();
            if let Some((other, _, _)) = with_bounds[..k]
                .iter()
                .find(|(_, i, o)| i.parent.as_ref() == parent && rects_overlap(b, o))
            {
                let refined = parent.map_or("the base grid".into(), |p| format!("inset {p}"));
                return Err(key_error(
                    &format!("insets.{name}.bounds"),
                    format!("overlap insets.{other}.bounds (both refine {refined})"),
                    &format!(
                        "move or shrink one off the other, or nest it with parent = \"{other}\""
                    ),
                ));
            }
            let outer = parent.and_then(|p| Some((p, self.insets[p].bounds.as_ref()?)));
            if let Some((p, o)) = outer {
                if !(b[0] >= o[0] && b[1] >= o[1] && b[2] <= o[2] && b[3] <= o[3]) {
                    return Err(key_error(
                        &format!("insets.{name}.bounds"),
                        format!("reach outside insets.{p}.bounds, the inset it refines"),
                        "give bounds inside its parent's",
                    ));
                }
            }
        }
        Ok(())
    }

    /// The inputs exist, and no file the build writes is an input or another output
    /// ([`crate::scene::plan::check_written`]).
    pub(super) fn check_paths(&self) -> Result<()> {
        for (key, path) in &self.inputs() {
            if !path.is_file() {
                return Err(key_error(
                    key,
                    format!("{} does not exist", path.display()),
                    "give a path relative to the scene file, or an absolute one",
                ));
            }
        }
        crate::scene::plan::check_written(self)
    }
}

impl ObjectSpec {
    fn check(&self, key: &str) -> Result<()> {
        match self {
            ObjectSpec::Cone {
                height,
                radius,
                voxel,
                vary,
                ..
            } => {
                positive(&format!("{key}.height"), *height)?;
                positive(&format!("{key}.radius"), *radius)?;
                positive(&format!("{key}.voxel"), *voxel)?;
                if !(0.0..1.0).contains(vary) {
                    return Err(key_error(
                        &format!("{key}.vary"),
                        format!("is {vary}, outside [0, 1)"),
                        "give a relative variation such as 0.2",
                    ));
                }
            }
            ObjectSpec::Revolve { profile, voxel } => {
                positive(&format!("{key}.voxel"), *voxel)?;
                if profile.len() < 2 || profile.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(key_error(
                        &format!("{key}.profile"),
                        "needs at least two [radius, z] pairs of numbers".into(),
                        "e.g. profile = [[6, 0], [6, 8], [0, 9.5]]",
                    ));
                }
            }
        }
        Ok(())
    }
}

impl Product {
    /// What each sensor needs and refuses: `ir` a `time` (its temperatures') and no sun;
    /// `nvg` and `radar` no time or sun (their tile files do not depend on one); `radar` its
    /// `radar`; `lights` only for `nvg`, `radar` only for `radar`.
    fn check_sensor(&self, key: &str) -> Result<()> {
        let sensor = self.sensor.as_str();
        let refuse = |field: &str, why: &str| {
            Err(key_error(
                &format!("{key}.{field}"),
                format!("is given, but {why}"),
                &format!("remove it from a {sensor} product"),
            ))
        };
        if self.sun.is_some() && sensor != "visual" {
            return refuse("sun", "only a visual product is shaded for a sun");
        }
        if self.time.is_some() && matches!(sensor, "nvg" | "radar") {
            return refuse("time", "this tile file does not depend on one (night vision takes it when rendering: dbms render --time)");
        }
        if self.lights.is_some() && sensor != "nvg" {
            return refuse("lights", "only a night-vision product carries light points");
        }
        if self.radar.is_some() && sensor != "radar" {
            return refuse("radar", "only a radar product has a radar look");
        }
        if let Some((k, _, _)) = self.conditions.weather().first().filter(|_| sensor != "ir") {
            return refuse(
                &format!("conditions.{k}"),
                "only an infrared product's temperatures depend on the weather",
            );
        }
        if sensor == "ir" && self.time.is_none() {
            return Err(key_error(
                key,
                "is an ir product without a time: its temperatures are for an instant".into(),
                "add time = \"2026-09-15T13:00:00Z\" (RFC 3339 UTC)",
            ));
        }
        match (&self.radar, sensor) {
            (None, "radar") => Err(key_error(
                key,
                "is a radar product without a radar look".into(),
                "add radar = { azimuth = 220, elevation = 20, band = \"X\" }",
            )),
            (Some(r), _) => {
                crate::radar_map::parse_band(&r.band).map_err(|e| {
                    key_error(
                        &format!("{key}.radar.band"),
                        format!("is {:?}, not a radar band ({})", r.band, e.problem),
                        "give one of L, S, C, X, Ku, Ka, W",
                    )
                })?;
                let above = r.elevation > 0.0 && r.elevation < 90.0;
                let look = Look("radar", r.elevation, r.azimuth);
                look.check(&format!("{key}.radar"), above, "(0, 90)")
            }
            _ => Ok(()),
        }
    }

    fn check(&self, key: &str) -> Result<()> {
        if !SENSORS.contains(&self.sensor.as_str()) {
            return Err(key_error(
                &format!("{key}.sensor"),
                format!("is {:?}, which this dbms does not build", self.sensor),
                &format!("give one of {}", SENSORS.join(", ")),
            ));
        }
        self.check_sensor(key)?;
        match (&self.time, &self.sun) {
            (Some(_), Some(_)) => {
                return Err(key_error(
                    key,
                    "gives both time and sun: a product has one sun".into(),
                    "keep one of them",
                ))
            }
            (Some(t), None) => check_time(&format!("{key}.time"), t)?,
            (None, Some(s)) => {
                let above = s.elevation > 0.0 && s.elevation <= 90.0;
                let look = Look("sun", s.elevation, s.azimuth);
                look.check(&format!("{key}.sun"), above, "(0, 90]")?;
            }
            (None, None) => {}
        }
        if let Some(v) = self.conditions.visibility_m {
            positive(&format!("{key}.conditions.visibility_m"), v)?;
        }
        let name = |k: &str| format!("{key}.conditions.{k}");
        let names = ["air_temp_c", "air_range_k", "wind_m_s", "humidity"].map(name);
        let names = [&*names[0], &*names[1], &*names[2], &*names[3]];
        self.conditions.thermal().check_named(names)
    }
}
/// A direction a product gives (the sun's, the radar's): what it is, its elevation and its
/// azimuth, degrees.
struct Look(&'static str, f64, f64);

impl Look {
    /// An error naming `key` unless the azimuth is finite and the elevation `above` the horizon
    /// (`range` says which degrees are): each named for what is wrong.
    fn check(&self, key: &str, above: bool, range: &str) -> Result<()> {
        let Look(what, elevation, azimuth) = *self;
        if !azimuth.is_finite() {
            return Err(key_error(
                &format!("{key}.azimuth"),
                format!("is {azimuth}: the {what}'s azimuth must be a finite number of degrees"),
                "give degrees clockwise from grid north",
            ));
        }
        if !above {
            return Err(key_error(
                &format!("{key}.elevation"),
                format!("is {elevation}: the {what} must be above the horizon, {range} degrees"),
                "give degrees above the horizon",
            ));
        }
        Ok(())
    }
}

/// An error about the value of `key`.
pub(in crate::scene) fn key_error(key: &str, problem: String, fix: &str) -> Error {
    let e = Error::msg(format!("{key} {problem}"));
    if fix.is_empty() {
        e
    } else {
        e.fix(fix)
    }
}

/// An error unless `v` is a positive finite number.
fn positive(key: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(key_error(key, format!("is {v}, not a positive number"), ""))
    }
}

/// An error unless `t` is an RFC 3339 time.
fn check_time(key: &str, t: &str) -> Result<()> {
    crate::sun::parse_time(t).map(|_| ()).map_err(|_| {
        key_error(
            key,
            format!("{t:?} is not an RFC 3339 time"),
            "write it like 2026-06-21T10:00:00Z (the offset is required)",
        )
    })
}

impl Inset {
    /// Name, factor, exactly one of bounds and corridor, each in range, and its photo time.
    fn check(&self, name: &str) -> Result<()> {
        let key = format!("insets.{name}");
        crate::inset::check_name(name).map_err(|_| {
            key_error(
                &key,
                "is not a plain inset name: it names the directory DB/insets/NAME".into(),
                "name it with 1 to 64 letters, digits, - or _ (not starting with -), e.g. town",
            )
        })?;
        let f = self.factor;
        if !(f.fract() == 0.0 && f >= 0.0 && crate::inset::FACTORS.contains(&(f as usize))) {
            let (lo, hi) = (crate::inset::FACTORS.start(), crate::inset::FACTORS.end());
            return Err(key_error(
                &format!("{key}.factor"),
                format!("is {f}, not a whole number from {lo} to {hi}"),
                "give the parent cells per inset cell, e.g. 4 (0.25 m cells become 0.0625 m); nest insets for more than 10",
            ));
        }
        match (&self.bounds, &self.corridor) {
            (Some([x0, y0, x1, y1]), None) => {
                if !(x0 < x1 && y0 < y1) || [x0, y0, x1, y1].iter().any(|v| !v.is_finite()) {
                    return Err(key_error(
                        &format!("{key}.bounds"),
                        "is not [min_x, min_y, max_x, max_y] with min < max".into(),
                        "give the window's corners, west-south first, on the parent's cell edges",
                    ));
                }
            }
            (None, Some(c)) => {
                if !(c.buffer.is_finite() && c.buffer >= 0.0) {
                    return Err(key_error(
                        &format!("{key}.corridor.buffer"),
                        format!("is {}, not a distance ≥ 0 in metres", c.buffer),
                        "e.g. corridor = { route = \"road.geojson\", buffer = 30 }",
                    ));
                }
            }
            _ => {
                return Err(key_error(
                    &key,
                    "needs exactly one of bounds and corridor".into(),
                    "bounds = [min_x, min_y, max_x, max_y] refines a rectangle; corridor = { route = \"FILE.geojson\", buffer = METRES } the cells along a route",
                ))
            }
        }
        if let Some(t) = &self.photo_time {
            check_time(&format!("{key}.photo_time"), t)?;
        }
        Ok(())
    }
}

/// Whether two `[min_x, min_y, max_x, max_y]` rectangles share an area.
fn rects_overlap(a: &[f64; 4], b: &[f64; 4]) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

impl Placement {
    /// Exactly one of `at` and `points`, each with only its own keys, and numbers in range.
    fn check(&self, key: &str) -> Result<()> {
        let with_points = [
            ("random_heading", self.random_heading.is_some()),
            ("scale_range", self.scale_range.is_some()),
            ("seed", self.seed.is_some()),
        ];
        let with_at = [
            ("heading", self.heading.is_some()),
            ("scale", self.scale.is_some()),
        ];
        let (given, fix) = match (&self.at, &self.points) {
            (Some(_), None) => (
                with_points.iter().find(|k| k.1),
                "it goes with points = \"FILE.geojson\", not at: remove it",
            ),
            (None, Some(_)) => (
                with_at.iter().find(|k| k.1),
                "it goes with at, not points: give it as each point's property instead",
            ),
            _ => {
                return Err(key_error(
                    key,
                    "needs exactly one of at and points".into(),
                    "at = [x, y] places one object; points = \"FILE.geojson\" one per point",
                ))
            }
        };
        if let Some((name, _)) = given {
            return Err(key_error(
                &format!("{key}.{name}"),
                "is not allowed here".into(),
                fix,
            ));
        }
        let at = self.at.as_deref().unwrap_or_default();
        if !(at.is_empty() || at.len() == 2 || at.len() == 3) {
            return Err(key_error(
                &format!("{key}.at"),
                format!("has {} numbers, not [x, y] or [x, y, z]", at.len()),
                "give the anchor's x and y, and its absolute height z if it is not the ground's",
            ));
        }
        if at.iter().chain(&self.heading).any(|v| !v.is_finite()) {
            return Err(key_error(
                key,
                "has a value that is not a number".into(),
                "",
            ));
        }
        if let Some(k) = self.scale.filter(|&k| !valid_scale(k)) {
            return Err(key_error(
                &format!("{key}.scale"),
                format!("is {k}, not a number above 0"),
                "1 places the object as made",
            ));
        }
        if let Some([lo, hi]) = self
            .scale_range
            .filter(|&[lo, hi]| !valid_scale_range(lo, hi))
        {
            return Err(key_error(
                &format!("{key}.scale_range"),
                format!("is [{lo}, {hi}]"),
                "give [min, max] with 0 < min <= max",
            ));
        }
        Ok(())
    }
}
