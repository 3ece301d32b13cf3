//! Many rasters on one cell lattice read as one (issue 19: inputs larger than memory): a
//! directory of GeoTIFF tiles, a list file naming them, or a GDAL VRT mosaic of them
//! (`gdalbuildvrt`'s), as `dbms ingest --dem` and `--ortho` take them.
//!
//! Invariant: the mosaic's grid is the union of its tiles' extents on their common lattice
//! (same CRS, same cell size, corners a whole number of cells apart), or a VRT's own grid, on
//! which each tile lies where the VRT places it; a cell takes the sample of
//! the last tile in the list that has data there (nodata or alpha 0 never covers data), and a
//! cell no tile covers holds nodata (all bands the declared nodata, or alpha 0). Rows are read
//! band by band from the tiles under them ([`RasterInput::rows`]), so the mosaic is never whole
//! in memory unless a tile has to be.

use super::input::RasterInput;
use super::{SampleValue, Samples, SourceRaster};
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, Grid};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// A tile of a mosaic and where it lies in it.
struct Placed {
    input: RasterInput,
    /// Column and row of the tile's first cell in the mosaic.
    col: usize,
    row: usize,
}

/// Tiles on one lattice, read by rows as one raster.
pub struct Mosaic {
    /// What was given: the directory or the list file.
    path: PathBuf,
    grid: Grid,
    tiles: Vec<Placed>,
    /// The tiles' shared metadata, with no samples.
    head: SourceRaster,
}

/// Extensions of a list file of tiles.
const LIST_EXTENSIONS: [&str; 2] = ["txt", "list"];

/// Whether `path` names a mosaic: a directory, a list file (`.txt`, `.list`) or a VRT.
pub fn is_mosaic(path: &Path) -> bool {
    path.is_dir() || LIST_EXTENSIONS.contains(&extension(path).as_str()) || is_vrt(path)
}

/// `path`'s extension, lower case ("" without one).
fn extension(path: &Path) -> String {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    ext.to_ascii_lowercase()
}

fn is_vrt(path: &Path) -> bool {
    extension(path) == "vrt"
}

/// The first child element of `node` named `name`.
fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, name: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|c| c.tag_name().name() == name)
}

/// What a VRT mosaic says: its grid's size and corner transform, and each source of its first
/// band with the window (column, row, width, height) it fills, in paint order.
struct Vrt {
    width: usize,
    height: usize,
    transform: GeoTransform,
    sources: Vec<(PathBuf, [usize; 4])>,
}

/// Read the VRT at `path`: a plain mosaic (`gdalbuildvrt`'s) whose first band's sources are
/// `SimpleSource`s or `ComplexSource`s, each a whole file copied unscaled into its window.
/// Anything else (a warped VRT, resampled or cropped sources, scaling, lookup tables, kernel
/// filters, pixel functions) is a one-line error naming the fix.
fn read_vrt(path: &Path) -> Result<Vrt> {
    let text = super::read_text(path)?;
    let fix = "make a plain mosaic of tiles on one lattice (gdalbuildvrt over gdalwarp -tap -tr tiles), or give the tiles as a directory";
    let bad = |what: String| Error::file(path, what).fix(fix);
    let doc =
        roxmltree::Document::parse(&text).map_err(|e| bad(format!("is not readable XML ({e})")))?;
    let root = doc.root_element();
    if root.tag_name().name() != "VRTDataset" || root.attribute("subClass").is_some() {
        return Err(bad(
            "is not a plain VRTDataset (a warped or derived VRT)".into()
        ));
    }
    let size = |node: roxmltree::Node, k: &str| -> Result<usize> {
        let v = node
            .attribute(k)
            .and_then(|v| v.trim().parse::<usize>().ok());
        v.ok_or_else(|| {
            bad(format!(
                "has no whole {k} on its {}",
                node.tag_name().name()
            ))
        })
    };
    let numbers: Vec<f64> = child(root, "GeoTransform")
        .and_then(|g| g.text())
        .map(|t| t.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_default();
    let [ox, dx, rx, oy, ry, dy] = numbers[..] else {
        return Err(bad("has no GeoTransform of six numbers".into()));
    };
    if rx != 0.0 || ry != 0.0 {
        return Err(bad(
            "is rotated (its GeoTransform has rotation terms)".into()
        ));
    }
    let band = root
        .children()
        .find(|c| c.tag_name().name() == "VRTRasterBand" && c.attribute("band") == Some("1"))
        .ok_or_else(|| bad("has no band 1".into()))?;
    if band.attribute("subClass").is_some() {
        return Err(bad("computes band 1 (a derived band, not a mosaic)".into()));
    }
    let base = path.parent().unwrap_or(Path::new(""));
    let mut sources = Vec::new();
    for source in band.children().filter(|c| c.is_element()) {
        let kind = source.tag_name().name();
        match kind {
            "SimpleSource" | "ComplexSource" => {}
            "NoDataValue" | "ColorInterp" | "Description" | "Metadata" | "Offset" | "Scale"
            | "UnitType" | "ColorTable" | "CategoryNames" | "Histograms" => continue,
            other => return Err(bad(format!("has a {other} in band 1: not a plain mosaic"))),
        }
        let allowed = [
            "SourceFilename",
            "SourceBand",
            "SourceProperties",
            "SrcRect",
            "DstRect",
            "NODATA",
            "UseMaskBand",
        ];
        if let Some(e) = source
            .children()
            .filter(|c| c.is_element())
            .find(|c| !allowed.contains(&c.tag_name().name()))
        {
            let what = e.tag_name().name();
            return Err(bad(format!(
                "has a {kind} with {what}: a source changed on its way in"
            )));
        }
        let name = child(source, "SourceFilename").and_then(|n| Some((n, n.text()?)));
        let (name, file) =
            name.ok_or_else(|| bad(format!("has a {kind} without SourceFilename")))?;
        let file = match name.attribute("relativeToVRT") == Some("1") {
            true => base.join(file.trim()),
            false => PathBuf::from(file.trim()),
        };
        let rect = |tag: &str| -> Result<[usize; 4]> {
            let r = child(source, tag).ok_or_else(|| bad(format!("has a source without {tag}")))?;
            Ok([
                size(r, "xOff")?,
                size(r, "yOff")?,
                size(r, "xSize")?,
                size(r, "ySize")?,
            ])
        };
        let (src, dst) = (rect("SrcRect")?, rect("DstRect")?);
        if src[..2] != [0, 0] || src[2..] != dst[2..] {
            return Err(bad(format!(
                "takes {} cropped or resampled (SrcRect {src:?}, DstRect {dst:?})",
                file.display()
            )));
        }
        sources.push((file, dst));
    }
    if sources.is_empty() {
        return Err(bad("has no sources in band 1".into()));
    }
    Ok(Vrt {
        width: size(root, "rasterXSize")?,
        height: size(root, "rasterYSize")?,
        transform: GeoTransform {
            origin_x: ox,
            cell_x: dx,
            origin_y: oy,
            cell_y: dy,
        },
        sources,
    })
}

/// The tile files `path` names: a directory's `.tif` / `.tiff` files by name, a list file's
/// lines (paths relative to the list's directory; blank lines and `#` comments skipped), or a
/// VRT's sources in paint order.
pub fn tile_paths(path: &Path) -> Result<Vec<PathBuf>> {
    let fix = "give a directory of GeoTIFF tiles, a list file (.txt) naming one tile a line, or a gdalbuildvrt mosaic";
    let paths: Vec<PathBuf> = if is_vrt(path) {
        read_vrt(path)?
            .sources
            .into_iter()
            .map(|(p, _)| p)
            .collect()
    } else if path.is_dir() {
        let entries = std::fs::read_dir(path).map_err(|e| Error::io(path, e))?;
        let mut tifs = Vec::new();
        for entry in entries {
            let p = entry.map_err(|e| Error::io(path, e))?.path();
            let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
            if p.is_file() && ["tif", "tiff"].contains(&ext.to_ascii_lowercase().as_str()) {
                tifs.push(p);
            }
        }
        tifs.sort();
        tifs
    } else {
        let text = super::read_settings(path).map_err(|e| e.fix(fix))?;
        let base = path.parent().unwrap_or(Path::new(""));
        let lines = text.lines().map(str::trim);
        let named = lines.filter(|l| !l.is_empty() && !l.starts_with('#'));
        named.map(|l| base.join(l)).collect()
    };
    if paths.is_empty() {
        return Err(Error::file(path, "names no tiles").fix(fix));
    }
    Ok(paths)
}

/// Check that `inputs` (opened from `paths`) agree with the first on CRS, cell size, bands,
/// sample type, nodata and alpha band; their bounds `[west, south, east, north]`, world metres.
fn alike(inputs: &[RasterInput], paths: &[PathBuf]) -> Result<[f64; 4]> {
    let first = inputs[0].meta();
    let lattice = inputs[0].grid().transform;
    let crs = &inputs[0].grid().crs;
    let (mut x0, mut y0) = (f64::INFINITY, f64::INFINITY);
    let (mut x1, mut y1) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for (input, p) in inputs.iter().zip(paths) {
        let (m, g) = (input.meta(), input.grid());
        let differs = |what: &str, a: String, b: String| {
            Error::file(
                p,
                format!(
                    "has {what} {a}, but {} has {b}: a mosaic's tiles must agree",
                    paths[0].display()
                ),
            )
            .fix("make the tiles alike (gdal_translate -ot / -a_nodata, gdalwarp -t_srs -tr -tap)")
        };
        if g.crs != *crs {
            return Err(differs("CRS", g.crs.name(), crs.name()));
        }
        let t = &g.transform;
        if (t.cell_x, t.cell_y) != (lattice.cell_x, lattice.cell_y) {
            let cell = |t: &GeoTransform| format!("{} × {}", t.cell_x, t.cell_y);
            return Err(differs("cells", cell(t), cell(&lattice)));
        }
        if (m.bands, m.samples.type_name()) != (first.bands, first.samples.type_name()) {
            let kind = |m: &SourceRaster| format!("{} {} band(s)", m.bands, m.samples.type_name());
            return Err(differs("samples", kind(m), kind(first)));
        }
        let same_nodata = match (m.nodata, first.nodata) {
            (Some(a), Some(b)) => a == b || (a.is_nan() && b.is_nan()),
            (a, b) => a.is_none() && b.is_none(),
        };
        if !same_nodata || m.alpha_band != first.alpha_band {
            let nodata = |m: &SourceRaster| {
                format!("nodata {:?} and alpha band {:?}", m.nodata, m.alpha_band)
            };
            return Err(differs("its", nodata(m), nodata(first)));
        }
        for (c, r) in [(0.0, 0.0), (g.width as f64, g.height as f64)] {
            let (x, y) = t.pixel_to_world(c, r);
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
    }
    Ok([x0, y0, x1, y1])
}

/// `v` metres as a whole, non-negative number of cells of `step` metres along `axis`; the error
/// names `p`, the file that lies off the mosaic's lattice or outside its grid.
fn whole_cells(v: f64, step: f64, p: &Path, axis: &str) -> Result<usize> {
    let k = v / step;
    let whole = k.round();
    if whole < 0.0 {
        return Err(Error::file(
            p,
            format!(
                "lies {} cells outside the mosaic's grid along {axis}",
                -whole
            ),
        )
        .fix("rebuild the VRT from the tiles as they are (gdalbuildvrt)"));
    }
    if (k - whole).abs() > 1e-6 {
        return Err(Error::file(
            p,
            format!("lies {k:.3} cells from the mosaic's corner along {axis}, not a whole number: it is not on the other tiles' cell lattice"),
        )
        .fix("align the tiles to one lattice (gdalwarp -tap -tr)"));
    }
    Ok(whole as usize)
}

impl Mosaic {
    /// The tiles `path` names ([`tile_paths`]), each opened and checked to share the first
    /// one's lattice, CRS, bands, sample type and nodata; one-line errors name the tile.
    pub fn open(path: &Path) -> Result<Mosaic> {
        let paths = tile_paths(path)?;
        let mut inputs = Vec::with_capacity(paths.len());
        for p in &paths {
            if is_mosaic(p) {
                return Err(
                    Error::file(path, format!("names {}, itself a mosaic", p.display()))
                        .fix("name the tiles themselves"),
                );
            }
            inputs.push(RasterInput::open(p)?);
        }
        let lattice = inputs[0].grid().transform;
        let crs = inputs[0].grid().crs.clone();
        let [x0, y0, x1, y1] = alike(&inputs, &paths)?;
        // The mosaic's corner: a VRT's own, or the west-most, north-most tile corner (south-most
        // when rows run north); every tile corner must then be a whole number of cells from it.
        let vrt = is_vrt(path).then(|| read_vrt(path)).transpose()?;
        let transform = match &vrt {
            Some(v)
                if (v.transform.cell_x, v.transform.cell_y) != (lattice.cell_x, lattice.cell_y) =>
            {
                return Err(Error::file(
                    path,
                    format!(
                        "has cells {} × {}, its tiles {} × {}: it resamples them",
                        v.transform.cell_x, v.transform.cell_y, lattice.cell_x, lattice.cell_y
                    ),
                )
                .fix("build the VRT at the tiles' resolution (gdalbuildvrt without -tr), or give the tiles as a directory"));
            }
            Some(v) => v.transform,
            None => GeoTransform {
                origin_x: x0,
                origin_y: if lattice.cell_y < 0.0 { y1 } else { y0 },
                ..lattice
            },
        };
        let mut tiles = Vec::with_capacity(inputs.len());
        for (input, p) in inputs.into_iter().zip(&paths) {
            let t = &input.grid().transform;
            let col = whole_cells(t.origin_x - transform.origin_x, lattice.cell_x, p, "x")?;
            let row = whole_cells(t.origin_y - transform.origin_y, lattice.cell_y, p, "y")?;
            tiles.push(Placed { input, col, row });
        }
        let (width, height) = match &vrt {
            Some(v) => (v.width, v.height),
            None => (
                whole_cells(x1 - x0, lattice.cell_x.abs(), path, "x")?,
                whole_cells(y1 - y0, lattice.cell_y.abs(), path, "y")?,
            ),
        };
        // A VRT places each tile itself: its window must be where the tile's georeference is.
        for (k, t) in tiles.iter().enumerate() {
            let g = t.input.grid();
            let at = [t.col, t.row, g.width, g.height];
            let placed = vrt.as_ref().map_or(at, |v| v.sources[k].1);
            if placed != at || t.col + g.width > width || t.row + g.height > height {
                return Err(Error::file(
                    &paths[k],
                    format!("lies at cells {at:?} of the mosaic's grid, but {} places it at {placed:?} of a {width} × {height} grid", path.display()),
                )
                .fix("rebuild the VRT from the tiles as they are (gdalbuildvrt)"));
            }
        }
        let grid = Grid {
            width,
            height,
            transform,
            crs,
        };
        Mosaic::of(path, grid, tiles)
    }

    /// The mosaic at `path` of `tiles` placed on `grid`: an error when cells no tile covers
    /// could not be told from data.
    fn of(path: &Path, grid: Grid, tiles: Vec<Placed>) -> Result<Mosaic> {
        let covered: u64 = tiles.iter().map(|t| t.input.grid().len() as u64).sum();
        let first = tiles[0].input.meta();
        if covered < grid.len() as u64 && first.nodata.is_none() && first.alpha_band.is_none() {
            return Err(Error::file(
                path,
                "leaves cells no tile covers, and its tiles declare no nodata value or alpha band to mark them",
            )
            .fix("give the tiles a nodata value (gdal_translate -a_nodata) or an alpha band, or fill the gaps"));
        }
        let head = SourceRaster {
            path: path.to_path_buf(),
            grid: grid.window_grid(&crate::grid::Window {
                col: 0,
                row: 0,
                width: grid.width,
                height: 0,
            }),
            samples: first.samples.slice(0..0),
            ..first.clone_meta()
        };
        Ok(Mosaic {
            path: path.to_path_buf(),
            grid,
            tiles,
            head,
        })
    }

    /// The mosaic's grid.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The tiles' shared metadata (no samples); its path is the directory or list file.
    pub fn meta(&self) -> &SourceRaster {
        &self.head
    }

    /// Every tile file, in list order.
    pub fn files(&self) -> Vec<PathBuf> {
        self.tiles
            .iter()
            .map(|t| t.input.meta().path.clone())
            .collect()
    }

    /// Rows `rows` (all columns) on their sub-grid: each cell from the last tile with data
    /// there, nodata where none has.
    pub fn rows(&self, rows: Range<usize>) -> Result<SourceRaster> {
        let (w, b, h) = (self.grid.width, self.head.bands, rows.len());
        let fill = match (self.head.alpha_band, self.head.nodata) {
            (Some(_), _) => 0.0,
            (None, Some(v)) => v,
            (None, None) => 0.0, // every cell is covered (checked when opened)
        };
        let mut samples = self.head.samples.filled(w * h * b, fill);
        for tile in &self.tiles {
            let tg = tile.input.grid();
            let lo = rows.start.max(tile.row);
            let hi = rows.end.min(tile.row + tg.height);
            if lo >= hi {
                continue;
            }
            let part = tile.input.rows(lo - tile.row..hi - tile.row)?;
            let tw = tg.width;
            let (alpha, nodata) = (self.head.alpha_band, self.head.nodata);
            copy_valid(&part.samples, &mut samples, b, alpha, nodata, |k| {
                // Tile sample k (pixel-interleaved) lands at this mosaic sample.
                let (px, band) = (k / b, k % b);
                let (r, c) = (lo - rows.start + px / tw, tile.col + px % tw);
                (r * w + c) * b + band
            });
        }
        Ok(SourceRaster {
            path: self.path.clone(),
            grid: self.grid.window_grid(&crate::grid::Window {
                col: 0,
                row: rows.start,
                width: w,
                height: h,
            }),
            samples,
            ..self.head.clone_meta()
        })
    }
}

/// Copy the pixels of `src` (`bands` samples each) that hold data into `dst` at `at(k)` for
/// each sample `k`: a pixel is nodata when its alpha band is 0, or when every band equals the
/// declared `nodata`.
fn copy_valid(
    src: &Samples,
    dst: &mut Samples,
    bands: usize,
    alpha: Option<usize>,
    nodata: Option<f64>,
    at: impl Fn(usize) -> usize,
) {
    macro_rules! copy {
        ($($t:ident),*) => {
            match (src, dst) {
                $((Samples::$t(s), Samples::$t(d)) => {
                    for (p, px) in s.chunks_exact(bands).enumerate() {
                        let empty = match (alpha, nodata) {
                            (Some(a), _) => Into::<f64>::into(px[a]) == 0.0,
                            (None, Some(v)) => px.iter().all(|x| x.is_nodata(v)),
                            (None, None) => false,
                        };
                        if !empty {
                            for (k, &x) in px.iter().enumerate() {
                                d[at(p * bands + k)] = x;
                            }
                        }
                    }
                })*
                _ => unreachable!("a mosaic's tiles share their sample type (checked when opened)"),
            }
        };
    }
    copy!(U8, U16, I16, U32, I32, F32, F64);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::io::geotiff;
    use crate::raster::Raster;

    /// Tile `name` of `w × h` 1 m cells with its corner `(c, r)` cells from (1000, 2000),
    /// each cell `value(col, row)` in the mosaic's numbering.
    fn tile(dir: &Path, name: &str, [c, r, w, h]: [usize; 4], value: impl Fn(usize, usize) -> f32) {
        let g = Grid::north_up(
            1000.0 + c as f64,
            2000.0 - r as f64,
            1.0,
            w,
            h,
            Crs::epsg(32632),
        );
        let z = (0..w * h).map(|i| value(c + i % w, r + i / w)).collect();
        geotiff::write_f32(&dir.join(name), &Raster::new(g, z)).unwrap();
    }

    fn cells(m: &Mosaic, rows: Range<usize>) -> Vec<f64> {
        let part = m.rows(rows).unwrap();
        (0..part.samples.len())
            .map(|i| part.samples.get(i))
            .collect()
    }

    /// A gap is nodata; where two tiles overlap the later one in the list wins, except where
    /// it has no data; any band of rows reads what the whole read holds.
    #[test]
    fn gaps_are_nodata_and_later_tiles_cover_earlier_ones_with_data() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        // A 6 × 5 mosaic: a (0..4, 0..3), b (3..6, 0..3) overlapping a in column 3 with a
        // nodata cell at (3, 1); c (0..2, 3..5); cells (2..6, 3..5) are no tile's.
        tile(d, "a.tif", [0, 0, 4, 3], |c, r| (10 * r + c) as f32);
        tile(d, "b.tif", [3, 0, 3, 3], |c, r| match (c, r) {
            (3, 1) => f32::NAN,
            _ => (100 + 10 * r + c) as f32,
        });
        tile(d, "c.tif", [0, 3, 2, 2], |c, r| (200 + 10 * r + c) as f32);
        std::fs::write(d.join("tiles.list"), "a.tif\nb.tif\nc.tif\n").unwrap();
        let m = Mosaic::open(&d.join("tiles.list")).unwrap();
        assert_eq!((m.grid().width, m.grid().height), (6, 5));
        assert_eq!(m.grid().transform.origin_x, 1000.0);
        let nd = -9999.0;
        #[rustfmt::skip]
        let want = [
            0.0, 1.0, 2.0, 103.0, 104.0, 105.0,
            10.0, 11.0, 12.0, 13.0, 114.0, 115.0,
            20.0, 21.0, 22.0, 123.0, 124.0, 125.0,
            230.0, 231.0, nd, nd, nd, nd,
            240.0, 241.0, nd, nd, nd, nd,
        ];
        assert_eq!(cells(&m, 0..5), want);
        for rows in [0..1, 1..4, 3..5, 2..2] {
            assert_eq!(
                cells(&m, rows.clone()),
                want[rows.start * 6..rows.end * 6],
                "{rows:?}"
            );
        }
        assert_eq!(m.meta().nodata, Some(nd));
        let names: Vec<_> = m
            .files()
            .iter()
            .map(|f| f.file_name().unwrap().to_owned())
            .collect();
        assert_eq!(names, ["a.tif", "b.tif", "c.tif"]);
    }

    /// A VRT places its tiles itself; one that changes them on the way in (resampling,
    /// scaling, filtering, warping) or misplaces them is refused in one line.
    #[test]
    fn a_plain_vrt_mosaic_reads_and_others_are_refused() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        tile(d, "a.tif", [0, 0, 4, 3], |c, r| (10 * r + c) as f32);
        tile(d, "b.tif", [4, 0, 2, 3], |c, r| (100 + 10 * r + c) as f32);
        let vrt = |band: &str, transform: &str| {
            format!(
                r#"<VRTDataset rasterXSize="7" rasterYSize="3"><GeoTransform>{transform}</GeoTransform>
                <VRTRasterBand dataType="Float32" band="1"><NoDataValue>-9999</NoDataValue>{band}</VRTRasterBand></VRTDataset>"#
            )
        };
        let source = |kind: &str, file: &str, src: [usize; 4], dst: [usize; 4], extra: &str| {
            format!(
                r#"<{kind}><SourceFilename relativeToVRT="1">{file}</SourceFilename><SourceBand>1</SourceBand>
                <SrcRect xOff="{}" yOff="{}" xSize="{}" ySize="{}"/><DstRect xOff="{}" yOff="{}" xSize="{}" ySize="{}"/>{extra}</{kind}>"#,
                src[0], src[1], src[2], src[3], dst[0], dst[1], dst[2], dst[3]
            )
        };
        // One column wider than the tiles: the VRT's grid, the extra column nodata.
        let corner = "999, 1, 0, 2000, 0, -1";
        let good = source(
            "ComplexSource",
            "a.tif",
            [0, 0, 4, 3],
            [1, 0, 4, 3],
            "<NODATA>-9999</NODATA>",
        ) + &source("SimpleSource", "b.tif", [0, 0, 2, 3], [5, 0, 2, 3], "");
        std::fs::write(d.join("m.vrt"), vrt(&good, corner)).unwrap();
        let m = Mosaic::open(&d.join("m.vrt")).unwrap();
        assert_eq!(
            (m.grid().width, m.grid().height, m.grid().transform.origin_x),
            (7, 3, 999.0)
        );
        assert_eq!(
            cells(&m, 1..2),
            [-9999.0, 10.0, 11.0, 12.0, 13.0, 114.0, 115.0]
        );
        for (band, transform, want) in [
            (
                source("SimpleSource", "a.tif", [0, 0, 4, 3], [1, 0, 2, 3], ""),
                corner,
                "cropped or resampled",
            ),
            (
                source("SimpleSource", "a.tif", [1, 0, 3, 3], [1, 0, 3, 3], ""),
                corner,
                "cropped or resampled",
            ),
            (
                source(
                    "ComplexSource",
                    "a.tif",
                    [0, 0, 4, 3],
                    [1, 0, 4, 3],
                    "<ScaleRatio>2</ScaleRatio>",
                ),
                corner,
                "ScaleRatio",
            ),
            (
                source(
                    "KernelFilteredSource",
                    "a.tif",
                    [0, 0, 4, 3],
                    [1, 0, 4, 3],
                    "",
                ),
                corner,
                "KernelFilteredSource",
            ),
            (
                source("SimpleSource", "a.tif", [0, 0, 4, 3], [2, 0, 4, 3], ""),
                corner,
                "places it at [2, 0, 4, 3]",
            ),
            (good.clone(), "999, 0.5, 0, 2000, 0, -0.5", "resamples them"),
            (good.clone(), "999, 1, 0.1, 2000, 0, -1", "rotated"),
        ] {
            std::fs::write(d.join("m.vrt"), vrt(&band, transform)).unwrap();
            let e = Mosaic::open(&d.join("m.vrt")).err().unwrap().to_string();
            assert!(e.contains(want) && !e.contains('\n'), "{want}: {e}");
        }
        let warped = r#"<VRTDataset subClass="VRTWarpedDataset" rasterXSize="1" rasterYSize="1"/>"#;
        std::fs::write(d.join("m.vrt"), warped).unwrap();
        let e = Mosaic::open(&d.join("m.vrt")).err().unwrap().to_string();
        assert!(e.contains("not a plain VRTDataset"), "{e}");
    }

    /// Tiles that do not fit together, and lists that name nothing usable, are one-line errors
    /// naming the file and the fix.
    #[test]
    fn tiles_that_do_not_fit_together_are_refused() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        tile(d, "a.tif", [0, 0, 4, 3], |_, _| 1.0);
        let off = Grid::north_up(1004.5, 2000.0, 1.0, 2, 2, Crs::epsg(32632));
        geotiff::write_f32(&d.join("off.tif"), &Raster::new(off, vec![1.0; 4])).unwrap();
        let fine = Grid::north_up(1004.0, 2000.0, 0.5, 2, 2, Crs::epsg(32632));
        geotiff::write_f32(&d.join("fine.tif"), &Raster::new(fine, vec![1.0; 4])).unwrap();
        let utm33 = Grid::north_up(1004.0, 2000.0, 1.0, 2, 2, Crs::epsg(32633));
        geotiff::write_f32(&d.join("utm33.tif"), &Raster::new(utm33, vec![1.0; 4])).unwrap();
        let bytes = Grid::north_up(1004.0, 2000.0, 1.0, 2, 2, Crs::epsg(32632));
        geotiff::write_u8(
            &d.join("u8.tif"),
            &Raster::new(bytes.clone(), vec![1; 4]),
            None,
        )
        .unwrap();
        geotiff::write_u8(
            &d.join("u8b.tif"),
            &Raster::new(
                Grid::north_up(1006.0, 2000.0, 1.0, 2, 2, Crs::epsg(32632)),
                vec![1; 4],
            ),
            None,
        )
        .unwrap();
        std::fs::write(d.join("empty.txt"), "# nothing\n\n").unwrap();
        for (list, want) in [
            ("a.tif\noff.tif\n", "not on the other tiles' cell lattice"),
            ("a.tif\nfine.tif\n", "has cells"),
            ("a.tif\nutm33.tif\n", "has CRS"),
            ("a.tif\nu8.tif\n", "has samples"),
            ("u8.tif\nu8b.tif\nmissing.tif\n", "missing.tif"),
            ("empty.txt\n", "itself a mosaic"),
        ] {
            std::fs::write(d.join("l.txt"), list).unwrap();
            let e = Mosaic::open(&d.join("l.txt")).err().unwrap().to_string();
            assert!(e.contains(want) && !e.contains('\n'), "{list:?}: {e}");
        }
        let e = Mosaic::open(&d.join("empty.txt"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("names no tiles"), "{e}");
        // Two byte tiles without nodata that leave a gap: nothing could mark it.
        let gap = Grid::north_up(1004.0, 1995.0, 1.0, 2, 2, Crs::epsg(32632));
        geotiff::write_u8(&d.join("u8c.tif"), &Raster::new(gap, vec![1; 4]), None).unwrap();
        std::fs::write(d.join("l.txt"), "u8.tif\nu8c.tif\n").unwrap();
        let e = Mosaic::open(&d.join("l.txt")).err().unwrap().to_string();
        assert!(
            e.contains("no tile covers") && e.contains("-a_nodata"),
            "{e}"
        );
    }
}
