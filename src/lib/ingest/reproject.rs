//! Reprojection for ingest (feature `gdal`): the CRS of `--t-srs`, and extents carried from one
//! CRS to another (densified edges, so curved images of straight edges are covered). The pixels
//! themselves are warped by [`crate::io::gdal::warp_to_grid`].

use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::Bounds;
use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};

/// A CRS from a user definition GDAL understands (`EPSG:32614`, WKT, PROJ string).
pub fn crs_from_definition(def: &str) -> Result<Crs> {
    let srs = SpatialRef::from_definition(def).map_err(|e| {
        Error::msg(format!("--t-srs {def:?} is not a CRS GDAL knows ({e})"))
            .fix("e.g. --t-srs EPSG:32614")
    })?;
    let wkt = srs
        .to_wkt()
        .map_err(|e| Error::msg(format!("--t-srs {def:?}: {e}")))?;
    let epsg = srs.auth_code().ok().and_then(|c| u32::try_from(c).ok());
    let (foreign_unit, vertical_unit) = crate::crs::foreign_units_in_wkt(&wkt);
    let geographic = srs.is_geographic();
    Ok(Crs {
        epsg,
        wkt: Some(wkt),
        geographic,
        foreign_unit: foreign_unit.filter(|_| !geographic),
        vertical_unit,
    })
}

fn spatial_ref(crs: &Crs) -> Result<SpatialRef> {
    let srs = match (crs.epsg, &crs.wkt) {
        (Some(code), _) => SpatialRef::from_epsg(code),
        (None, Some(wkt)) => SpatialRef::from_wkt(wkt),
        (None, None) => {
            return Err(
                Error::msg("an input has no CRS, so it cannot be reprojected")
                    .fix("assign one with gdal_translate -a_srs"),
            )
        }
    };
    let mut srs =
        srs.map_err(|e| Error::msg(format!("GDAL does not know {} ({e})", crs.name())))?;
    srs.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    Ok(srs)
}

/// The extent in `to` of rectangle `b` given in `from` (21 points per edge).
pub fn transform_bounds(b: &Bounds, from: &Crs, to: &Crs) -> Result<Bounds> {
    let t = CoordTransform::new(&spatial_ref(from)?, &spatial_ref(to)?).map_err(|e| {
        Error::msg(format!(
            "no transformation from {} to {} ({e})",
            from.name(),
            to.name()
        ))
    })?;
    let [min_x, min_y, max_x, max_y] = t
        .transform_bounds(&[b.min_x, b.min_y, b.max_x, b.max_y], 21)
        .map_err(|e| {
            Error::msg(format!(
                "cannot carry an extent from {} to {} ({e})",
                from.name(),
                to.name()
            ))
        })?;
    Ok(Bounds {
        min_x,
        min_y,
        max_x,
        max_y,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utm_extent_to_geographic_and_back_covers_it() {
        let utm = Crs::epsg(32614);
        let geo = crs_from_definition("EPSG:4326").unwrap();
        assert!(geo.geographic && geo.epsg == Some(4326));
        let b = Bounds {
            min_x: 640_000.0,
            min_y: 3_600_000.0,
            max_x: 670_000.0,
            max_y: 3_630_000.0,
        };
        let g = transform_bounds(&b, &utm, &geo).unwrap();
        assert!(
            g.min_x > -97.6 && g.max_x < -97.1 && g.min_y > 32.5 && g.max_y < 32.85,
            "{g:?}"
        );
        let back = transform_bounds(&g, &geo, &utm).unwrap();
        assert!(
            back.min_x <= b.min_x
                && back.max_x >= b.max_x
                && back.min_y <= b.min_y
                && back.max_y >= b.max_y
        );
        assert!(crs_from_definition("EPSG:999999999").is_err());
    }
}
