//! Placing a voxel object in a database (`dbms place`).
//!
//! # Rules
//! * The object's **anchor** (centre of the bottom face of its grid, [`VoxelObject::anchor`])
//!   goes to world `(x, y, z)`; the object turns about the vertical through the anchor by
//!   `heading` degrees clockwise seen from above (0 = the object's +y stays north), and is
//!   sized about the anchor by `scale` (> 0; the voxel edge and every voxel's offset times it).
//! * `z` is the given absolute height, or else the terrain height at `(x, y)`: bilinear between
//!   the four nearest elevation cell centres (clamped at the grid edge); nodata there is an error.
//! * A given `z` must lie within [`Z_MARGIN_M`] of the terrain's range (its lowest and highest
//!   valid cell): room for any structure on a roof or a bridge, or sunk in a pit, while a unit
//!   slip or a missing decimal point (`1e8`) is refused before anything is written. Heights are
//!   `f32` in the tile set; far from the terrain they would lose the voxels' resolution.
//! * The object file is copied into `DB/objects/` under a content-addressed name
//!   (`<stem>-<first 12 hex of its SHA-256>.dvox`), so placing one tree many times stores it once,
//!   and the placement is appended to the manifest's `objects` with a `place` stage record.

use super::format;
use super::object::VoxelObject;
use crate::db::{sha256_file, Change, Database, PlacedObject, Stage};
use crate::error::{Error, Result};
use crate::num::splitmix64;
use crate::raster::{Elevation, RowSource};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How far (metres) a placement's given height may lie below the lowest or above the highest
/// terrain of the database: a kilometre, more than any structure is tall.
pub const Z_MARGIN_M: f64 = 1000.0;

/// Terrain height (metres) at world `(x, y)`, bilinear on cell centres; `None` outside the grid
/// or where a contributing cell is nodata.
pub fn ground_height(dem: &Elevation, x: f64, y: f64) -> Option<f64> {
    let g = &dem.grid;
    g.cell_at(x, y)?;
    let (cx, cy) = g.world_to_centre_space(x, y);
    let (w, h) = (g.width as f64, g.height as f64);
    let (cx, cy) = (cx.clamp(0.0, w - 1.0), cy.clamp(0.0, h - 1.0));
    let (c0, r0) = (cx.floor() as usize, cy.floor() as usize);
    let (c1, r1) = ((c0 + 1).min(g.width - 1), (r0 + 1).min(g.height - 1));
    let (fx, fy) = (cx - c0 as f64, cy - r0 as f64);
    let v = |c: usize, r: usize| *dem.get(c, r) as f64;
    let z = (v(c0, r0) * (1.0 - fx) + v(c1, r0) * fx) * (1.0 - fy)
        + (v(c0, r1) * (1.0 - fx) + v(c1, r1) * fx) * fy;
    (!z.is_nan()).then_some(z)
}

/// One object to place: its file, where its anchor goes (`x`, `y` in the database CRS; `z`
/// absolute metres, or the ground's when `None`), its heading (degrees clockwise from north)
/// and its size factor about the anchor.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// The voxel object file (.dvox).
    pub object: PathBuf,
    /// World x of the anchor.
    pub x: f64,
    /// World y of the anchor.
    pub y: f64,
    /// Absolute height of the anchor, metres; `None`: the terrain's.
    pub z: Option<f64>,
    /// Degrees clockwise from north.
    pub heading_deg: f64,
    /// Size factor about the anchor, > 0 (1: the object as made).
    pub scale: f64,
}

/// Place every one of `placements` in the database in `dir` in one change under its lock: all
/// or none. Each distinct object file is read (and so checked) and stored once, the terrain is
/// read once, and each placement gets a new id ([`crate::manifest::Manifest::new_placement_id`]). Errors name
/// the placement by its position.
pub fn place_all(
    dir: &Path,
    wait: std::time::Duration,
    placements: &[Placement],
) -> Result<Vec<PlacedObject>> {
    for p in placements {
        check_finite(p.x, p.y, p.z, p.heading_deg)?;
        check_scale(p.scale)?;
    }
    let objects: Vec<&Path> = placements.iter().map(|p| p.object.as_path()).collect();
    let mut change = Database::begin(dir, wait, &objects)?;
    require_projected(&change.db)?;
    // Everything is checked before anything is written: the objects, then every position.
    let mut objects: BTreeMap<&Path, (String, usize)> = BTreeMap::new();
    for p in placements {
        if !objects.contains_key(p.object.as_path()) {
            let (obj, _): (VoxelObject, _) = format::read(&p.object)?;
            let most = largest_scale(&change.db, &obj.grid);
            if let Some(k) = placements
                .iter()
                .filter(|q| q.object == p.object)
                .find(|q| q.scale > most)
            {
                return Err(too_large(&change.db, &obj.grid, k.scale, most));
            }
            objects.insert(&p.object, (sha256_file(&p.object)?, obj.len()));
        }
    }
    let db = &change.db;
    let ground = match placements.iter().any(|p| p.z.is_none()) {
        true => Some(db.read_elevation()?),
        false => None,
    };
    let heights = placements
        .iter()
        .map(|p| anchor_height(db, ground.as_ref(), p.x, p.y, p.z))
        .collect::<Result<Vec<f64>>>()?;
    let mut files: BTreeMap<&Path, String> = BTreeMap::new();
    for (path, (sha256, _)) in &objects {
        files.insert(path, store_object(&mut change, path, sha256)?);
    }
    let db = &mut change.db;
    let mut placed = Vec::with_capacity(placements.len());
    for (p, z) in placements.iter().zip(heights) {
        let object = PlacedObject {
            id: db.manifest.new_placement_id(),
            file: files[p.object.as_path()].clone(),
            sha256: objects[p.object.as_path()].0.clone(),
            x: p.x,
            y: p.y,
            z,
            heading_deg: p.heading_deg.rem_euclid(360.0),
            scale: p.scale,
        };
        db.manifest.objects.push(object.clone());
        placed.push(object);
    }
    let params = match placed.as_slice() {
        [one] => serde_json::json!({
            "id": one.id, "object": one.file, "x": one.x, "y": one.y, "z": one.z,
            "heading_deg": one.heading_deg, "scale": one.scale,
            "voxels": objects[placements[0].object.as_path()].1,
        }),
        many => serde_json::json!({
            "placements": many.len(),
            "objects": objects.len(),
            "ids": [many.first().map(|p| p.id), many.last().map(|p| p.id)],
        }),
    };
    db.record_stage(Stage::now("place", params));
    change.commit()?;
    Ok(placed)
}

/// Remove placement `id` from the database in `dir` (its object file stays, as other
/// placements may use it); returns what was removed.
pub fn remove(dir: &Path, wait: std::time::Duration, id: u64) -> Result<PlacedObject> {
    let mut change = Database::begin(dir, wait, &[])?;
    let db = &mut change.db;
    let k = position_of(db, id)?;
    let removed = db.manifest.objects.remove(k);
    db.record_stage(Stage::now("place", serde_json::json!({ "removed": id })));
    change.commit()?;
    Ok(removed)
}

/// Move placement `id` of the database in `dir` to `(x, y)` and height `z` (absolute metres, or
/// the ground's when `None`), keeping its id, object, heading and scale (or `heading_deg` and
/// `scale` when given); returns it as moved.
pub fn move_to(
    dir: &Path,
    wait: std::time::Duration,
    id: u64,
    (x, y, z): (f64, f64, Option<f64>),
    heading_deg: Option<f64>,
    scale: Option<f64>,
) -> Result<PlacedObject> {
    check_finite(x, y, z, heading_deg.unwrap_or(0.0))?;
    scale.map(check_scale).transpose()?;
    let mut change = Database::begin(dir, wait, &[])?;
    let db = &mut change.db;
    let k = position_of(db, id)?;
    if let Some(scale) = scale {
        let (obj, _): (VoxelObject, _) = format::read(&db.dir.join(&db.manifest.objects[k].file))?;
        let most = largest_scale(db, &obj.grid);
        if scale > most {
            return Err(too_large(db, &obj.grid, scale, most));
        }
    }
    let ground = match z {
        Some(_) => None,
        None => Some(db.read_elevation()?),
    };
    let z = anchor_height(db, ground.as_ref(), x, y, z)?;
    let o = &mut db.manifest.objects[k];
    (o.x, o.y, o.z) = (x, y, z);
    if let Some(h) = heading_deg {
        o.heading_deg = h.rem_euclid(360.0);
    }
    if let Some(k) = scale {
        o.scale = k;
    }
    let moved = o.clone();
    db.record_stage(Stage::now(
        "place",
        serde_json::json!({
            "moved": id, "x": x, "y": y, "z": z,
            "heading_deg": moved.heading_deg, "scale": moved.scale,
        }),
    ));
    change.commit()?;
    Ok(moved)
}

/// Where placement `id` is in the manifest's list, or an error naming the ids there are.
fn position_of(db: &Database, id: u64) -> Result<usize> {
    db.manifest
        .objects
        .iter()
        .position(|o| o.id == id)
        .ok_or_else(|| {
            let n = db.manifest.objects.len();
            Error::file(&db.dir, format!("has no placement {id} ({n} placements)"))
                .fix("dbms info DB --json lists the placements with their ids")
        })
}

fn check_finite(x: f64, y: f64, z: Option<f64>, heading_deg: f64) -> Result<()> {
    if x.is_finite() && y.is_finite() && z.is_none_or(f64::is_finite) && heading_deg.is_finite() {
        Ok(())
    } else {
        Err(Error::msg("--at and --heading must be finite numbers")
            .fix("e.g. --at 500120.5,5000340,0 --heading 30"))
    }
}

/// Whether `scale` is a size factor: finite and above 0.
pub fn valid_scale(scale: f64) -> bool {
    scale.is_finite() && scale > 0.0
}

/// Whether `[lo, hi]` is a range of size factors: both valid, `lo <= hi`.
pub fn valid_scale_range(lo: f64, hi: f64) -> bool {
    valid_scale(lo) && valid_scale(hi) && lo <= hi
}

/// An error unless `scale` is a size factor ([`valid_scale`]).
fn check_scale(scale: f64) -> Result<()> {
    match valid_scale(scale) {
        true => Ok(()),
        false => Err(
            Error::msg(format!("--scale {scale}: must be a number above 0"))
                .fix("1 places the object as made, 2 twice as large"),
        ),
    }
}

/// The most cells of the database a placed object's bounding box may fill, columns times the
/// cell heights it stands (its width, depth and height each in cells): 2^28. The pyramid's time
/// and memory for a placement grow with it, as the cube of the scale. On the 0.25 m cells of
/// the 2048-pixel sample (4096² cells), with a 5 m wide, 8 m tall tree placed at scale 1
/// (1.3e4 cells) the pyramid took 10 s and 79 MB; at scale 10 (1.3e7 cells) 10.8 s and 89 MB;
/// at scale 40 (8.2e8) 33 s and 380 MB; at scale 100 (1.3e10) 256 s and 1.5 GB (debug build,
/// 2 cores, shared, 2026-11-29). 2^28 cells (scale 27.6 there) cost a few seconds and about
/// 100 MB more.
pub const MAX_OBJECT_CELLS: f64 = (1u64 << 28) as f64;

/// The largest size factor an object on `grid` may be placed at in `db`: its grid's
/// horizontal diagonal (so at any heading) no wider than the database's narrower side, its
/// height no more than [`Z_MARGIN_M`], and its box no more than [`MAX_OBJECT_CELLS`] of the
/// database's cells. Larger, each of its voxels is repeated over many cells, and the pyramid's
/// time and memory with them.
pub fn largest_scale(db: &Database, grid: &super::grid::VoxelGrid) -> f64 {
    largest_scale_in(database_width(db), database_cell(db), grid)
}

/// [`largest_scale`] in a database `width` metres wide (its narrower side) of `cell` metre
/// cells.
fn largest_scale_in(width: f64, cell: f64, grid: &super::grid::VoxelGrid) -> f64 {
    let (across, tall) = object_size(grid);
    let fills = (MAX_OBJECT_CELLS / cells_at_scale_1(cell, grid)).cbrt();
    (width / across).min(Z_MARGIN_M / tall).min(fills)
}

/// An object's horizontal diagonal and height, metres, at scale 1.
fn object_size(grid: &super::grid::VoxelGrid) -> (f64, f64) {
    let [nx, ny, nz] = grid.dims.map(f64::from);
    (nx.hypot(ny) * grid.voxel_size, nz * grid.voxel_size)
}

/// The cells of `cell` metres the box of an object on `grid` fills at scale 1 (width, depth
/// and height each in cells; at scale k, k³ times as many).
fn cells_at_scale_1(cell: f64, grid: &super::grid::VoxelGrid) -> f64 {
    grid.dims
        .map(|n| f64::from(n) * grid.voxel_size / cell)
        .iter()
        .product()
}

/// The smaller side of `db`'s cells, metres.
fn database_cell(db: &Database) -> f64 {
    let (cx, cy) = db.grid().cell_size();
    cx.abs().min(cy.abs())
}

/// The narrower side of `db`'s extent, metres.
fn database_width(db: &Database) -> f64 {
    let b = db.grid().bounds();
    (b.max_x - b.min_x).min(b.max_y - b.min_y)
}

/// The error for an object on `grid` placed at `scale` in `db`, above `most` ([`largest_scale`]).
fn too_large(db: &Database, grid: &super::grid::VoxelGrid, scale: f64, most: f64) -> Error {
    let (across, tall) = object_size(grid);
    let cells = cells_at_scale_1(database_cell(db), grid) * scale.powi(3);
    Error::file(
        &db.dir,
        format!(
            "--scale {scale}: the object would be {:.0} m across and {:.0} m tall, filling {cells:.1e} cells, more than a placement may ({:.0} m across, {Z_MARGIN_M} m tall, {MAX_OBJECT_CELLS:.1e} cells: the pyramid's time and memory grow with them)",
            across * scale,
            tall * scale,
            database_width(db)
        ),
    )
    .fix(format!("give a scale of at most {most:.3}"))
}

fn require_projected(db: &Database) -> Result<()> {
    if db.grid().crs.geographic {
        return Err(Error::file(
            &db.dir,
            "the database is in geographic coordinates (degrees) but voxel objects are in metres",
        )
        .fix("ingest onto a projected CRS (e.g. UTM)"));
    }
    Ok(())
}

/// The anchor's height at `(x, y)` inside the database: `z` when given and near the terrain,
/// else the terrain's (`ground`, read by the caller whenever `z` is `None`).
fn anchor_height(
    db: &Database,
    ground: Option<&Elevation>,
    x: f64,
    y: f64,
    z: Option<f64>,
) -> Result<f64> {
    require_inside(db, x, y)?;
    match (z, ground) {
        (Some(z), _) => require_near_terrain(db, z),
        (None, Some(dem)) => ground_height(dem, x, y).ok_or_else(|| {
            Error::file(&db.dir, format!("no terrain height at {x},{y} (nodata)"))
                .fix("give the height as --at X,Y,Z")
        }),
        (None, None) => unreachable!("the terrain is read when a height is missing"),
    }
}

fn require_inside(db: &Database, x: f64, y: f64) -> Result<()> {
    if db.grid().cell_at(x, y).is_none() {
        let b = db.grid().bounds();
        return Err(Error::msg(format!(
            "--at {x},{y} is outside the database extent [{}, {}, {}, {}]",
            b.min_x, b.min_y, b.max_x, b.max_y
        ))
        .fix("give a position inside the database"));
    }
    Ok(())
}

/// The name an object was placed under: its stored file's name (`objects/<stem>-<12 hex>.dvox`,
/// `store_object`) without the directory, the hash and the extension. `"tree"` for
/// `objects/tree-514b4940741c.dvox`; a name not of that form comes back as its file stem.
pub fn placed_name(file: &str) -> &str {
    let name = file.rsplit('/').next().unwrap_or(file);
    let stem = name.strip_suffix(".dvox").unwrap_or(name);
    match stem.rsplit_once('-') {
        Some((s, hash)) if hash.len() == 12 && hash.bytes().all(|b| b.is_ascii_hexdigit()) => s,
        _ => stem,
    }
}

/// Store the object at `path` (SHA-256 `sha256`) in the database under its content-addressed
/// name, once (placing one tree many times stores it once); returns that name.
fn store_object(change: &mut Change, path: &Path, sha256: &str) -> Result<String> {
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("object");
    let file = format!("objects/{stem}-{}.dvox", &sha256[..12]);
    let dest = change.db.dir.join(&file);
    if !dest.exists() {
        let dir = change.db.dir.join("objects");
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let bytes = crate::io::read_bytes(path)?;
        crate::io::atomic::write_bytes_atomic(&dest, &bytes)?;
        change.wrote(&file);
    }
    Ok(file)
}

/// Seeded variation of the placements read from a point layer ([`read_points`]), for the
/// features that do not set the property themselves. A feature's draws depend only on the
/// seed and its position in the file ([`uniform`]): same seed and file, same placements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Variation {
    /// Seed of the per-feature random numbers.
    pub seed: u64,
    /// Features without a `heading` get one uniform in [0, 360) degrees (else 0).
    pub random_heading: bool,
    /// Features without a `scale` get one uniform in `[min, max]` (else 1).
    pub scale_range: Option<(f64, f64)>,
}

impl Variation {
    /// No variation: heading 0 and scale 1 where a feature gives none.
    pub const NONE: Variation = Variation {
        seed: 0,
        random_heading: false,
        scale_range: None,
    };

    /// An error unless the scale range is `0 < min <= max`, both finite.
    pub fn check(&self) -> Result<()> {
        match self.scale_range {
            Some((lo, hi)) if !valid_scale_range(lo, hi) => Err(Error::msg(format!(
                "--scale-range {lo},{hi}: must be two positive numbers, the smaller first"
            ))
            .fix("e.g. --scale-range 0.8,1.25")),
            _ => Ok(()),
        }
    }

    /// The heading (degrees) and scale of feature `index` when it gives neither.
    fn draw(&self, index: u64) -> (f64, f64) {
        let heading = match self.random_heading {
            true => 360.0 * uniform(self.seed, index, 0),
            false => 0.0,
        };
        let scale = match self.scale_range {
            Some((lo, hi)) => lo + (hi - lo) * uniform(self.seed, index, 1),
            None => 1.0,
        };
        (heading, scale)
    }
}

/// A number uniform in [0, 1) for draw `draw` of feature `index` under `seed`:
/// [`splitmix64`] chained over the three, top 53 bits. A pure function, so a feature's draws
/// do not depend on the others or the order they are made in.
pub fn uniform(seed: u64, index: u64, draw: u64) -> f64 {
    let z = splitmix64(splitmix64(splitmix64(seed) ^ index) ^ draw);
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// The placements of a GeoJSON FeatureCollection of Points (`[x, y]` or `[x, y, z]` in the
/// database CRS). Per feature: its object is its `object` property (a path relative to the
/// GeoJSON file) or `default_object`; its `heading` (degrees) and `scale` (> 0) properties, or
/// else what `vary` draws for it.
pub fn read_points(
    path: &Path,
    default_object: Option<&Path>,
    vary: &Variation,
) -> Result<Vec<Placement>> {
    vary.check()?;
    let fix = "give a FeatureCollection of Point features with optional object, heading and scale properties";
    let features = crate::geojson::read_features(path, fix)?;
    let base = path.parent().unwrap_or(Path::new(""));
    features
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let bad = |what: &str| Error::file(path, format!("feature {i}: {what}")).fix(fix);
            let coords = f
                .pointer("/geometry/coordinates")
                .and_then(|c| c.as_array())
                .filter(|_| f.pointer("/geometry/type").and_then(|t| t.as_str()) == Some("Point"))
                .ok_or_else(|| bad("not a Point"))?;
            let v: Vec<f64> = coords.iter().filter_map(|c| c.as_f64()).collect();
            if !(v.len() == 2 || v.len() == 3) || v.len() != coords.len() {
                return Err(bad("coordinates are not [x, y] or [x, y, z] numbers"));
            }
            let object = match f.pointer("/properties/object") {
                Some(o) => base.join(o.as_str().ok_or_else(|| bad("object is not a path"))?),
                None => default_object
                    .ok_or_else(|| bad("no object property, and no --object given"))?
                    .to_path_buf(),
            };
            let number = |name: &str| match f.pointer(&format!("/properties/{name}")) {
                Some(h) => h
                    .as_f64()
                    .map(Some)
                    .ok_or_else(|| bad(&format!("{name} is not a number"))),
                None => Ok(None),
            };
            let (heading, scale) = vary.draw(i as u64);
            let scale = number("scale")?.unwrap_or(scale);
            if !valid_scale(scale) {
                return Err(bad(&format!("scale {scale} is not a positive number")));
            }
            Ok(Placement {
                object,
                x: v[0],
                y: v[1],
                z: v.get(2).copied(),
                heading_deg: number("heading")?.unwrap_or(heading),
                scale,
            })
        })
        .collect()
}

/// `z` (absolute metres), when within [`Z_MARGIN_M`] of the terrain's range in `db`.
fn require_near_terrain(db: &Database, z: f64) -> Result<f64> {
    let rows = db.elevation_rows()?;
    let (w, h) = (db.grid().width, db.grid().height);
    let band = ((1 << 22) / w.max(1)).max(1);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for r0 in (0..h).step_by(band) {
        for &v in rows.read_rows(r0, band.min(h - r0))?.iter() {
            if !v.is_nan() {
                lo = lo.min(v as f64);
                hi = hi.max(v as f64);
            }
        }
    }
    if lo - Z_MARGIN_M <= z && z <= hi + Z_MARGIN_M {
        return Ok(z);
    }
    Err(Error::msg(format!(
        "--at height {z} m is more than {Z_MARGIN_M} m outside the terrain's range, {lo} to {hi} m"
    ))
    .fix("give Z in metres on the elevation layer's datum, or leave it out to stand the object on the ground"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;

    /// Issue 40, defect 13: a 5 m wide, 8 m tall tree at scale 100 on the 2048-pixel sample's
    /// 0.25 m cells (1024 m across) fitted the database, yet made the pyramid take 256 s and
    /// 1.5 GB: the bound counts the cells its box fills too.
    #[test]
    fn the_largest_scale_bounds_the_cells_an_object_fills() {
        let tree = super::super::grid::VoxelGrid::new([0.0; 3], 0.25, [20, 20, 32]).unwrap();
        let most = largest_scale_in(1024.0, 0.25, &tree);
        // (2^28 / (20 · 20 · 32))^(1/3) = 27.6: under the width's 1024 / 7.07 = 145 and the
        // height's 1000 / 8 = 125.
        assert!((most - 27.6).abs() < 0.05, "{most}");
        assert!(cells_at_scale_1(0.25, &tree) * most.powi(3) <= MAX_OBJECT_CELLS * 1.000001);
        // On a small database the width binds, and on coarse cells the height.
        assert!(
            (largest_scale_in(160.0, 0.25, &tree) - 160.0 / 20f64.hypot(20.0) / 0.25).abs() < 1e-9
        );
        assert!((largest_scale_in(1e5, 2.0, &tree) - 1000.0 / 8.0).abs() < 1e-9);
    }

    #[test]
    fn ground_height_is_bilinear_between_centres() {
        // 3×2 cells of 10 m; values rise 1 m per cell east and 10 m per cell south.
        let g = Grid::north_up(1000.0, 2000.0, 10.0, 3, 2, Crs::epsg(32632));
        let dem = Elevation::new(g, vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0]);
        assert_eq!(ground_height(&dem, 1005.0, 1995.0), Some(0.0));
        assert!((ground_height(&dem, 1010.0, 1990.0).unwrap() - 5.5).abs() < 1e-9);
        assert_eq!(
            ground_height(&dem, 1001.0, 1999.0),
            Some(0.0),
            "clamped at the edge"
        );
        assert_eq!(ground_height(&dem, 999.0, 1995.0), None);
        let mut holes = dem.clone();
        holes.data[1] = f32::NAN;
        assert_eq!(ground_height(&holes, 1010.0, 1990.0), None);
    }

    #[test]
    fn uniform_draws_are_pure_in_range_and_even() {
        let n = 100_000;
        let draws: Vec<f64> = (0..n).map(|i| uniform(7, i, 0)).collect();
        assert!(draws.iter().all(|u| (0.0..1.0).contains(u)));
        let mean = draws.iter().sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
        // Ten bins each within 5 % of n / 10.
        let mut bins = [0usize; 10];
        for u in &draws {
            bins[(u * 10.0) as usize] += 1;
        }
        assert!(
            bins.iter().all(|&b| b.abs_diff(n as usize / 10) < 500),
            "{bins:?}"
        );
        assert_eq!(uniform(7, 3, 0), draws[3]);
        assert_ne!(uniform(7, 3, 1), draws[3], "draws of one feature differ");
        assert_ne!(uniform(8, 3, 0), draws[3], "seeds differ");
    }

    fn points_file(dir: &Path, features: &[serde_json::Value]) -> PathBuf {
        let path = dir.join("points.geojson");
        let fc = serde_json::json!({"type": "FeatureCollection", "features": features});
        std::fs::write(&path, fc.to_string()).unwrap();
        path
    }

    fn point(x: f64, properties: serde_json::Value) -> serde_json::Value {
        serde_json::json!({"type": "Feature", "geometry": {"type": "Point", "coordinates": [x, 0.0]}, "properties": properties})
    }

    #[test]
    fn point_layers_vary_by_seed_and_features_keep_their_own_values() {
        let dir = tempfile::tempdir().unwrap();
        let mut features: Vec<_> = (0..500)
            .map(|i| point(i as f64, serde_json::json!({})))
            .collect();
        features[10] = point(10.0, serde_json::json!({"heading": 33.0, "scale": 3.0}));
        let path = points_file(dir.path(), &features);
        let tree = Path::new("tree.dvox");
        let vary = |seed| Variation {
            seed,
            random_heading: true,
            scale_range: Some((0.5, 2.0)),
        };
        let a = read_points(&path, Some(tree), &vary(7)).unwrap();
        assert_eq!(
            a,
            read_points(&path, Some(tree), &vary(7)).unwrap(),
            "same seed, same placements"
        );
        let b = read_points(&path, Some(tree), &vary(8)).unwrap();
        assert!(
            a.iter().zip(&b).filter(|(a, b)| a != b).count() > 490,
            "another seed, others"
        );
        assert_eq!(
            (a[10].heading_deg, a[10].scale),
            (33.0, 3.0),
            "the feature's own values win"
        );
        assert!(a.iter().all(|p| (0.0..360.0).contains(&p.heading_deg)));
        let scales: Vec<f64> = a
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 10)
            .map(|(_, p)| p.scale)
            .collect();
        assert!(scales.iter().all(|k| (0.5..=2.0).contains(k)));
        let (lo, hi) = scales
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), &k| (lo.min(k), hi.max(k)));
        assert!(
            lo < 0.55 && hi > 1.95,
            "the whole range is drawn: {lo}..{hi}"
        );
        let none = read_points(&path, Some(tree), &Variation::NONE).unwrap();
        assert!(none
            .iter()
            .enumerate()
            .all(|(i, p)| i == 10 || (p.heading_deg, p.scale) == (0.0, 1.0)));
    }

    #[test]
    fn placed_names_drop_the_directory_hash_and_extension() {
        assert_eq!(placed_name("objects/tree-514b4940741c.dvox"), "tree");
        assert_eq!(
            placed_name("objects/oak-tree-2-9e841e821ca5.dvox"),
            "oak-tree-2"
        );
        // Not the stored form: the stem as it is.
        assert_eq!(placed_name("objects/tank-v2.dvox"), "tank-v2");
        assert_eq!(placed_name("tank.dvox"), "tank");
    }

    #[test]
    fn bad_scales_are_one_line_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = points_file(
            dir.path(),
            &[point(0.0, serde_json::json!({"scale": -1.0}))],
        );
        let e = read_points(&path, Some(Path::new("t.dvox")), &Variation::NONE)
            .unwrap_err()
            .to_string();
        assert!(e.contains("feature 0") && e.contains("scale -1"), "{e}");
        let path = points_file(
            dir.path(),
            &[point(0.0, serde_json::json!({"scale": "big"}))],
        );
        let e = read_points(&path, Some(Path::new("t.dvox")), &Variation::NONE)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scale is not a number"), "{e}");
        for range in [(2.0, 1.0), (0.0, 1.0), (1.0, f64::INFINITY)] {
            let vary = Variation {
                scale_range: Some(range),
                ..Variation::NONE
            };
            let e = read_points(&path, Some(Path::new("t.dvox")), &vary)
                .unwrap_err()
                .to_string();
            assert!(e.contains("--scale-range") && e.lines().count() == 1, "{e}");
        }
        assert!(
            check_scale(0.0).is_err() && check_scale(f64::NAN).is_err() && check_scale(0.5).is_ok()
        );
    }
}
