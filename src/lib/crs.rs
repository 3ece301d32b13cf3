//! Coordinate reference systems, as far as the default build needs them.
//!
//! Without GDAL we do not transform between CRSs: we identify them (EPSG code, and WKT when a
//! source gives one), compare them, and know whether their units are degrees or metres. Inputs in
//! different CRSs are an error that names both and says how to reproject.

use serde::{Deserialize, Serialize};

/// A CRS as read from an input: an EPSG code when known, WKT when given, and its linear unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Crs {
    /// EPSG code (e.g. 32614 for UTM 14N, 4326 for WGS 84 geographic), when known.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub epsg: Option<u32>,
    /// OGC WKT, when a source gave one (GDAL builds, .prj files).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub wkt: Option<String>,
    /// True when coordinates are longitude/latitude in degrees; false for projected (metres).
    pub geographic: bool,
    /// The projected coordinates' unit when the source declares a length other than the metre
    /// (a State Plane CRS in US survey feet). Never written: a database CRS is in metres.
    #[serde(skip)]
    pub foreign_unit: Option<ForeignUnit>,
    /// The heights' unit when the source declares a length other than the metre (GeoTIFF
    /// VerticalUnitsGeoKey, a compound WKT's vertical part). Never written.
    #[serde(skip)]
    pub vertical_unit: Option<ForeignUnit>,
}

impl Crs {
    /// A CRS known by EPSG code. Geographic-ness is inferred for the common codes
    /// (4326, 4269, 4258, 4267, 4019 and the 4000–4999 range of geographic 2-D CRSs).
    pub fn epsg(code: u32) -> Crs {
        Crs {
            epsg: Some(code),
            geographic: (4000..5000).contains(&code),
            ..Crs::default()
        }
    }

    /// No CRS information at all (e.g. an ASCII grid without a .prj).
    pub fn unknown() -> Crs {
        Crs::default()
    }

    /// True when nothing identifies this CRS.
    pub fn is_unknown(&self) -> bool {
        self.epsg.is_none() && self.wkt.is_none()
    }

    /// Do two CRSs name the same system? Unknown matches anything (we cannot tell otherwise);
    /// two EPSG codes compare by code; otherwise WKT compares as text.
    pub fn same_as(&self, other: &Crs) -> bool {
        if self.is_unknown() || other.is_unknown() {
            return true;
        }
        match (self.epsg, other.epsg) {
            (Some(a), Some(b)) => a == b,
            _ => match (&self.wkt, &other.wkt) {
                (Some(a), Some(b)) => a == b,
                _ => false,
            },
        }
    }

    /// A short human name: `EPSG:32614`, or the WKT's first name, or `unknown CRS`.
    pub fn name(&self) -> String {
        if let Some(c) = self.epsg {
            return format!("EPSG:{c}");
        }
        if let Some(w) = &self.wkt {
            // WKT starts with KIND["name", ...
            if let Some(start) = w.find('"') {
                if let Some(len) = w[start + 1..].find('"') {
                    return format!("\"{}\"", &w[start + 1..start + 1 + len]);
                }
            }
            return "a WKT CRS".to_string();
        }
        "unknown CRS".to_string()
    }

    /// Latitude and longitude (degrees, WGS 84 / GRS 80) of a point given in this CRS, where the
    /// default build can tell: geographic CRSs, and UTM zones on WGS 84 (EPSG 32601–32660,
    /// 32701–32760), ETRS89 (25828–25838) and NAD83 (26901–26923). `None` otherwise (a GDAL
    /// build converts any CRS). Accuracy of the UTM inverse: well under a millimetre in-zone.
    pub fn to_lat_lon(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        if self.geographic {
            return Some((y, x));
        }
        let code = self.epsg?;
        let (zone, south) = match code {
            32601..=32660 => (code - 32600, false),
            32701..=32760 => (code - 32700, true),
            25828..=25838 => (code - 25800, false),
            26901..=26923 => (code - 26900, false),
            _ => return None,
        };
        Some(utm_inverse(x, y, zone, south))
    }

    /// Meridian convergence at `(x, y)` in this CRS, in degrees: the angle clockwise from true
    /// north to grid north (the grid's +y axis). A true azimuth `A` (the sun model's) is grid
    /// azimuth `A − γ`. Positive east of a UTM zone's central meridian in the northern hemisphere
    /// (about 2.2° at the zone's edge at 48° N), negative west of it; 0 for geographic CRSs.
    /// `None` where [`to_lat_lon`](Self::to_lat_lon) is `None`. Measured on the ellipsoid from the
    /// inverse projection (a central difference over ±10 m along grid north), so it holds for
    /// any conformal projection; error below 1e-7°.
    pub fn grid_convergence_deg(&self, x: f64, y: f64) -> Option<f64> {
        if self.geographic {
            return Some(0.0);
        }
        const STEP_M: f64 = 10.0;
        let (lat0, lon0) = self.to_lat_lon(x, y - STEP_M)?;
        let (lat1, lon1) = self.to_lat_lon(x, y + STEP_M)?;
        // WGS 84 radii of curvature at the mid latitude: meridian (rho) and prime vertical (nu).
        const A_AXIS: f64 = 6_378_137.0;
        const E2: f64 = (2.0 - 1.0 / 298.257_223_563) / 298.257_223_563;
        let phi = (0.5 * (lat0 + lat1)).to_radians();
        let w2 = 1.0 - E2 * phi.sin().powi(2);
        let nu = A_AXIS / w2.sqrt();
        let rho = A_AXIS * (1.0 - E2) / (w2 * w2.sqrt());
        let north_m = rho * (lat1 - lat0).to_radians();
        let east_m = nu * phi.cos() * (lon1 - lon0).to_radians();
        Some(east_m.atan2(north_m).to_degrees())
    }

    /// Refuse projected coordinates in a unit other than the metre: dbms works in metres, and a
    /// foot read as a metre is a silently wrong result. `path` names where the CRS came from.
    pub fn require_metric_coordinates(&self, path: &std::path::Path) -> crate::error::Result<()> {
        match &self.foreign_unit {
            Some(u) => Err(crate::error::Error::file(path, format!("{} has coordinates in {} ({} m), not metres", self.name(), u.name, u.metres))
                .fix("reproject to a metric CRS: gdalwarp -t_srs EPSG:326NN in.tif out.tif (or --t-srs in a --features gdal build)")),
            None => Ok(()),
        }
    }

    /// Refuse heights declared in a unit other than the metre (`path` names the DEM).
    pub fn require_metric_heights(&self, path: &std::path::Path) -> crate::error::Result<()> {
        match &self.vertical_unit {
            Some(u) => Err(crate::error::Error::file(path, format!("heights are in {} ({} m), not metres", u.name, u.metres))
                .fix(format!("convert them to metres first, e.g. gdal_calc.py -A in.tif --calc=\"A*{}\" --outfile=out.tif, and drop the vertical unit", u.metres))),
            None => Ok(()),
        }
    }

    /// The unit of the coordinates, for messages and the manifest: `degree` or `metre`.
    pub fn unit(&self) -> &'static str {
        if self.geographic {
            "degree"
        } else {
            "metre"
        }
    }
}

/// A length unit other than the metre in which a CRS gives coordinates or heights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ForeignUnit {
    /// The unit's name as the source gives it, e.g. `US survey foot`.
    pub name: String,
    /// Its length in metres, e.g. 0.304800609601219.
    pub metres: f64,
}

/// The length units in `wkt` that are not the metre, `(horizontal, vertical)`: WKT1
/// `UNIT["name", factor]` and WKT2 `LENGTHUNIT["name", factor]` with a factor (metres per unit)
/// other than 1 — a projected CRS in feet, or a compound CRS whose vertical part (inside
/// `VERT_CS`/`VERTCRS`) is in feet. Angular, scale, time and parametric units are not lengths and
/// are skipped (WKT1 angular units by name: degree, grad, radian, second, minute), and so are a
/// WKT2 projection parameter's own units. `None` where every length is in metres.
pub fn foreign_units_in_wkt(wkt: &str) -> (Option<ForeignUnit>, Option<ForeignUnit>) {
    let upper = wkt.to_ascii_uppercase();
    let (mut horizontal, mut vertical) = (None, None);
    let mut from = 0;
    while let Some(at) = upper[from..].find("UNIT[") {
        let start = from + at;
        from = start + 5;
        let keyword_start = upper[..start]
            .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .map_or(0, |i| i + 1);
        let keyword = &upper[keyword_start..start + 4];
        if !matches!(keyword, "UNIT" | "LENGTHUNIT") {
            continue; // ANGLEUNIT, SCALEUNIT, TIMEUNIT, PARAMETRICUNIT
        }
        let parents = enclosing(&upper, keyword_start);
        if parents.first() == Some(&"PARAMETER") {
            continue; // a WKT2 projection parameter's own unit, not the coordinates'
        }
        let is_vertical = parents
            .iter()
            .any(|k| matches!(*k, "VERT_CS" | "VERTCRS" | "VERTICALCRS"));
        let body = &wkt[from..];
        let end = body.find(']').unwrap_or(body.len());
        let mut parts = body[..end].splitn(3, ',');
        let name = parts
            .next()
            .unwrap_or("")
            .trim()
            .trim_matches('"')
            .to_string();
        let Some(metres) = parts.next().and_then(|f| f.trim().parse::<f64>().ok()) else {
            continue;
        };
        let lower = name.to_ascii_lowercase();
        let angular = ["degree", "grad", "gon", "radian", "second", "minute"]
            .iter()
            .any(|a| lower.contains(a));
        if keyword == "UNIT" && angular {
            continue;
        }
        let slot = if is_vertical {
            &mut vertical
        } else {
            &mut horizontal
        };
        if (metres - 1.0).abs() > 1e-9 && slot.is_none() {
            *slot = Some(ForeignUnit { name, metres });
        }
    }
    (horizontal, vertical)
}

/// The keywords of the WKT objects whose brackets enclose byte `at`, innermost first.
fn enclosing(wkt: &str, at: usize) -> Vec<&str> {
    let mut out = Vec::new();
    let mut depth = 0;
    for (i, c) in wkt[..at].char_indices().rev() {
        match c {
            ']' => depth += 1,
            '[' if depth == 0 => {
                let start = wkt[..i]
                    .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                    .map_or(0, |j| j + 1);
                out.push(&wkt[start..i]);
            }
            '[' => depth -= 1,
            _ => {}
        }
    }
    out
}

/// The EPSG name and length in metres of a GeoTIFF linear unit code (ProjLinearUnitsGeoKey,
/// VerticalUnitsGeoKey; EPSG unit codes 9001–9099): `None` for the metre (9001) and for codes
/// that are not length units we know.
pub fn foreign_unit_from_epsg(code: u16) -> Option<ForeignUnit> {
    let (name, metres) = match code {
        9002 => ("foot", 0.3048),
        9003 => ("US survey foot", 1200.0 / 3937.0),
        9005 => ("Clarke's foot", 0.3047972654),
        9014 => ("fathom", 1.8288),
        9030 => ("nautical mile", 1852.0),
        9036 => ("kilometre", 1000.0),
        9037 => ("Clarke's yard", 0.9143917962),
        9040 => ("British yard (Sears 1922)", 36.0 / 39.370147),
        9041 => ("British foot (Sears 1922)", 12.0 / 39.370147),
        9042 => ("British chain (Sears 1922)", 792.0 / 39.370147),
        9050 => ("British yard (Benoit 1895 A)", 0.9143992),
        9060 => ("British yard (Benoit 1895 B)", 36.0 / 39.370113),
        9070 => ("British foot (1865)", 0.30480083333),
        9080 => ("Indian foot", 12.0 / 39.370142),
        9081 => ("Indian foot (1937)", 0.30479841),
        9082 => ("Indian foot (1962)", 0.3047996),
        9083 => ("Indian foot (1975)", 0.3047995),
        9084 => ("Indian yard", 36.0 / 39.370142),
        9093 => ("statute mile", 1609.344),
        9094 => ("Gold Coast foot", 6378300.0 / 20926201.0),
        9095 => ("British foot (1936)", 0.3048007491),
        9096 => ("yard", 0.9144),
        9097 => ("chain", 20.1168),
        9098 => ("link", 0.201168),
        9099 => ("British yard (Sears 1922 truncated)", 0.914398),
        _ => return None,
    };
    Some(ForeignUnit {
        name: name.to_string(),
        metres,
    })
}

/// Inverse transverse Mercator for a UTM zone (Krüger series to n³, as in Karney 2011 and the
/// usual UTM formulas): easting/northing in metres → (latitude, longitude) in degrees.
/// GRS 80 and WGS 84 differ by 0.1 mm in the semi-minor axis; WGS 84 is used for both.
fn utm_inverse(easting: f64, northing: f64, zone: u32, south: bool) -> (f64, f64) {
    const A_AXIS: f64 = 6_378_137.0;
    const FLATTENING: f64 = 1.0 / 298.257_223_563;
    const K0: f64 = 0.9996;
    const E0: f64 = 500_000.0;
    let n0 = if south { 10_000_000.0 } else { 0.0 };
    let n = FLATTENING / (2.0 - FLATTENING);
    let (n2, n3) = (n * n, n * n * n);
    let a = A_AXIS / (1.0 + n) * (1.0 + n2 / 4.0 + n2 * n2 / 64.0);
    let beta = [
        n / 2.0 - 2.0 / 3.0 * n2 + 37.0 / 96.0 * n3,
        n2 / 48.0 + n3 / 15.0,
        17.0 / 480.0 * n3,
    ];
    let delta = [
        2.0 * n - 2.0 / 3.0 * n2 - 2.0 * n3,
        7.0 / 3.0 * n2 - 8.0 / 5.0 * n3,
        56.0 / 15.0 * n3,
    ];
    let xi = (northing - n0) / (K0 * a);
    let eta = (easting - E0) / (K0 * a);
    let (mut xi_p, mut eta_p) = (xi, eta);
    for (j, b) in beta.iter().enumerate() {
        let k = 2.0 * (j as f64 + 1.0);
        xi_p -= b * (k * xi).sin() * (k * eta).cosh();
        eta_p -= b * (k * xi).cos() * (k * eta).sinh();
    }
    let chi = (xi_p.sin() / eta_p.cosh()).asin();
    let mut phi = chi;
    for (j, d) in delta.iter().enumerate() {
        phi += d * (2.0 * (j as f64 + 1.0) * chi).sin();
    }
    let lon0 = (zone as f64 * 6.0 - 183.0).to_radians();
    let lon = lon0 + (eta_p.sinh() / xi_p.cos()).atan();
    (phi.to_degrees(), lon.to_degrees())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsg_geographic_inference_and_comparison() {
        assert!(Crs::epsg(4326).geographic);
        assert!(!Crs::epsg(32614).geographic);
        assert!(Crs::epsg(32614).same_as(&Crs::epsg(32614)));
        assert!(!Crs::epsg(32614).same_as(&Crs::epsg(32615)));
        assert!(Crs::unknown().same_as(&Crs::epsg(4326)));
        assert_eq!(Crs::epsg(32614).name(), "EPSG:32614");
    }

    #[test]
    fn foreign_units_are_found_in_wkt1_and_wkt2_and_metres_and_angles_are_not() {
        // gdalsrsinfo -o wkt1 EPSG:2277 (abridged): degrees in the GEOGCS, US feet outside.
        let ft = r#"PROJCS["NAD83 / Texas Central (ftUS)",GEOGCS["NAD83",DATUM["North_American_Datum_1983",SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic_2SP"],UNIT["US survey foot",0.304800609601219,AUTHORITY["EPSG","9003"]],AUTHORITY["EPSG","2277"]]"#;
        let u = foreign_units_in_wkt(ft).0.unwrap();
        assert_eq!(u.name, "US survey foot");
        assert!((u.metres - 0.304800609601219).abs() < 1e-15);
        let utm = r#"PROJCS["WGS 84 / UTM zone 14N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],UNIT["metre",1],AUTHORITY["EPSG","32614"]]"#;
        assert_eq!(foreign_units_in_wkt(utm), (None, None));
        // WKT2: angle and scale units are skipped, and so are a parameter's own units; the
        // axes' LENGTHUNIT decides.
        let wkt2 = r#"PROJCRS["x",BASEGEOGCRS["NAD83",ANGLEUNIT["degree",0.0174532925199433]],CONVERSION["c",PARAMETER["k",0.9999,SCALEUNIT["unity",1]],PARAMETER["False easting",1968500,LENGTHUNIT["foot",0.3048]]],CS[Cartesian,2],AXIS["x",east,LENGTHUNIT["foot",0.3048]]]"#;
        assert_eq!(foreign_units_in_wkt(wkt2).0.unwrap().name, "foot");
        let metric_axes = wkt2.replace(
            r#"east,LENGTHUNIT["foot",0.3048]"#,
            r#"east,LENGTHUNIT["metre",1]"#,
        );
        assert_eq!(foreign_units_in_wkt(&metric_axes), (None, None));
        let geo = r#"GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],UNIT["degree",0.0174532925199433]]"#;
        assert_eq!(foreign_units_in_wkt(geo), (None, None));
        // A compound CRS with metres across and heights in feet.
        let compound = r#"COMPD_CS["x",PROJCS["UTM",UNIT["metre",1]],VERT_CS["NAVD88 height (ftUS)",VERT_DATUM["NAVD88",2005],UNIT["US survey foot",0.304800609601219]]]"#;
        let (h, v) = foreign_units_in_wkt(compound);
        assert_eq!((h, v.unwrap().name.as_str()), (None, "US survey foot"));
    }

    #[test]
    fn epsg_unit_codes() {
        assert_eq!(foreign_unit_from_epsg(9001), None);
        assert_eq!(foreign_unit_from_epsg(9102), None, "degree is not a length");
        assert!((foreign_unit_from_epsg(9003).unwrap().metres - 0.304800609601219).abs() < 1e-15);
        assert_eq!(foreign_unit_from_epsg(9002).unwrap().metres, 0.3048);
    }

    #[test]
    fn utm_inverse_agrees_with_gdaltransform() {
        // Reference values from GDAL 3.6 `gdaltransform -s_srs EPSG:326xx -t_srs EPSG:4326`.
        let cases = [
            (32614, 500_000.0, 3_620_000.0, 32.7177735495427, -99.0),
            (
                32614,
                635_000.0,
                3_620_000.0,
                32.7095006160078,
                -97.5596143604619,
            ),
            (
                32614,
                421_000.0,
                4_000_000.0,
                36.1414990471862,
                -99.8780956083833,
            ),
            (
                32733,
                300_000.0,
                5_500_000.0,
                -40.6266397268273,
                12.6353192129815,
            ),
        ];
        for (code, e, n, lat, lon) in cases {
            let (la, lo) = Crs::epsg(code).to_lat_lon(e, n).unwrap();
            // 1e-8 degrees is about a millimetre.
            assert!(
                (la - lat).abs() < 1e-8 && (lo - lon).abs() < 1e-8,
                "{code} {e} {n}: {la} {lo}"
            );
        }
        assert_eq!(Crs::epsg(4326).to_lat_lon(-97.3, 32.7), Some((32.7, -97.3)));
        assert_eq!(Crs::epsg(2056).to_lat_lon(2_600_000.0, 1_200_000.0), None);
    }

    #[test]
    fn grid_convergence_agrees_with_proj() {
        // Reference values from PROJ 9 `proj -V +proj=utm +zone=Z [+south] +datum=WGS84`
        // ("Convergence"): east of zone 32's meridian at 48° N, near the zone's edge; west of
        // zone 33S's at 40.6° S. Both put grid north east of true north.
        let cases = [
            (32632, 716_317.392_258, 5_320_370.154_245, 2.155_951_60),
            (32733, 300_000.0, 5_500_000.0, 1.540_217_49),
        ];
        for (code, e, n, gamma) in cases {
            let got = Crs::epsg(code).grid_convergence_deg(e, n).unwrap();
            assert!(
                (got - gamma).abs() < 1e-7,
                "{code} {e} {n}: {got} vs {gamma}"
            );
        }
        // Mirror images across the central meridian; none on it; none for a geographic grid.
        let utm = Crs::epsg(32632);
        let east = utm.grid_convergence_deg(600_000.0, 5_300_000.0).unwrap();
        let west = utm.grid_convergence_deg(400_000.0, 5_300_000.0).unwrap();
        assert!(east > 0.9 && (east + west).abs() < 1e-9, "{east} {west}");
        assert!(
            utm.grid_convergence_deg(500_000.0, 5_300_000.0)
                .unwrap()
                .abs()
                < 1e-12
        );
        assert_eq!(Crs::epsg(4326).grid_convergence_deg(9.0, 48.0), Some(0.0));
        assert_eq!(
            Crs::epsg(2056).grid_convergence_deg(2_600_000.0, 1_200_000.0),
            None
        );
    }
}
