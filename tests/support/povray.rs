//! Independent-truth scenes for `dbms shadow-height`: orthophotos rendered by POV-Ray.
//!
//! POV-Ray shares no code and no conventions with dbms: the scene is stated as geometry (a
//! ground plane, buildings as CSG solids, a parallel sun) and POV-Ray's own ray tracer decides
//! every pixel — shadows, anti-aliased edges, shading. dbms then sees only what a modeller has:
//! a PNG with a world file, an Esri ASCII DEM, footprints in GeoJSON. The truth is the geometry
//! written into the scene, never anything dbms computed.
//!
//! Conventions of this generator (its own, stated here): world coordinates are metres east and
//! north; the image covers `size` cells of `cell` metres from the world corner `origin` (west,
//! north), one pixel per cell. POV-Ray's axes are x = east, y = up, z = north; its orthographic
//! camera looks straight down with +z (north) up the image and +x (east) to the right. Scene
//! coordinates are kept local (relative to `origin`) so POV-Ray never sees UTM-sized numbers;
//! the world file and DEM carry the offset.
//!
//! Buildings are [`Structure`]s: rectangles ([`Building`], isolated boxes) or arbitrary simple
//! polygons ([`PolygonBuilding`], a real town's footprints: tests/support/town.rs), each with a
//! flat, gable or hip [`Roof`]. How the photo is made beyond the geometry — a soft sun (the
//! solar disc as an area light), sRGB encoding, JPEG compression, the CRS label — is a
//! [`Photo`]; [`Scene::write`] is [`Scene::write_photo`] with the default (hard parallel sun,
//! linear PNG), as it always was.
//!
//! Used by `tests/povray_shadow_height.rs` (a small slice, in CI) and
//! `benches/shadow_height_povray.rs` (the table in docs/shadow-height.md), and for the real
//! town by `tests/povray_town.rs` and `benches/shadow_height_town.rs`.

#![allow(dead_code)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// WKT of the harness's default CRS label (WGS 84 / UTM zone 32N, [`Photo::default`]); numbers
/// are only labels to dbms here.
pub const UTM32N_WKT: &str = r#"PROJCS["WGS 84 / UTM zone 32N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4326"]],PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",0],PARAMETER["central_meridian",9],PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],PARAMETER["false_northing",0],UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["Easting",EAST],AXIS["Northing",NORTH],AUTHORITY["EPSG","32632"]]"#;

/// A roof shape over a footprint.
///
/// Pitched roofs follow one convention (dbms states roofs the same way). Take the ridge
/// direction — a [`Building`]'s first side (`rotation_deg`), a [`PolygonBuilding`]'s
/// `ridge_azimuth_deg` — and project the footprint's vertices onto it (`along`, a) and across
/// it (`across`, c): the extent is [a0, a1] × [c0, c1]; half-width w = (c1 − c0)/2, centre-line
/// c_m = (c0 + c1)/2, half-length l = (a1 − a0)/2, a_m = (a0 + a1)/2.
/// Gable: z(p) = eave_z + (ridge_z − eave_z)·(1 − |c(p) − c_m|/w).
/// Hip: z(p) = min(gable z(p), eave_z + (ridge_z − eave_z)·(l − |a(p) − a_m|)/w), equal pitch
/// on all four faces. The roof is clipped to the footprint's prism.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Roof {
    /// Flat at absolute height `z`, metres.
    Flat { z: f64 },
    /// Two planes meeting at a ridge along the ridge direction: eaves at `eave_z`, ridge at
    /// `ridge_z`, absolute metres.
    Gable { eave_z: f64, ridge_z: f64 },
    /// Four planes of equal pitch: the gable's two plus two hips at the ends.
    Hip { eave_z: f64, ridge_z: f64 },
}

impl Roof {
    /// The highest point of the roof (the ridge, or the flat roof), absolute metres.
    pub fn top_z(&self) -> f64 {
        match *self {
            Roof::Flat { z } => z,
            Roof::Gable { ridge_z, .. } | Roof::Hip { ridge_z, .. } => ridge_z,
        }
    }

    /// The eaves (the flat roof's height for a flat roof), absolute metres.
    pub fn eave_z(&self) -> f64 {
        match *self {
            Roof::Flat { z } => z,
            Roof::Gable { eave_z, .. } | Roof::Hip { eave_z, .. } => eave_z,
        }
    }

    /// `"flat"`, `"gable"` or `"hip"`.
    pub fn form(&self) -> &'static str {
        match self {
            Roof::Flat { .. } => "flat",
            Roof::Gable { .. } => "gable",
            Roof::Hip { .. } => "hip",
        }
    }
}

/// What a scene's buildings are: a footprint dbms is given and a solid POV-Ray renders.
pub trait Structure: Clone {
    /// The footprint's outer ring, world metres (east, north), not closed.
    fn outline(&self) -> Vec<(f64, f64)>;
    /// The roof.
    fn roof(&self) -> Roof;
    /// Whether the footprint is written to the footprint file (`false`: rendered but unlisted,
    /// as buildings missing from a real footprint layer).
    fn listed(&self) -> bool {
        true
    }
    /// The POV-Ray solid (CSG) of the building in `scene`'s local frame.
    fn pov<B: Structure>(&self, scene: &Scene<B>) -> String;
}

impl Structure for Building {
    fn outline(&self) -> Vec<(f64, f64)> {
        self.corners().to_vec()
    }
    fn roof(&self) -> Roof {
        self.roof
    }
    fn pov<B: Structure>(&self, scene: &Scene<B>) -> String {
        scene.building_pov(self)
    }
}

/// A building on an arbitrary simple polygon (no holes: a real footprint's holes are filled
/// before it gets here), with a roof whose ridge runs along `ridge_azimuth_deg` ([`Roof`]'s
/// convention).
#[derive(Debug, Clone, PartialEq)]
pub struct PolygonBuilding {
    /// Outer ring, world metres (east, north), not closed, either orientation.
    pub outline: Vec<(f64, f64)>,
    /// Roof (absolute metres).
    pub roof: Roof,
    /// Ridge direction of a gable or hip roof, degrees clockwise from grid north, in [0, 180)
    /// (ignored for a flat roof).
    pub ridge_azimuth_deg: f64,
    /// Roof colour, linear RGB in [0, 1].
    pub colour: [f64; 3],
    /// Whether its footprint is written to the footprint file ([`Structure::listed`]).
    pub listed: bool,
}

/// `along`, `across` (unit vectors, east and north), (a0, a1), (c0, c1) (metres): see
/// [`PolygonBuilding::ridge_frame`].
pub type RidgeFrame = ((f64, f64), (f64, f64), (f64, f64), (f64, f64));

impl PolygonBuilding {
    /// The ridge frame of [`Roof`]'s convention: unit vectors `along` and `across` (east,
    /// north), and the footprint's extent along them, ((a0, a1), (c0, c1)), metres, in world
    /// coordinates relative to `origin`.
    pub fn ridge_frame(&self, origin: (f64, f64)) -> RidgeFrame {
        let (s, c) = self.ridge_azimuth_deg.to_radians().sin_cos();
        let along = (s, c);
        let across = (c, -s);
        let (mut a, mut cc) = (
            (f64::INFINITY, f64::NEG_INFINITY),
            (f64::INFINITY, f64::NEG_INFINITY),
        );
        for &(x, y) in &self.outline {
            let (x, y) = (x - origin.0, y - origin.1);
            let pa = x * along.0 + y * along.1;
            let pc = x * across.0 + y * across.1;
            a = (a.0.min(pa), a.1.max(pa));
            cc = (cc.0.min(pc), cc.1.max(pc));
        }
        (along, across, a, cc)
    }

    /// The roof's height at world point `p` by [`Roof`]'s formulas (not clipped to the
    /// footprint), absolute metres.
    pub fn roof_z_at(&self, p: (f64, f64)) -> f64 {
        let (eave_z, ridge_z, hip) = match self.roof {
            Roof::Flat { z } => return z,
            Roof::Gable { eave_z, ridge_z } => (eave_z, ridge_z, false),
            Roof::Hip { eave_z, ridge_z } => (eave_z, ridge_z, true),
        };
        let (along, across, a, c) = self.ridge_frame((0.0, 0.0));
        let (w, cm) = ((c.1 - c.0) / 2.0, (c.0 + c.1) / 2.0);
        let (l, am) = ((a.1 - a.0) / 2.0, (a.0 + a.1) / 2.0);
        let pc = p.0 * across.0 + p.1 * across.1;
        let pa = p.0 * along.0 + p.1 * along.1;
        let gable = eave_z + (ridge_z - eave_z) * (1.0 - (pc - cm).abs() / w);
        if hip {
            gable.min(eave_z + (ridge_z - eave_z) * (l - (pa - am).abs()) / w)
        } else {
            gable
        }
    }
}

impl Structure for PolygonBuilding {
    fn outline(&self) -> Vec<(f64, f64)> {
        self.outline.clone()
    }
    fn roof(&self) -> Roof {
        self.roof
    }
    fn listed(&self) -> bool {
        self.listed
    }
    fn pov<B: Structure>(&self, scene: &Scene<B>) -> String {
        scene.polygon_pov(self)
    }
}

/// A building: a rectangle (centre, full sides along its axis and across, rotation of its
/// first side from east counter-clockwise, degrees) with a roof.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Building {
    /// Centre, world metres (east, north).
    pub centre: (f64, f64),
    /// Side along the rectangle's axis (the ridge), and across it, metres.
    pub size: (f64, f64),
    /// Direction of the first side, degrees counter-clockwise from east.
    pub rotation_deg: f64,
    /// Roof.
    pub roof: Roof,
    /// Roof colour, linear RGB in [0, 1].
    pub colour: [f64; 3],
}

impl Building {
    /// The rectangle's corners, counter-clockwise, world metres.
    pub fn corners(&self) -> [(f64, f64); 4] {
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let (a, b) = (self.size.0 / 2.0, self.size.1 / 2.0);
        [(-a, -b), (a, -b), (a, b), (-a, b)]
            .map(|(x, y)| (self.centre.0 + x * c - y * s, self.centre.1 + x * s + y * c))
    }
}

/// Something standing on the ground that is not a building: it casts shadow and hides ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clutter {
    /// A tree: crown of `radius` metres whose top is `height` metres above the ground at
    /// `at`, on a trunk.
    Tree {
        at: (f64, f64),
        radius: f64,
        height: f64,
    },
    /// A vehicle: a box `size` (length, width, height) metres at `at`, rotated `heading_deg`.
    Vehicle {
        at: (f64, f64),
        size: (f64, f64, f64),
        heading_deg: f64,
    },
}

/// How the photo was taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Camera {
    /// A true orthophoto: every pixel looks straight down.
    Ortho,
    /// A vertical frame photo from `height_m` above the (flat) ground at world point `nadir`,
    /// rectified on the bare ground: the ground is in place, anything standing leans away from
    /// the nadir (relief displacement). Valid on flat ground only.
    Perspective { nadir: (f64, f64), height_m: f64 },
}

/// One scene; its buildings are rectangles ([`Building`], the default) or any other
/// [`Structure`] ([`PolygonBuilding`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Scene<B = Building> {
    /// World coordinates of the image's north-west corner, metres.
    pub origin: (f64, f64),
    /// Cell (pixel) size, metres.
    pub cell: f64,
    /// Image size in cells (columns, rows).
    pub size: (usize, usize),
    /// Ground height at `origin`, metres, and its gradient (rise per metre east, per metre north).
    pub ground: (f64, f64, f64),
    /// Sun azimuth, degrees clockwise from grid north, toward the sun.
    pub sun_azimuth_deg: f64,
    /// Sun elevation above the horizon, degrees.
    pub sun_elevation_deg: f64,
    /// Buildings.
    pub buildings: Vec<B>,
    /// Non-building objects.
    pub clutter: Vec<Clutter>,
    /// Misregistration: the footprints written are the true ones moved by this, metres (east,
    /// north), as footprints from another source sit off the photo.
    pub footprint_shift: (f64, f64),
    /// The camera.
    pub camera: Camera,
    /// Anti-aliasing: POV-Ray's non-adaptive `n × n` samples per pixel (1 = none; 2..=9).
    /// See [`antialias_for`].
    pub antialias: u32,
}

/// The anti-aliasing depth that keeps POV-Ray's own edge error small beside what it is there
/// to measure, for a sun at `elevation_deg` (degrees).
///
/// POV-Ray's non-adaptive method (`+AM1 +Rn`) samples an `n × n` grid that *includes the
/// pixel's borders* (offsets −½, …, +½). A straight edge across a pixel is read as the share of
/// samples on each side, in steps of `1/n`, off the true cover by up to `1/n` of a cell: with
/// `n = 3` a roof covering 0.475 of a pixel renders as 1/3. A shadow-length error is a
/// height error times `tan(elevation)`: at an 80° sun that is 5.7 × — a third of a cell on
/// both the roof's edge and the shadow's tip put a 1 m truth off by up to 2 m on its own
/// (axis-aligned edges, whose every pixel errs alike). So a sun from 60° up gets POV-Ray's
/// deepest grid, 9 × 9 (an edge within 1/9 cell; ~5 × the render time at 0.25 m cells).
pub fn antialias_for(elevation_deg: f64) -> u32 {
    if elevation_deg >= 60.0 {
        9
    } else {
        3
    }
}

/// Paths of a written scene.
pub struct Written {
    pub dir: PathBuf,
    pub ortho: PathBuf,
    pub dem: PathBuf,
    pub footprints: PathBuf,
}

/// How the photo is made, beyond the scene's geometry. [`Photo::default`] is the harness's
/// original photo: a hard parallel sun, a linear PNG, CRS labelled UTM 32N.
#[derive(Debug, Clone, PartialEq)]
pub struct Photo {
    /// The sun as a disc of this angular diameter, degrees (the real sun: 0.53), rendered as
    /// POV-Ray's area light (a circular grid of `area_samples` × `area_samples` lights, adaptive,
    /// deterministic: no jitter), so shadows have penumbrae. `None`: a point-like parallel sun
    /// (hard shadows).
    pub sun_disc_deg: Option<f64>,
    /// Area-light grid size (lights across the disc) for a soft sun.
    pub area_samples: u32,
    /// Encode the PNG in sRGB (POV-Ray `File_Gamma=sRGB`) instead of linear values.
    pub srgb: bool,
    /// Re-encode the photo as JPEG at this quality (1–100; the `image` crate's encoder):
    /// `ortho.jpg` with `ortho.jgw` is what dbms reads. `None`: the PNG.
    pub jpeg_quality: Option<u8>,
    /// WKT written as the photo's and DEM's `.prj` (a label only: dbms takes the sun's azimuth
    /// from grid north).
    pub crs_wkt: &'static str,
}

impl Default for Photo {
    fn default() -> Self {
        Photo {
            sun_disc_deg: None,
            area_samples: 9,
            srgb: false,
            jpeg_quality: None,
            crs_wkt: UTM32N_WKT,
        }
    }
}

/// WKT of WGS 84 / UTM zone 13N (EPSG:32613), the real town's CRS (tests/data/boulder/).
pub const UTM13N_WKT: &str = r#"PROJCS["WGS 84 / UTM zone 13N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4326"]],PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",0],PARAMETER["central_meridian",-105],PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],PARAMETER["false_northing",0],UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["Easting",EAST],AXIS["Northing",NORTH],AUTHORITY["EPSG","32613"]]"#;

impl<B: Structure> Scene<B> {
    /// World extent: (west, south, east, north), metres.
    pub fn extent(&self) -> (f64, f64, f64, f64) {
        let (w, n) = self.origin;
        let e = w + self.size.0 as f64 * self.cell;
        let s = n - self.size.1 as f64 * self.cell;
        (w, s, e, n)
    }

    /// Ground height at world point `p`, metres.
    pub fn ground_z(&self, p: (f64, f64)) -> f64 {
        let (z0, gx, gy) = self.ground;
        z0 + gx * (p.0 - self.origin.0) + gy * (p.1 - self.origin.1)
    }

    /// Local POV-Ray coordinates (x east, z north) of world point `p`.
    fn local(&self, p: (f64, f64)) -> (f64, f64) {
        (p.0 - self.origin.0, p.1 - self.origin.1)
    }

    /// Unit vector toward the sun (east, north, up).
    fn toward_sun(&self) -> (f64, f64, f64) {
        let (a, e) = (
            self.sun_azimuth_deg.to_radians(),
            self.sun_elevation_deg.to_radians(),
        );
        (a.sin() * e.cos(), a.cos() * e.cos(), e.sin())
    }

    /// The POV-Ray scene description (the default [`Photo`]'s hard sun).
    pub fn pov(&self) -> String {
        self.pov_photo(&Photo::default())
    }

    /// The POV-Ray scene description, with `photo`'s sun.
    pub fn pov_photo(&self, photo: &Photo) -> String {
        let mut s = String::new();
        let (width, height) = (
            self.size.0 as f64 * self.cell,
            self.size.1 as f64 * self.cell,
        );
        // Image centre, local: x = width / 2, z = −height / 2 (origin is the north-west corner).
        let (cx, cz) = (width / 2.0, -height / 2.0);
        let (z0, gx, gy) = self.ground;
        let zmax = self
            .buildings
            .iter()
            .map(|b| b.roof().top_z())
            .fold(z0.abs() + 1000.0, f64::max);
        writeln!(s, "#version 3.7;").unwrap();
        writeln!(
            s,
            "global_settings {{ assumed_gamma 1.0 ambient_light rgb <1,1,1> max_trace_level 5 }}"
        )
        .unwrap();
        match self.camera {
            Camera::Ortho => {
                writeln!(
                    s,
                    "camera {{ orthographic location <{cx:.6}, {top:.6}, {cz:.6}> \
                     direction <0, -1, 0> right <{width:.6}, 0, 0> up <0, 0, {height:.6}> }}",
                    top = zmax + 100.0
                )
                .unwrap();
            }
            Camera::Perspective { nadir, height_m } => {
                // A vertical camera at `height_m` over the ground (z0 at the nadir) whose image
                // plane, put at ground level, is exactly the scene's extent: the ground maps to
                // its own cells (the rectification of a flat-ground photo), objects standing on
                // it lean away from the nadir.
                let (nx, nz) = self.local(nadir);
                let gz = self.ground_z(nadir);
                writeln!(
                    s,
                    "camera {{ perspective location <{nx:.6}, {eye:.6}, {nz:.6}> \
                     direction <{dx:.6}, {dy:.6}, {dz:.6}> right <{width:.6}, 0, 0> up <0, 0, {height:.6}> }}",
                    eye = gz + height_m,
                    dx = cx - nx,
                    dy = -height_m,
                    dz = cz - nz
                )
                .unwrap();
            }
        }
        let (e, n, u) = self.toward_sun();
        match photo.sun_disc_deg {
            None => writeln!(
                s,
                "light_source {{ <{:.9}, {:.9}, {:.9}> color rgb <1.0, 0.97, 0.92> parallel point_at <0, 0, 0> }}",
                e * 1e6,
                u * 1e6,
                n * 1e6
            )
            .unwrap(),
            Some(disc) => {
                // The solar disc: a circular area light of the disc's diameter at the parallel
                // light's distance, its grid turned to face the scene (`orient`), every light's
                // rays parallel (`parallel`: each grid point shines along its own direction).
                // Two axes across the sun direction (POV-Ray: x east, y up, z north).
                let d = 1e6;
                let diameter = 2.0 * d * (disc.to_radians() / 2.0).tan();
                let h = e.hypot(n);
                let (p1, p2) = if h > 1e-12 {
                    // Horizontal, across the azimuth; and up the sky, across both.
                    let p1 = (-n / h, 0.0, e / h);
                    let p2 = (-u * e / h, h, -u * n / h);
                    (p1, p2)
                } else {
                    ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
                };
                let k = photo.area_samples.max(2);
                writeln!(
                    s,
                    "light_source {{ <{:.9}, {:.9}, {:.9}> color rgb <1.0, 0.97, 0.92> parallel point_at <0, 0, 0>\n  \
                     area_light <{:.9}, {:.9}, {:.9}>, <{:.9}, {:.9}, {:.9}>, {k}, {k} adaptive 1 circular orient }}",
                    e * d,
                    u * d,
                    n * d,
                    p1.0 * diameter,
                    p1.1 * diameter,
                    p1.2 * diameter,
                    p2.0 * diameter,
                    p2.1 * diameter,
                    p2.2 * diameter,
                )
                .unwrap()
            }
        }
        // Ground: a sloped plane through (0, z0, 0), textured like mixed grass and soil.
        writeln!(
            s,
            "plane {{ <{:.9}, 1, {:.9}>, 0 translate <0, {z0:.6}, 0>\n  \
             texture {{ pigment {{ bozo scale 2.3 turbulence 0.4 color_map {{ \
             [0.0 color rgb <0.16, 0.26, 0.09>] [0.5 color rgb <0.22, 0.30, 0.12>] \
             [0.7 color rgb <0.30, 0.28, 0.18>] [1.0 color rgb <0.24, 0.31, 0.13>] }} }}\n  \
             finish {{ ambient rgb <0.30, 0.33, 0.42> diffuse 0.75 }} }} }}",
            -gx, -gy
        )
        .unwrap();
        for b in &self.buildings {
            s.push_str(&b.pov(self));
        }
        for c in &self.clutter {
            s.push_str(&self.clutter_pov(c));
        }
        s
    }

    fn building_pov(&self, b: &Building) -> String {
        let corners = b.corners().map(|p| self.local(p));
        let base = corners
            .iter()
            .map(|&(x, z)| self.ground_z((x + self.origin.0, z + self.origin.1)))
            .fold(f64::INFINITY, f64::min)
            - 2.0;
        let top = b.roof.top_z();
        let mut s = String::new();
        let pts: Vec<String> = corners
            .iter()
            .chain(std::iter::once(&corners[0]))
            .map(|(x, z)| format!("<{x:.6}, {z:.6}>"))
            .collect();
        writeln!(s, "intersection {{").unwrap();
        writeln!(
            s,
            "  prism {{ linear_sweep linear_spline {base:.6}, {top:.6}, 5, {} }}",
            pts.join(", ")
        )
        .unwrap();
        // Roof planes: a plane keeps the side its normal points away from.
        let (sn, cs) = b.rotation_deg.to_radians().sin_cos();
        let along = (cs, sn); // ridge direction (east, north)
        let across = (-sn, cs);
        let (cx, cz) = self.local(b.centre);
        let (a, w) = (b.size.0 / 2.0, b.size.1 / 2.0);
        let mut plane = |dir: (f64, f64), half: f64, eave: f64, ridge: f64, run: f64| {
            // Height falls from `ridge` at distance `half − run` from the centre along `dir` to
            // `eave` at `half`: z = ridge − (ridge − eave)/run · (d − (half − run)).
            let k = (ridge - eave) / run;
            // Plane: k·d + z = ridge + k·(half − run), d = (p − c)·dir. Normal (k·dir, 1).
            let d0 = ridge + k * (half - run) + k * (cx * dir.0 + cz * dir.1);
            let norm = (k * k + 1.0).sqrt();
            writeln!(
                s,
                "  plane {{ <{:.9}, {:.9}, {:.9}>, {:.9} }}",
                k * dir.0 / norm,
                1.0 / norm,
                k * dir.1 / norm,
                d0 / norm
            )
            .unwrap();
        };
        match b.roof {
            Roof::Flat { .. } => {}
            Roof::Gable { eave_z, ridge_z } => {
                for sign in [1.0, -1.0] {
                    plane((across.0 * sign, across.1 * sign), w, eave_z, ridge_z, w);
                }
            }
            Roof::Hip { eave_z, ridge_z } => {
                for sign in [1.0, -1.0] {
                    plane((across.0 * sign, across.1 * sign), w, eave_z, ridge_z, w);
                    plane((along.0 * sign, along.1 * sign), a, eave_z, ridge_z, w);
                }
            }
        }
        let [r, g, bl] = b.colour;
        writeln!(
            s,
            "  texture {{ pigment {{ color rgb <{r:.4}, {g:.4}, {bl:.4}> }} \
             finish {{ ambient rgb <0.30, 0.33, 0.42> diffuse 0.75 }} }}\n}}"
        )
        .unwrap();
        s
    }

    /// A polygon building: its footprint's prism from below the ground to the ridge,
    /// intersected with the roof's half-spaces ([`Roof`]'s convention: each face is a plane, the
    /// roof is their minimum).
    fn polygon_pov(&self, b: &PolygonBuilding) -> String {
        let pts: Vec<(f64, f64)> = b.outline.iter().map(|&p| self.local(p)).collect();
        let base = b
            .outline
            .iter()
            .map(|&p| self.ground_z(p))
            .fold(f64::INFINITY, f64::min)
            - 2.0;
        let top = b.roof.top_z();
        let mut s = String::new();
        let ring: Vec<String> = pts
            .iter()
            .chain(std::iter::once(&pts[0]))
            .map(|(x, z)| format!("<{x:.6}, {z:.6}>"))
            .collect();
        writeln!(s, "intersection {{").unwrap();
        writeln!(
            s,
            "  prism {{ linear_sweep linear_spline {base:.6}, {top:.6}, {}, {} }}",
            ring.len(),
            ring.join(", ")
        )
        .unwrap();
        let (along, across, a, c) = b.ridge_frame(self.origin);
        let (w, cm) = ((c.1 - c.0) / 2.0, (c.0 + c.1) / 2.0);
        let (l, am) = ((a.1 - a.0) / 2.0, (a.0 + a.1) / 2.0);
        // z = base_z + k·(m − d) with d = p·dir (local): k·(p·dir) + z = base_z + k·m.
        let mut plane = |dir: (f64, f64), base_z: f64, m: f64, k: f64| {
            let d0 = base_z + k * m;
            let norm = (k * k + 1.0).sqrt();
            writeln!(
                s,
                "  plane {{ <{:.9}, {:.9}, {:.9}>, {:.9} }}",
                k * dir.0 / norm,
                1.0 / norm,
                k * dir.1 / norm,
                d0 / norm
            )
            .unwrap();
        };
        let faces = |eave: f64, ridge: f64| (ridge - eave) / w;
        match b.roof {
            Roof::Flat { .. } => {}
            Roof::Gable { eave_z, ridge_z } | Roof::Hip { eave_z, ridge_z } => {
                let k = faces(eave_z, ridge_z);
                // Gable faces: z = ridge − k·|c − c_m|, one plane per sign.
                for sign in [1.0, -1.0] {
                    plane((across.0 * sign, across.1 * sign), ridge_z, cm * sign, k);
                }
                if let Roof::Hip { .. } = b.roof {
                    // Hips: z = eave + k·(l − |a − a_m|) = (eave + k·l) − k·|a − a_m|.
                    for sign in [1.0, -1.0] {
                        plane(
                            (along.0 * sign, along.1 * sign),
                            eave_z + k * l,
                            am * sign,
                            k,
                        );
                    }
                }
            }
        }
        let [r, g, bl] = b.colour;
        writeln!(
            s,
            "  texture {{ pigment {{ color rgb <{r:.4}, {g:.4}, {bl:.4}> }} \
             finish {{ ambient rgb <0.30, 0.33, 0.42> diffuse 0.75 }} }}\n}}"
        )
        .unwrap();
        s
    }

    fn clutter_pov(&self, c: &Clutter) -> String {
        let finish = "finish { ambient rgb <0.30, 0.33, 0.42> diffuse 0.75 }";
        match *c {
            Clutter::Tree { at, radius, height } => {
                let (x, z) = self.local(at);
                let g = self.ground_z(at);
                format!(
                    "union {{ cylinder {{ <{x:.6}, {g0:.6}, {z:.6}>, <{x:.6}, {top:.6}, {z:.6}>, {tr:.4} }} \
                     sphere {{ <{x:.6}, {cy:.6}, {z:.6}>, {radius:.4} }} \
                     texture {{ pigment {{ color rgb <0.07, 0.16, 0.05> }} {finish} }} }}\n",
                    g0 = g - 1.0,
                    top = g + height - radius,
                    tr = (radius * 0.15).max(0.15),
                    cy = g + height - radius,
                )
            }
            Clutter::Vehicle {
                at,
                size,
                heading_deg,
            } => {
                let (x, z) = self.local(at);
                let g = self.ground_z(at);
                format!(
                    "box {{ <{:.4}, -1, {:.4}>, <{:.4}, {:.4}, {:.4}> rotate <0, {:.6}, 0> translate <{x:.6}, {g:.6}, {z:.6}> \
                     texture {{ pigment {{ color rgb <0.55, 0.08, 0.06> }} {finish} }} }}\n",
                    -size.0 / 2.0,
                    -size.1 / 2.0,
                    size.0 / 2.0,
                    size.2 + 1.0,
                    size.1 / 2.0,
                    // POV's `rotate y` turns x toward −z... (left-handed): a heading
                    // counter-clockwise from east is a negative rotation about +y.
                    -heading_deg,
                )
            }
        }
    }

    /// Write the scene into `dir` (created): `scene.pov`, `ortho.png` (rendered) with its world
    /// file and `.prj`, `dem.asc` (the ground at every cell centre) with its `.prj`, and
    /// `footprints.geojson` (moved by `footprint_shift`). Errors name what failed. The default
    /// [`Photo`]: [`Scene::write_photo`].
    pub fn write(&self, dir: &Path) -> Result<Written, String> {
        self.write_photo(dir, &Photo::default())
    }

    /// [`Scene::write`] with `photo`'s sun and encoding: with `jpeg_quality`, also `ortho.jpg`
    /// and `ortho.jgw` (then [`Written::ortho`]). The footprint file holds the
    /// [`Structure::listed`] buildings, each with property `id`, its index in `buildings`.
    pub fn write_photo(&self, dir: &Path, photo: &Photo) -> Result<Written, String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let put = |name: &str, text: &str| -> Result<PathBuf, String> {
            let p = dir.join(name);
            std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
            Ok(p)
        };
        let pov = put("scene.pov", &self.pov_photo(photo))?;
        let ortho = dir.join("ortho.png");
        let aa = if self.antialias > 1 {
            vec![
                "+A0.0".to_string(),
                "+AM1".to_string(),
                format!("+R{}", self.antialias),
                "-J".to_string(),
            ]
        } else {
            vec!["-A".to_string()]
        };
        let out = Command::new("povray")
            .arg(format!("+I{}", pov.display()))
            .arg(format!("+O{}", ortho.display()))
            .arg(format!("+W{}", self.size.0))
            .arg(format!("+H{}", self.size.1))
            .args(["+FN8", "-D", "-V", "+WT1", "Display_Gamma=1.0"])
            .arg(if photo.srgb {
                "File_Gamma=sRGB"
            } else {
                "File_Gamma=1.0"
            })
            .args(&aa)
            .output()
            .map_err(|e| format!("povray: {e} (apt-get install povray)"))?;
        if !out.status.success() || !ortho.exists() {
            return Err(format!(
                "povray failed: {}",
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        let (w, _, _, n) = self.extent();
        let world = format!(
            "{c}\n0\n0\n{m}\n{x}\n{y}\n",
            c = self.cell,
            m = -self.cell,
            x = w + self.cell / 2.0,
            y = n - self.cell / 2.0
        );
        put("ortho.pgw", &world)?;
        put("ortho.prj", photo.crs_wkt)?;
        let ortho = match photo.jpeg_quality {
            None => ortho,
            Some(q) => {
                let jpg = dir.join("ortho.jpg");
                let img = image::open(&ortho)
                    .map_err(|e| format!("{}: {e}", ortho.display()))?
                    .to_rgb8();
                let file =
                    std::fs::File::create(&jpg).map_err(|e| format!("{}: {e}", jpg.display()))?;
                image::codecs::jpeg::JpegEncoder::new_with_quality(
                    std::io::BufWriter::new(file),
                    q,
                )
                .encode_image(&img)
                .map_err(|e| format!("{}: {e}", jpg.display()))?;
                put("ortho.jgw", &world)?;
                jpg
            }
        };
        let mut dem = format!(
            "ncols {}\nnrows {}\nxllcorner {:.6}\nyllcorner {:.6}\ncellsize {}\n",
            self.size.0,
            self.size.1,
            w,
            n - self.size.1 as f64 * self.cell,
            self.cell
        );
        for r in 0..self.size.1 {
            let y = n - (r as f64 + 0.5) * self.cell;
            let row: Vec<String> = (0..self.size.0)
                .map(|c| {
                    let x = w + (c as f64 + 0.5) * self.cell;
                    format!("{:.4}", self.ground_z((x, y)))
                })
                .collect();
            dem.push_str(&row.join(" "));
            dem.push('\n');
        }
        let dem_path = put("dem.asc", &dem)?;
        put("dem.prj", photo.crs_wkt)?;
        let (sx, sy) = self.footprint_shift;
        let features: Vec<String> = self
            .buildings
            .iter()
            .enumerate()
            .filter(|(_, b)| b.listed())
            .map(|(k, b)| {
                let mut ring: Vec<String> = b
                    .outline()
                    .iter()
                    .map(|(x, y)| format!("[{:.4}, {:.4}]", x + sx, y + sy))
                    .collect();
                ring.push(ring[0].clone());
                format!(
                    "{{\"type\":\"Feature\",\"properties\":{{\"id\":{k}}},\"geometry\":{{\"type\":\"Polygon\",\"coordinates\":[[{}]]}}}}",
                    ring.join(", ")
                )
            })
            .collect();
        let fp = put(
            "footprints.geojson",
            &format!(
                "{{\"type\":\"FeatureCollection\",\"features\":[\n{}\n]}}\n",
                features.join(",\n")
            ),
        )?;
        Ok(Written {
            dir: dir.to_path_buf(),
            ortho,
            dem: dem_path,
            footprints: fp,
        })
    }
}

/// Whether POV-Ray is on PATH, for a test that needs it: without it the test says so and
/// should pass, except under CI (`CI` set), where this fails the test: `.ci/run` installs it.
pub fn available() -> bool {
    let ok = Command::new("povray").arg("--version").output().is_ok();
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "povray is not on PATH under CI: .ci/run must install it"
        );
        eprintln!("skipped: povray not on PATH (apt-get install povray)");
    }
    ok
}

/// A deterministic stream of numbers in [0, 1) (a 64-bit LCG): the harness's scenes are the same
/// on every run.
pub struct Rng(pub u64);

impl Rng {
    /// The next number in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The next number in [`lo`, `hi`).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// `n × n` isolated flat-roofed buildings 60 m apart (shadows never meet), the first centred
/// 40 m in from the north-west corner `origin`: sides 8 m to 8 m + `spread`, roofs 6 m to 6 m +
/// `spread` above the ground (plus the rise across the footprint on a slope, so every wall
/// stands clear), at sub-cell offsets drawn from `seed`; axis-aligned or rotated.
pub fn isolated_layout(
    seed: u64,
    n: usize,
    spread: f64,
    rotated: bool,
    ground: (f64, f64, f64),
    origin: (f64, f64),
) -> Vec<Building> {
    let mut rng = Rng(seed);
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let centre = (
                origin.0 + 40.0 + 60.0 * i as f64 + rng.next(),
                origin.1 - 40.0 - 60.0 * j as f64 - rng.next(),
            );
            let size = (8.0 + spread * rng.next(), 8.0 + spread * rng.next());
            let g = ground.0 + ground.1 * (centre.0 - origin.0) + ground.2 * (centre.1 - origin.1);
            let h = 6.0 + spread * rng.next();
            let rotation_deg = if rotated { 360.0 * rng.next() } else { 0.0 };
            let grey = 0.35 + 0.3 * rng.next();
            out.push(Building {
                centre,
                size,
                rotation_deg,
                roof: Roof::Flat {
                    z: g + h + 0.25 * size.0.hypot(size.1) * ground.1.hypot(ground.2),
                },
                colour: [grey, grey * 0.95, grey * 0.9],
            });
        }
    }
    out
}
