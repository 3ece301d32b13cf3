//! Esri ASCII grid (`.asc`): a text header then `nrows` rows of `ncols` numbers.
//!
//! # Invariant
//! The header's lower-left reference (`xllcorner`/`yllcorner`, or `xllcenter`/`yllcenter` which
//! is half a cell inside) becomes the corner-convention top-left origin
//! `(xll, yll + nrows · cellsize)`. Values are kept exactly as written: all-integer grids as
//! Int32 (as GDAL does), anything with a decimal point or exponent as Float64.

use super::{read_prj, Samples, SourceRaster};
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, Grid};
use rayon::prelude::*;
use std::path::Path;

/// Header keywords (lower-case).
const KEYS: &[&str] = &[
    "ncols",
    "nrows",
    "xllcorner",
    "xllcenter",
    "yllcorner",
    "yllcenter",
    "cellsize",
    "dx",
    "dy",
    "nodata_value",
];

/// True when `head` (the first bytes of a file) starts with an Esri ASCII grid header keyword.
pub fn looks_like(head: &[u8]) -> bool {
    let head = head.strip_prefix(b"\xef\xbb\xbf").unwrap_or(head);
    let start = head
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(head.len());
    let word: Vec<u8> = head[start..]
        .iter()
        .take_while(|b| b.is_ascii_alphabetic() || **b == b'_')
        .map(u8::to_ascii_lowercase)
        .collect();
    let next = head.get(start + word.len());
    KEYS.iter().any(|k| k.as_bytes() == word.as_slice())
        && next.is_some_and(|b| b.is_ascii_whitespace())
}

/// The parsed header.
#[derive(Debug, Default)]
struct Header {
    ncols: Option<usize>,
    nrows: Option<usize>,
    xll: Option<(f64, bool)>,
    yll: Option<(f64, bool)>,
    cellsize: Option<f64>,
    dx: Option<f64>,
    dy: Option<f64>,
    nodata: Option<f64>,
}

/// Read an Esri ASCII grid and its sibling `.prj`.
/// Errors name the line: missing or repeated header keys, non-numbers, wrong value counts.
pub fn read(path: &Path) -> Result<SourceRaster> {
    let bytes = crate::io::read_bytes(path)?;
    let text = std::str::from_utf8(&bytes).map_err(|e| {
        Error::file(
            path,
            format!(
                "not a text file (invalid UTF-8 at byte {})",
                e.valid_up_to()
            ),
        )
    })?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let (grid_shape, samples, nodata) = parse(text).map_err(|e| e.in_file(path))?;
    let (ncols, nrows, transform) = grid_shape;
    let crs = read_prj(path)?;
    Ok(SourceRaster {
        path: path.to_path_buf(),
        grid: Grid {
            width: ncols,
            height: nrows,
            transform,
            crs,
        },
        bands: 1,
        samples,
        nodata,
        alpha_band: None,
        pixel_is_point: false,
        format: "AAIGrid",
    })
}

type Shape = (usize, usize, GeoTransform);

/// Parse the whole text: header, then exactly `ncols · nrows` numbers.
fn parse(text: &str) -> Result<(Shape, Samples, Option<f64>)> {
    let lines: Vec<(usize, &str)> = text.lines().enumerate().map(|(i, l)| (i + 1, l)).collect();
    let mut h = Header::default();
    let mut first_data = lines.len();
    for (idx, &(n, line)) in lines.iter().enumerate() {
        let mut tokens = line.split_ascii_whitespace();
        let Some(key) = tokens.next() else { continue };
        if !key.starts_with(|c: char| c.is_ascii_alphabetic()) || key.eq_ignore_ascii_case("nan") {
            first_data = idx;
            break;
        }
        let value = tokens
            .next()
            .ok_or_else(|| line_error(n, format!("header keyword '{key}' has no value")))?;
        if tokens.next().is_some() {
            return Err(line_error(
                n,
                format!("header line '{}' has more than one value", line.trim()),
            ));
        }
        header_entry(&mut h, n, key, value)?;
    }
    let shape = shape(&h)?;
    let (ncols, nrows, _) = shape;
    let data = &lines[first_data..];
    let rows: Vec<Vec<f64>> = data
        .par_iter()
        .map(|&(n, line)| parse_values(n, line))
        .collect::<Result<_>>()?;
    let count: usize = rows.iter().map(Vec::len).sum();
    let expected = ncols * nrows;
    if count != expected {
        return Err(Error::msg(format!(
            "has {count} values but the header says ncols × nrows = {ncols} × {nrows} = {expected}"
        ))
        .fix("check ncols/nrows and that the file is complete"));
    }
    let is_int = |v: f64| v.fract() == 0.0 && v >= i32::MIN as f64 && v <= i32::MAX as f64;
    let integer_text = data.par_iter().all(|(_, l)| {
        !l.bytes()
            .any(|b| matches!(b, b'.' | b'e' | b'E' | b'n' | b'N' | b'i' | b'I'))
    });
    let values: Vec<f64> = rows.into_iter().flatten().collect();
    let samples = if integer_text && values.par_iter().all(|&v| is_int(v)) {
        Samples::I32(values.into_par_iter().map(|v| v as i32).collect())
    } else {
        Samples::F64(values)
    };
    Ok((shape, samples, h.nodata))
}

fn line_error(n: usize, problem: String) -> Error {
    Error::msg(format!("line {n}: {problem}"))
}

fn number(n: usize, key: &str, s: &str) -> Result<f64> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() || key == "nodata_value")
        .ok_or_else(|| line_error(n, format!("{key} value '{s}' is not a number")))
}

fn header_entry(h: &mut Header, n: usize, key: &str, value: &str) -> Result<()> {
    let k = key.to_ascii_lowercase();
    let count = |s: &str| -> Result<usize> {
        s.parse::<usize>()
            .ok()
            .filter(|&v| v > 0)
            .ok_or_else(|| line_error(n, format!("{k} '{s}' is not a positive whole number")))
    };
    let slot_taken = match k.as_str() {
        "ncols" => h.ncols.replace(count(value)?).is_some(),
        "nrows" => h.nrows.replace(count(value)?).is_some(),
        "xllcorner" | "xllcenter" => h.xll.replace((number(n, &k, value)?, k.ends_with("center"))).is_some(),
        "yllcorner" | "yllcenter" => h.yll.replace((number(n, &k, value)?, k.ends_with("center"))).is_some(),
        "cellsize" => h.cellsize.replace(number(n, &k, value)?).is_some(),
        "dx" => h.dx.replace(number(n, &k, value)?).is_some(),
        "dy" => h.dy.replace(number(n, &k, value)?).is_some(),
        "nodata_value" => h.nodata.replace(number(n, &k, value)?).is_some(),
        _ => {
            return Err(line_error(n, format!("unknown header keyword '{key}'"))
                .fix("the header has ncols, nrows, xllcorner|xllcenter, yllcorner|yllcenter, cellsize (or dx, dy), NODATA_value"))
        }
    };
    if slot_taken {
        return Err(line_error(n, format!("{k} is given twice")));
    }
    Ok(())
}

/// Size and corner-convention transform from a complete header.
fn shape(h: &Header) -> Result<Shape> {
    let missing = |what: &str| {
        Error::msg(format!("header has no {what}"))
            .fix("an Esri ASCII grid header needs ncols, nrows, xllcorner, yllcorner and cellsize")
    };
    let ncols = h.ncols.ok_or_else(|| missing("ncols"))?;
    let nrows = h.nrows.ok_or_else(|| missing("nrows"))?;
    let (xll, x_centre) = h.xll.ok_or_else(|| missing("xllcorner"))?;
    let (yll, y_centre) = h.yll.ok_or_else(|| missing("yllcorner"))?;
    let (dx, dy) = match (h.cellsize, h.dx, h.dy) {
        (Some(c), None, None) => (c, c),
        (None, Some(dx), Some(dy)) => (dx, dy),
        _ => return Err(missing("cellsize (or both dx and dy, not both kinds)")),
    };
    if !(dx > 0.0 && dy > 0.0) {
        return Err(Error::msg(format!("cell size {dx} × {dy} is not positive")));
    }
    let x0 = if x_centre { xll - 0.5 * dx } else { xll };
    let y0 = if y_centre { yll - 0.5 * dy } else { yll };
    let transform = GeoTransform {
        origin_x: x0,
        origin_y: y0 + nrows as f64 * dy,
        cell_x: dx,
        cell_y: -dy,
    };
    Ok((ncols, nrows, transform))
}

/// The numbers of one data line.
fn parse_values(n: usize, line: &str) -> Result<Vec<f64>> {
    line.split_ascii_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| line_error(n, format!("'{t}' is not a number")))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_and_centre_headers() {
        let ((w, h, t), s, nd) = parse("ncols 3\nnrows 2\nxllcorner 10\nyllcorner 20\ncellsize 2\nNODATA_value -9999\n1 2 3\n4 -9999 6\n").unwrap();
        assert_eq!((w, h), (3, 2));
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 10.0,
                origin_y: 24.0,
                cell_x: 2.0,
                cell_y: -2.0
            }
        );
        assert_eq!(s, Samples::I32(vec![1, 2, 3, 4, -9999, 6]));
        assert_eq!(nd, Some(-9999.0));
        let ((_, _, t), s, _) =
            parse("NCOLS 2\nNROWS 1\nXLLCENTER 10\nYLLCENTER 20\nDX 2\nDY 4\n1.5 2\n").unwrap();
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 9.0,
                origin_y: 22.0,
                cell_x: 2.0,
                cell_y: -4.0
            }
        );
        assert_eq!(s, Samples::F64(vec![1.5, 2.0]));
    }

    #[test]
    fn values_may_wrap_lines() {
        let (_, s, _) =
            parse("ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4 5\n6\n")
                .unwrap();
        assert_eq!(s, Samples::I32(vec![1, 2, 3, 4, 5, 6]));
    }

    #[test]
    fn errors_name_the_line() {
        let hdr = "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n";
        let e = parse(&format!("{hdr}1 x\n")).unwrap_err().to_string();
        assert_eq!(e, "line 6: 'x' is not a number");
        let e = parse(&format!("{hdr}1 2 3\n")).unwrap_err().to_string();
        assert!(e.contains("has 3 values") && e.contains("= 2"), "{e}");
        let e = parse("ncols 2\nnrows one\n").unwrap_err().to_string();
        assert!(e.starts_with("line 2: nrows 'one'"), "{e}");
        let e = parse("ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\n1 2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("cellsize"), "{e}");
        let e = parse("ncols 2\nncols 2\n").unwrap_err().to_string();
        assert!(e.contains("twice"), "{e}");
        assert!(parse("ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize -1\n1 2\n").is_err());
        assert!(parse("ncols 2\nbogus 1\n").is_err());
    }

    #[test]
    fn recognises_header_keywords_only() {
        assert!(looks_like(b"ncols        20\nnrows 15"));
        assert!(looks_like(b"\xef\xbb\xbf  NCOLS\t3"));
        assert!(looks_like(b"nrows 3\n"));
        assert!(!looks_like(b"ncolsx 3"));
        assert!(!looks_like(b"hello world"));
    }
}
