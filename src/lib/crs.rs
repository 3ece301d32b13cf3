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

    /// The unit of the coordinates, for messages and the manifest: `degree` or `metre`.
    pub fn unit(&self) -> &'static str {
        if self.geographic { "degree" } else { "metre" }
    }
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
}
