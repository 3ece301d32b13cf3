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
}

impl Crs {
    /// A CRS known by EPSG code. Geographic-ness is inferred for the common codes
    /// (4326, 4269, 4258, 4267, 4019 and the 4000–4999 range of geographic 2-D CRSs).
    pub fn epsg(code: u32) -> Crs {
        Crs { epsg: Some(code), wkt: None, geographic: (4000..5000).contains(&code) }
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

    /// The unit of the coordinates, for messages and the manifest: `degree` or `metre`.
    pub fn unit(&self) -> &'static str {
        if self.geographic { "degree" } else { "metre" }
    }
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
    let beta = [n / 2.0 - 2.0 / 3.0 * n2 + 37.0 / 96.0 * n3, n2 / 48.0 + n3 / 15.0, 17.0 / 480.0 * n3];
    let delta = [2.0 * n - 2.0 / 3.0 * n2 - 2.0 * n3, 7.0 / 3.0 * n2 - 8.0 / 5.0 * n3, 56.0 / 15.0 * n3];
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
    fn utm_inverse_agrees_with_gdaltransform() {
        // Reference values from GDAL 3.6 `gdaltransform -s_srs EPSG:326xx -t_srs EPSG:4326`.
        let cases = [
            (32614, 500_000.0, 3_620_000.0, 32.7177735495427, -99.0),
            (32614, 635_000.0, 3_620_000.0, 32.7095006160078, -97.5596143604619),
            (32614, 421_000.0, 4_000_000.0, 36.1414990471862, -99.8780956083833),
            (32733, 300_000.0, 5_500_000.0, -40.6266397268273, 12.6353192129815),
        ];
        for (code, e, n, lat, lon) in cases {
            let (la, lo) = Crs::epsg(code).to_lat_lon(e, n).unwrap();
            // 1e-8 degrees is about a millimetre.
            assert!((la - lat).abs() < 1e-8 && (lo - lon).abs() < 1e-8, "{code} {e} {n}: {la} {lo}");
        }
        assert_eq!(Crs::epsg(4326).to_lat_lon(-97.3, 32.7), Some((32.7, -97.3)));
        assert_eq!(Crs::epsg(2056).to_lat_lon(2_600_000.0, 1_200_000.0), None);
    }
}
