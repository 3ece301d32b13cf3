//! One tile of one level: its terrain simplified and draped, what stands in it, written as a
//! `.glb`, and its terrain measured against level 0.

use super::standing::Things;
use super::{max3, mean_opaque, min3, Levels, BAND_ROWS};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::io::atomic::{AtomicFile, Staged};
use crate::mesh::gltf::write_glb;
use crate::mesh::tileset::Frame;
use crate::mesh::tin::{simplify, Heights, Tin};
use crate::mesh::{Drape, Lighting, Mesh, Part};
use crate::raster::RowSource;
use std::io::Write;
use std::path::Path;

/// What one tile became.
pub(super) struct Built {
    /// Its frame: origin (world), to ECEF, departure at its corners.
    pub(super) frame: Frame,
    /// Its box in its local frame, when it has content.
    pub(super) bounds: Option<([f64; 3], [f64; 3])>,
    pub(super) uri: Option<String>,
    pub(super) terrain_triangles: u64,
    pub(super) triangles: u64,
    pub(super) bytes: u64,
    pub(super) error: Measured,
}

/// A tile's terrain against level 0.
#[derive(Default)]
pub(super) struct Measured {
    pub(super) max: f64,
    pub(super) sum_sq: f64,
    pub(super) points: u64,
    pub(super) uncovered: u64,
}

/// Tile `(tx, ty)` of `level` in `frame`: its terrain TIN with the photo draped, the standing
/// meshes it holds, staged as a `.glb` under `dir` when it has content, and its terrain's
/// error against the level-0 points it owns.
#[allow(clippy::too_many_arguments)]
pub(super) fn build_tile(
    levels: &Levels,
    level: usize,
    tx: usize,
    ty: usize,
    elevation: &dyn RowSource<f32>,
    colour: &dyn RowSource<[u8; 4]>,
    standing: &Things,
    frame: Frame,
    dir: &Path,
) -> Result<(Built, Option<Staged>)> {
    let grid = elevation.grid();
    let cols = levels.points(level, tx, grid.width);
    let rows = levels.points(level, ty, grid.height);
    let z = read_points(elevation, &rows, &cols)?;
    let heights = Heights {
        width: cols.len(),
        height: rows.len(),
        z: &z,
    };
    let tin = simplify(&heights, levels.bound(level));
    let (terrain, drape, cell_tris) =
        terrain_mesh(grid, &tin, &rows, &cols, &z, colour, levels.stride(level))?;
    let (nx, ny) = levels.across(level);
    let own_cols = levels.owned(level, tx, grid.width, nx);
    let own_rows = levels.owned(level, ty, grid.height, ny);
    let error = measure(elevation, &cell_tris, own_cols.clone(), own_rows.clone())?;

    let mut things = Mesh::default();
    for (col, row, m, base) in &standing.meshes {
        if own_cols.contains(col) && own_rows.contains(row) {
            let first = things.positions.len();
            things.append(m);
            // Walls reach the level's bound below the lowest terrain: no gap under them.
            if let Some(base) = base {
                for p in &mut things.positions[first..] {
                    if p[2] == *base {
                        p[2] = base - levels.bound(level);
                    }
                }
            }
        }
    }
    let parts: Vec<Part> = [
        (terrain, Lighting::Unlit, Some(drape)),
        (things, Lighting::Lit, None),
    ]
    .into_iter()
    .filter(|(m, _, _)| !m.is_empty())
    .map(|(mesh, lighting, drape)| Part {
        mesh,
        lighting,
        drape,
    })
    .collect();
    let triangles = parts.iter().map(|p| p.mesh.triangles.len() as u64).sum();
    let terrain_triangles = parts
        .iter()
        .filter(|p| p.lighting == Lighting::Unlit)
        .map(|p| p.mesh.triangles.len() as u64)
        .sum();
    if parts.is_empty() {
        let built = Built {
            frame,
            bounds: None,
            uri: None,
            terrain_triangles,
            triangles,
            bytes: 0,
            error,
        };
        return Ok((built, None));
    }
    let bytes = write_glb(&parts, frame.origin)?;
    let name = format!("{tx}_{ty}.glb");
    let path = dir.join(&name);
    let mut f = AtomicFile::create(&path)?;
    f.writer()
        .write_all(&bytes)
        .map_err(|e| Error::io(&path, e))?;
    let bounds = parts
        .iter()
        .filter_map(|p| p.mesh.bounds())
        .reduce(|a, b| (min3(a.0, b.0), max3(a.1, b.1)))
        .map(|(lo, hi)| {
            let o = frame.origin;
            (
                [0, 1, 2].map(|k| lo[k] - o[k]),
                [0, 1, 2].map(|k| hi[k] - o[k]),
            )
        });
    let built = Built {
        frame,
        bounds,
        uri: Some(format!("tiles/{level}/{name}")),
        terrain_triangles,
        triangles,
        bytes: bytes.len() as u64,
        error,
    };
    Ok((built, Some(f.stage()?)))
}

/// Heights at the points `rows × cols` (grid indices), row-major.
fn read_points(src: &dyn RowSource<f32>, rows: &[usize], cols: &[usize]) -> Result<Vec<f32>> {
    let w = src.grid().width;
    let mut out = Vec::with_capacity(rows.len() * cols.len());
    let contiguous = rows.windows(2).all(|p| p[1] == p[0] + 1);
    if contiguous {
        let band = src.read_rows(rows[0], rows.len())?;
        for r in 0..rows.len() {
            out.extend(cols.iter().map(|&c| band[r * w + c]));
        }
    } else {
        for &r in rows {
            let row = src.read_rows(r, 1)?;
            out.extend(cols.iter().map(|&c| row[c]));
        }
    }
    Ok(out)
}

/// A triangle in level-0 cell coordinates (column, row as numbers; whole numbers, so the
/// orientation and inside tests are exact) with its vertices' heights.
type CellTriangle = [[f64; 3]; 3];

/// The TIN as a mesh in world coordinates with the photo draped over it, and its triangles in
/// cell coordinates for measuring. The image has a texel per point of the window: the photo at
/// the point (stride 1) or its mean over the `stride × stride` cells around it; each vertex
/// samples its own point's texel, and its colour is that texel. A triangle that the grid's
/// uneven last step would turn over is dropped (its points then count as uncovered).
fn terrain_mesh(
    grid: &Grid,
    tin: &Tin,
    rows: &[usize],
    cols: &[usize],
    z: &[f32],
    photo: &dyn RowSource<[u8; 4]>,
    stride: usize,
) -> Result<(Mesh, Drape, Vec<CellTriangle>)> {
    let (w, h) = (cols.len(), rows.len());
    let texels = window_image(photo, rows, cols, stride)?;
    let mut mesh = Mesh::default();
    let mut uv = Vec::with_capacity(tin.vertices.len());
    let mut cell = Vec::with_capacity(tin.vertices.len());
    for &[i, j] in &tin.vertices {
        let (c, r) = (cols[i as usize], rows[j as usize]);
        let height = z[j as usize * w + i as usize] as f64;
        let (x, y) = grid.cell_centre(c, r);
        mesh.positions.push([x, y, height]);
        mesh.colours.push(texels[j as usize * w + i as usize]);
        // The texel's centre.
        uv.push([
            ((i as f64 + 0.5) / w as f64) as f32,
            ((j as f64 + 0.5) / h as f64) as f32,
        ]);
        cell.push([c as f64, r as f64, height]);
    }
    let mut cell_tris = Vec::with_capacity(tin.triangles.len());
    for &t in &tin.triangles {
        let p = t.map(|i| cell[i as usize]);
        // Counter-clockwise from above in world terms is clockwise in (column, row).
        if orient(p) >= 0.0 {
            continue;
        }
        mesh.triangles.push(t);
        cell_tris.push(p);
    }
    let drape = Drape {
        width: w as u32,
        height: h as u32,
        texels,
        uv,
    };
    Ok((mesh, drape, cell_tris))
}

/// Twice the signed area of a triangle in (column, row): negative when clockwise there.
fn orient([a, b, c]: CellTriangle) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// The photo at every point `rows × cols` of a window, row-major: the cell's at stride 1, the
/// mean of the opaque cells within half a stride around it above (grey where none is opaque).
fn window_image(
    photo: &dyn RowSource<[u8; 4]>,
    rows: &[usize],
    cols: &[usize],
    stride: usize,
) -> Result<Vec<[u8; 3]>> {
    let (w, h) = (photo.grid().width, photo.grid().height);
    let half = stride / 2;
    let mut out = Vec::with_capacity(rows.len() * cols.len());
    for &r in rows {
        let (r0, r1) = (r.saturating_sub(half), (r + half + 1).min(h));
        let block = photo.read_rows(r0, r1 - r0)?;
        for &c in cols {
            let (c0, c1) = (c.saturating_sub(half), (c + half + 1).min(w));
            out.push(mean_opaque(
                (0..r1 - r0).flat_map(|rr| &block[rr * w + c0..rr * w + c1]),
            ));
        }
    }
    Ok(out)
}

/// The vertical difference between `tris` and the level-0 heights at the valid points in
/// `cols × rows`, streamed in bands of [`BAND_ROWS`]. A point on an edge shared by two
/// triangles counts once.
fn measure(
    elevation: &dyn RowSource<f32>,
    tris: &[CellTriangle],
    cols: std::ops::Range<usize>,
    rows: std::ops::Range<usize>,
) -> Result<Measured> {
    let w = elevation.grid().width;
    let mut m = Measured::default();
    let mut band0 = rows.start;
    while band0 < rows.end {
        let band1 = (band0 + BAND_ROWS).min(rows.end);
        let z = elevation.read_rows(band0, band1 - band0)?;
        let bw = cols.len();
        let mut seen = vec![false; bw * (band1 - band0)];
        for t in tris {
            let lo = |k: usize| t.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            let hi = |k: usize| t.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
            let (r0, r1) = ((lo(1) as usize).max(band0), (hi(1) as usize + 1).min(band1));
            let (c0, c1) = (
                (lo(0) as usize).max(cols.start),
                (hi(0) as usize + 1).min(cols.end),
            );
            let area = orient(*t);
            for r in r0..r1 {
                for c in c0..c1 {
                    let k = (r - band0) * bw + (c - cols.start);
                    if seen[k] {
                        continue;
                    }
                    let p = [c as f64, r as f64, 0.0];
                    let [a, b, d] = *t;
                    let wa = orient([p, b, d]) / area;
                    let wb = orient([a, p, d]) / area;
                    let wd = orient([a, b, p]) / area;
                    if wa < 0.0 || wb < 0.0 || wd < 0.0 {
                        continue;
                    }
                    seen[k] = true;
                    let h = z[(r - band0) * w + c];
                    if !h.is_finite() {
                        continue;
                    }
                    let e = (wa * a[2] + wb * b[2] + wd * d[2] - h as f64).abs();
                    m.max = m.max.max(e);
                    m.sum_sq += e * e;
                    m.points += 1;
                }
            }
        }
        for r in band0..band1 {
            for c in cols.clone() {
                if !seen[(r - band0) * bw + (c - cols.start)] && z[(r - band0) * w + c].is_finite()
                {
                    m.uncovered += 1;
                }
            }
        }
        band0 = band1;
    }
    Ok(m)
}
