//! GeoTIFF georeferencing: the GeoKey directory and the model tags, read into one parsed
//! record and turned into a [`Crs`] and a corner-convention [`GeoTransform`]; and the
//! directory the writers put in a file for a [`Crs`].

use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, NotNorthUp};
use crate::io::crs_from_wkt;
use std::io::Seek;
use std::path::Path;
use tiff::decoder::Decoder;
use tiff::tags::Tag;
use tiff::TiffResult;

/// GeoKey IDs (GeoTIFF 1.1, section 7).
mod key {
    pub const GT_MODEL_TYPE: u16 = 1024;
    pub const GT_RASTER_TYPE: u16 = 1025;
    pub const GT_CITATION: u16 = 1026;
    pub const GEOGRAPHIC_TYPE: u16 = 2048;
    pub const GEOG_CITATION: u16 = 2049;
    pub const GEOG_ANGULAR_UNITS: u16 = 2054;
    pub const PROJECTED_CS_TYPE: u16 = 3072;
    pub const PCS_CITATION: u16 = 3073;
    pub const PROJ_LINEAR_UNITS: u16 = 3076;
    pub const PROJ_LINEAR_UNIT_SIZE: u16 = 3077;
    pub const VERTICAL_UNITS: u16 = 4099;
    /// Value meaning "user-defined" for any code key.
    pub const USER_DEFINED: u16 = 32767;
    pub const MODEL_PROJECTED: u16 = 1;
    pub const MODEL_GEOGRAPHIC: u16 = 2;
    pub const RASTER_PIXEL_IS_AREA: u16 = 1;
    pub const RASTER_PIXEL_IS_POINT: u16 = 2;
    pub const LINEAR_METRE: u16 = 9001;
    pub const ANGULAR_DEGREE: u16 = 9102;
}

/// GDAL's private TIFF tag holding band metadata as XML (scale, offset, statistics).
const TAG_GDAL_METADATA: Tag = Tag::Unknown(42112);

/// Prefix GDAL (and we) use to carry a WKT CRS in GTCitationGeoKey.
const ESRI_PE_STRING: &str = "ESRI PE String = ";

/// The georeferencing tags of a TIFF, raw.
#[derive(Debug, Default)]
pub(super) struct GeoTags {
    pixel_scale: Option<Vec<f64>>,
    tiepoints: Option<Vec<f64>>,
    transformation: Option<Vec<f64>>,
    geokeys: Option<Vec<u16>>,
    doubles: Option<Vec<f64>>,
    ascii: Option<String>,
    nodata: Option<String>,
    metadata: Option<String>,
}

/// A GeoKey's value: a short, doubles, or text.
#[derive(Debug, Clone, PartialEq)]
enum KeyValue {
    Short(u16),
    Doubles(Vec<f64>),
    Ascii(String),
}

/// A file's GeoKeys, parsed once: `(id, value)` in file order.
struct GeoKeys(Vec<(u16, KeyValue)>);

impl GeoKeys {
    fn value(&self, id: u16) -> Option<&KeyValue> {
        self.0.iter().find(|(k, _)| *k == id).map(|(_, v)| v)
    }

    /// Key `id`'s value if it is a short.
    fn short(&self, id: u16) -> Option<u16> {
        match self.value(id)? {
            KeyValue::Short(s) => Some(*s),
            _ => None,
        }
    }

    /// Key `id`'s value if it is text.
    fn text(&self, id: u16) -> Option<&str> {
        match self.value(id)? {
            KeyValue::Ascii(s) => Some(s),
            _ => None,
        }
    }

    /// Key `id`'s value if it is doubles.
    fn doubles(&self, id: u16) -> Option<&[f64]> {
        match self.value(id)? {
            KeyValue::Doubles(d) => Some(d),
            _ => None,
        }
    }

    /// The CRS the keys name, before length units are looked at (see [`GeoTags::crs`]).
    fn crs(&self, path: &Path) -> Result<Crs> {
        if let Some(wkt) = self
            .text(key::GT_CITATION)
            .and_then(|c| c.strip_prefix(ESRI_PE_STRING))
        {
            if let Some(crs) = crs_from_wkt(wkt) {
                return Ok(crs);
            }
        }
        let projected = self.short(key::PROJECTED_CS_TYPE);
        let geographic = self.short(key::GEOGRAPHIC_TYPE);
        let model = self
            .short(key::GT_MODEL_TYPE)
            .or(match (projected, geographic) {
                (Some(_), _) => Some(key::MODEL_PROJECTED),
                (None, Some(_)) => Some(key::MODEL_GEOGRAPHIC),
                _ => None,
            });
        let (code, citation_keys, is_geo) = match model {
            Some(key::MODEL_PROJECTED) => (projected, [key::PCS_CITATION, key::GT_CITATION], false),
            Some(key::MODEL_GEOGRAPHIC) => {
                (geographic, [key::GEOG_CITATION, key::GT_CITATION], true)
            }
            Some(other) => {
                return Err(Error::file(
                    path,
                    format!("unsupported GeoTIFF model type {other} (geocentric?)"),
                )
                .fix("reproject it: gdalwarp -t_srs EPSG:CODE in.tif out.tif"))
            }
            None => return Ok(Crs::unknown()),
        };
        Ok(match code {
            Some(c) if c != key::USER_DEFINED && c != 0 => Crs {
                geographic: is_geo,
                ..Crs::epsg(c as u32)
            },
            _ => {
                let name = citation_keys
                    .iter()
                    .find_map(|&k| self.text(k))
                    .unwrap_or("user-defined")
                    .replace('"', "'");
                Crs {
                    epsg: None,
                    wkt: Some(format!("LOCAL_CS[\"{name}\"]")),
                    geographic: is_geo,
                    ..Crs::default()
                }
            }
        })
    }
}

impl GeoTags {
    pub(super) fn read<R: std::io::Read + Seek>(dec: &mut Decoder<R>) -> TiffResult<GeoTags> {
        let f64s = |dec: &mut Decoder<R>, t| {
            dec.find_tag(t)
                .and_then(|v| v.map(|v| v.into_f64_vec()).transpose())
        };
        let text = |dec: &mut Decoder<R>, t| {
            dec.find_tag(t)
                .and_then(|v| v.map(|v| v.into_string()).transpose())
        };
        Ok(GeoTags {
            pixel_scale: f64s(dec, Tag::ModelPixelScaleTag)?,
            tiepoints: f64s(dec, Tag::ModelTiepointTag)?,
            transformation: f64s(dec, Tag::ModelTransformationTag)?,
            geokeys: dec.find_tag_unsigned_vec(Tag::GeoKeyDirectoryTag)?,
            doubles: f64s(dec, Tag::GeoDoubleParamsTag)?,
            ascii: text(dec, Tag::GeoAsciiParamsTag)?,
            nodata: text(dec, Tag::GdalNodata)?,
            metadata: text(dec, TAG_GDAL_METADATA)?,
        })
    }

    /// The GeoKeys, parsed. A malformed directory is an error.
    fn keys(&self, path: &Path) -> Result<GeoKeys> {
        let Some(dir) = &self.geokeys else {
            return Ok(GeoKeys(Vec::new()));
        };
        let bad = |what: &str| {
            Error::file(path, format!("corrupt GeoKeyDirectory: {what}"))
                .fix("re-create the georeference with gdal_translate -a_srs")
        };
        if dir.len() < 4 {
            return Err(bad("too short"));
        }
        let n = dir[3] as usize;
        let entries = dir
            .get(4..4 + 4 * n)
            .ok_or_else(|| bad("fewer keys than it declares"))?;
        let keys = entries
            .chunks_exact(4)
            .map(|e| {
                let (id, loc, count, off) = (e[0], e[1], e[2] as usize, e[3] as usize);
                let value = match loc {
                    0 => KeyValue::Short(off as u16),
                    34736 => KeyValue::Doubles(
                        self.doubles
                            .as_ref()
                            .and_then(|d| d.get(off..off + count))
                            .ok_or_else(|| bad("double out of range"))?
                            .to_vec(),
                    ),
                    34737 => {
                        let s = self
                            .ascii
                            .as_deref()
                            .and_then(|a| a.get(off..off + count))
                            .ok_or_else(|| bad("text out of range"))?;
                        KeyValue::Ascii(s.trim_end_matches(['|', '\0']).to_string())
                    }
                    34735 => {
                        KeyValue::Short(*dir.get(off).ok_or_else(|| bad("short out of range"))?)
                    }
                    _ => return Err(bad("unknown value location")),
                };
                Ok((id, value))
            })
            .collect::<Result<_>>()?;
        Ok(GeoKeys(keys))
    }

    /// The CRS from the GeoKeys, and whether the raster type is PixelIsPoint.
    ///
    /// EPSG codes come from ProjectedCSTypeGeoKey (projected) or GeographicTypeGeoKey
    /// (geographic). A user-defined CRS (code 32767) has no EPSG code: it keeps the WKT carried in
    /// an `ESRI PE String = ` citation if there is one, else a `LOCAL_CS["<citation>"]` WKT that
    /// names it (so it compares unequal to every EPSG CRS instead of matching anything).
    /// Length units other than the metre (ProjLinearUnitsGeoKey, with ProjLinearUnitSizeGeoKey
    /// for a user-defined one, and VerticalUnitsGeoKey) are kept in the CRS's `foreign_unit` and
    /// `vertical_unit` so ingest can refuse them.
    pub(super) fn crs(&self, path: &Path) -> Result<(Crs, bool)> {
        let keys = self.keys(path)?;
        let point = keys.short(key::GT_RASTER_TYPE) == Some(key::RASTER_PIXEL_IS_POINT);
        let mut crs = keys.crs(path)?;
        if !crs.geographic && crs.foreign_unit.is_none() {
            crs.foreign_unit = match keys.short(key::PROJ_LINEAR_UNITS) {
                Some(key::USER_DEFINED) => keys
                    .doubles(key::PROJ_LINEAR_UNIT_SIZE)
                    .filter(|d| d.len() == 1 && (d[0] - 1.0).abs() > 1e-9)
                    .map(|d| crate::crs::ForeignUnit {
                        name: "a user-defined unit".into(),
                        metres: d[0],
                    }),
                Some(code) => crate::crs::foreign_unit_from_epsg(code),
                None => None,
            };
        }
        if let Some(v) = keys
            .short(key::VERTICAL_UNITS)
            .and_then(crate::crs::foreign_unit_from_epsg)
        {
            crs.vertical_unit = Some(v);
        }
        Ok((crs, point))
    }

    /// The corner-convention transform, or `None` when the file has no georeferencing tags.
    pub(super) fn transform(
        &self,
        path: &Path,
        pixel_is_point: bool,
    ) -> Result<Option<GeoTransform>> {
        let (origin, cell, shear) = match (&self.transformation, &self.tiepoints, &self.pixel_scale)
        {
            (Some(m), _, _) => {
                if m.len() < 8 {
                    return Err(
                        Error::file(path, "ModelTransformation has fewer than 16 values")
                            .fix("re-create the georeference with gdal_translate"),
                    );
                }
                ([m[3], m[7]], [m[0], m[5]], [m[1], m[4]])
            }
            (None, Some(tp), Some(sc)) if tp.len() == 6 && sc.len() >= 2 => (
                [tp[3] - tp[0] * sc[0], tp[4] + tp[1] * sc[1]],
                [sc[0], -sc[1]],
                [0.0, 0.0],
            ),
            (None, Some(tp), _) if tp.len() >= 6 => {
                return Err(Error::file(
                    path,
                    format!(
                        "georeferenced by {} ground control points, not a grid",
                        tp.len() / 6
                    ),
                )
                .fix("warp it onto a north-up grid first: gdalwarp in.tif out.tif"))
            }
            _ => return Ok(None),
        };
        let t = GeoTransform::north_up(origin, cell, shear).map_err(|e| match e {
            NotNorthUp::Sheared => Error::file(
                path,
                format!(
                    "rotated or sheared georeference (ModelTransformation terms {}, {})",
                    shear[0], shear[1]
                ),
            )
            .fix("make it north-up first: gdalwarp in.tif out.tif"),
            NotNorthUp::BadGeometry => Error::file(
                path,
                format!(
                    "bad georeference (origin {}, {}; cell {} × {})",
                    origin[0], origin[1], cell[0], cell[1]
                ),
            )
            .fix("assign one: gdal_translate -a_ullr ULX ULY LRX LRY in.tif out.tif"),
        })?;
        Ok(Some(if pixel_is_point {
            // The tiepoint is a pixel centre: the corner is half a cell up and left (GDAL does the same).
            GeoTransform {
                origin_x: t.origin_x - 0.5 * t.cell_x,
                origin_y: t.origin_y - 0.5 * t.cell_y,
                ..t
            }
        } else {
            t
        }))
    }

    /// The GDAL_NODATA value: a number, `nan`, `inf` or `-inf`.
    pub(super) fn nodata(&self, path: &Path) -> Result<Option<f64>> {
        let Some(s) = &self.nodata else {
            return Ok(None);
        };
        let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
        if s.is_empty() {
            return Ok(None);
        }
        s.parse::<f64>().map(Some).map_err(|_| {
            Error::file(path, format!("GDAL_NODATA tag '{s}' is not a number"))
                .fix("set it: gdal_edit.py -a_nodata VALUE in.tif")
        })
    }

    /// GDAL stores band scale/offset in its metadata XML; values would need `v·scale + offset`,
    /// which we do not apply, so refuse rather than return unscaled numbers.
    pub(super) fn check_no_scale_offset(&self, path: &Path) -> Result<()> {
        let Some(xml) = &self.metadata else {
            return Ok(());
        };
        for (role, identity) in [("scale", 1.0), ("offset", 0.0)] {
            let needle = format!("role=\"{role}\">");
            for (at, _) in xml.match_indices(&needle) {
                let rest = &xml[at + needle.len()..];
                let value = rest.split('<').next().unwrap_or("").trim();
                if value.parse::<f64>() != Ok(identity) {
                    return Err(Error::file(
                        path,
                        format!("band {role} {value} is set (values are not in their final units)"),
                    )
                    .fix("apply it: gdal_translate -unscale -ot Float32 in.tif out.tif"));
                }
            }
        }
        Ok(())
    }
}

/// The GeoKeyDirectory (sorted by key, as the spec requires) and GeoAsciiParams for a CRS:
/// EPSG codes as ProjectedCSType (linear unit metre) or GeographicType (angular unit degree);
/// a WKT-only CRS as user-defined with the WKT in an `ESRI PE String = ` citation (GDAL reads it).
pub(super) fn directory(crs: &Crs) -> (Vec<u16>, Option<String>) {
    let mut entries: Vec<[u16; 4]> = vec![[key::GT_RASTER_TYPE, 0, 1, key::RASTER_PIXEL_IS_AREA]];
    let mut ascii = None;
    let wkt = crs
        .wkt
        .as_deref()
        .filter(|w| w.is_ascii() && !w.contains('|'));
    let code = match (crs.epsg, wkt) {
        (Some(c), _) if c < key::USER_DEFINED as u32 => Some(c as u16),
        (_, Some(w)) => {
            let citation = format!("{ESRI_PE_STRING}{w}|");
            entries.push([key::GT_CITATION, 34737, citation.len() as u16, 0]);
            ascii = Some(citation);
            Some(key::USER_DEFINED)
        }
        _ => None,
    };
    if let Some(code) = code {
        if crs.geographic {
            entries.push([key::GT_MODEL_TYPE, 0, 1, key::MODEL_GEOGRAPHIC]);
            entries.push([key::GEOGRAPHIC_TYPE, 0, 1, code]);
            entries.push([key::GEOG_ANGULAR_UNITS, 0, 1, key::ANGULAR_DEGREE]);
        } else {
            entries.push([key::GT_MODEL_TYPE, 0, 1, key::MODEL_PROJECTED]);
            entries.push([key::PROJECTED_CS_TYPE, 0, 1, code]);
            entries.push([key::PROJ_LINEAR_UNITS, 0, 1, key::LINEAR_METRE]);
        }
    }
    entries.sort_by_key(|e| e[0]);
    let mut dir = vec![1, 1, 0, entries.len() as u16];
    dir.extend(entries.into_iter().flatten());
    (dir, ascii)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiepoint_scale_and_pixel_is_point() {
        let tags = GeoTags {
            tiepoints: Some(vec![2.0, 1.0, 0.0, 100.0, 200.0, 0.0]),
            pixel_scale: Some(vec![10.0, 5.0, 0.0]),
            ..Default::default()
        };
        let t = tags.transform(Path::new("x"), false).unwrap().unwrap();
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 80.0,
                origin_y: 205.0,
                cell_x: 10.0,
                cell_y: -5.0
            }
        );
        let t = tags.transform(Path::new("x"), true).unwrap().unwrap();
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 75.0,
                origin_y: 207.5,
                cell_x: 10.0,
                cell_y: -5.0
            }
        );
    }

    #[test]
    fn rotation_and_gcps_are_errors() {
        let mut m = vec![0.0; 16];
        (m[0], m[1], m[3], m[4], m[5], m[7]) = (1.0, 0.2, 0.0, 0.0, -1.0, 0.0);
        let tags = GeoTags {
            transformation: Some(m),
            ..Default::default()
        };
        let e = tags
            .transform(Path::new("r.tif"), false)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("r.tif: rotated"), "{e}");
        let tags = GeoTags {
            tiepoints: Some(vec![0.0; 18]),
            ..Default::default()
        };
        let e = tags
            .transform(Path::new("g.tif"), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("3 ground control points"), "{e}");
    }

    #[test]
    fn geokeys_user_defined_citation() {
        let keys = [
            1u16, 1, 0, 3, 1024, 0, 1, 1, 1026, 34737, 8, 0, 3072, 0, 1, 32767,
        ];
        let tags = GeoTags {
            geokeys: Some(keys.to_vec()),
            ascii: Some("My Grid|".into()),
            ..Default::default()
        };
        let (crs, point) = tags.crs(Path::new("x")).unwrap();
        assert!(!point);
        assert_eq!(crs.epsg, None);
        assert_eq!(crs.name(), "\"My Grid\"");
        assert!(!crs.same_as(&Crs::epsg(32614)));
    }

    /// GDAL writes ProjLinearUnitsGeoKey 9003 for EPSG:2277 (Texas Central, US survey feet):
    /// the unit is kept so ingest refuses feet; metres and degrees leave nothing to refuse.
    #[test]
    fn geokeys_linear_and_vertical_units() {
        let tags = |keys: &[u16]| GeoTags {
            geokeys: Some(keys.to_vec()),
            ..Default::default()
        };
        let feet = tags(&[
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 2277, 3076, 0, 1, 9003,
        ]);
        let (crs, _) = feet.crs(Path::new("x")).unwrap();
        assert_eq!(crs.epsg, Some(2277));
        assert_eq!(crs.foreign_unit.as_ref().unwrap().name, "US survey foot");
        let e = crs
            .require_metric_coordinates(Path::new("dem.tif"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("US survey foot") && e.contains("gdalwarp -t_srs"),
            "{e}"
        );
        let metres = tags(&[
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 32614, 3076, 0, 1, 9001,
        ]);
        let (crs, _) = metres.crs(Path::new("x")).unwrap();
        assert!(
            crs.require_metric_coordinates(Path::new("x")).is_ok()
                && crs.require_metric_heights(Path::new("x")).is_ok()
        );
        let heights_in_feet = tags(&[
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 32614, 4099, 0, 1, 9002,
        ]);
        let (crs, _) = heights_in_feet.crs(Path::new("x")).unwrap();
        assert_eq!(
            (
                crs.foreign_unit.is_none(),
                crs.vertical_unit.unwrap().metres
            ),
            (true, 0.3048)
        );
    }

    #[test]
    fn scale_offset_metadata_is_refused() {
        let xml =
            r#"<GDALMetadata><Item name="SCALE" sample="0" role="scale">0.1</Item></GDALMetadata>"#;
        let tags = GeoTags {
            metadata: Some(xml.into()),
            ..Default::default()
        };
        assert!(tags.check_no_scale_offset(Path::new("x")).is_err());
        let xml = r#"<GDALMetadata><Item name="OFFSET" sample="0" role="offset">0</Item><Item name="SCALE" sample="0" role="scale">1</Item></GDALMetadata>"#;
        let tags = GeoTags {
            metadata: Some(xml.into()),
            ..Default::default()
        };
        assert!(tags.check_no_scale_offset(Path::new("x")).is_ok());
    }
}
