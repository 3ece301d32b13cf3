//! Exports for ordinary viewers: PLY point clouds and MagicaVoxel `.vox` models.
//!
//! * PLY (binary little-endian): one vertex per solid voxel at its centre in world metres
//!   (`double x, y, z`, so UTM coordinates keep millimetres) with `uchar red, green, blue`,
//!   in storage order.
//! * `.vox` (MagicaVoxel, version 150): chunks `MAIN { SIZE, XYZI, RGBA }`; voxel indices as
//!   they are in the object (x east, y north, z up), at most 256 per axis (larger objects are an
//!   error, never silently cropped). Colours go into the 255-entry palette exactly when the object
//!   has at most 255 distinct colours (sorted, so deterministic); otherwise each colour is
//!   quantised to the nearest level of a fixed 6 × 7 × 6 RGB cube.

use super::format;
use super::object::VoxelObject;
use crate::error::{Error, Result};
use crate::io::atomic::{check_outputs, commit_all, AtomicFile, Staged};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

crate::choice! {
    /// An export format for ordinary tools.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Export {
        /// Binary PLY point cloud of coloured voxel centres, world metres.
        Ply = "ply",
        /// MagicaVoxel `.vox` model.
        Vox = "vox",
    }
}

impl Export {
    /// File extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Export::Ply => "ply",
            Export::Vox => "vox",
        }
    }
}

/// An export [`plan_exports`] planned: its kind and the path it goes to.
pub type PlannedExport = (Export, PathBuf);

/// Where the exports of `kinds` go beside `object_path` (same stem, the export's extension; a
/// kind given twice is one export), after checking the run's outputs, the object and these
/// ([`check_outputs`]): none is a special file or a database's file, none would overwrite
/// another (the object: name it `*.dvox`) or one of the run's `inputs`. Callers plan before any
/// work, check the object fits with [`check_exports`], then write all with
/// [`write_with_exports`].
pub fn plan_exports(
    object_path: &Path,
    kinds: &[Export],
    inputs: &[&Path],
) -> Result<Vec<PlannedExport>> {
    let mut planned: Vec<PlannedExport> = Vec::new();
    for &k in kinds {
        if planned.iter().any(|&(p, _)| p == k) {
            continue;
        }
        let p = object_path.with_extension(k.extension());
        if p == object_path {
            return Err(Error::file(
                object_path,
                format!(
                    "the object file would be overwritten by its {} export",
                    k.extension()
                ),
            )
            .fix("name the object *.dvox"));
        }
        planned.push((k, p));
    }
    let outputs: Vec<&Path> = std::iter::once(object_path)
        .chain(planned.iter().map(|(_, p)| p.as_path()))
        .collect();
    check_outputs(&outputs, inputs)?;
    Ok(planned)
}

/// Check `obj` can be written as every export of `planned`: it fits a `.vox` (at most
/// [`VOX_MAX_DIM`] voxels an axis). Called before writing, so a refused export leaves no output
/// at all.
pub fn check_exports(obj: &VoxelObject, planned: &[PlannedExport]) -> Result<()> {
    for (k, p) in planned {
        if *k == Export::Vox {
            vox_fits(obj).map_err(|e| e.in_file(p))?;
        }
    }
    Ok(())
}

/// Write `obj` to `object_path` (`.dvox`, [`format`](mod@super::format), with `source`) and as each export of
/// `planned`, all or none: every file is written and synced under a temporary name first, then
/// all are renamed into place, the object last — it is what `make` waits for. A run that fails
/// leaves no output and replaces none.
pub fn write_with_exports(
    object_path: &Path,
    obj: &VoxelObject,
    source: &str,
    planned: &[PlannedExport],
) -> Result<()> {
    let object = stage_bytes(object_path, &format::encode(obj, source)?)?;
    let mut staged = planned
        .iter()
        .map(|(k, p)| match k {
            Export::Ply => stage_ply(p, obj),
            Export::Vox => stage_bytes(p, &encode_vox(obj)?),
        })
        .collect::<Result<Vec<Staged>>>()?;
    staged.push(object);
    commit_all(staged)
}

/// `bytes` written to a temporary file for `path`, staged.
fn stage_bytes(path: &Path, bytes: &[u8]) -> Result<Staged> {
    let mut out = AtomicFile::create(path)?;
    out.writer()
        .write_all(bytes)
        .map_err(|e| Error::io(path, e))?;
    out.stage()
}

/// Largest number of voxels per axis a MagicaVoxel model holds.
pub const VOX_MAX_DIM: u32 = 256;

/// Write `obj` as a binary PLY of coloured voxel centres (world metres).
pub fn write_ply(path: &Path, obj: &VoxelObject) -> Result<()> {
    stage_ply(path, obj)?.commit()
}

/// [`write_ply`], staged.
fn stage_ply(path: &Path, obj: &VoxelObject) -> Result<Staged> {
    let mut out = AtomicFile::create(path)?;
    let w = out.writer();
    let io = |e| Error::io(path, e);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment dbms voxel object: solid voxel centres, world metres\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        obj.len()
    )
    .map_err(io)?;
    for ([x, y, z], c) in obj.voxels() {
        for v in obj.grid.centre(x, y, z) {
            w.write_all(&v.to_le_bytes()).map_err(io)?;
        }
        w.write_all(&c).map_err(io)?;
    }
    out.stage()
}

/// Errors when a dimension of `obj` exceeds [`VOX_MAX_DIM`].
fn vox_fits(obj: &VoxelObject) -> Result<()> {
    let d = obj.grid.dims;
    if d.iter().any(|&n| n > VOX_MAX_DIM) {
        return Err(Error::msg(format!(
            "the object is {}×{}×{} voxels but a MagicaVoxel model holds at most {VOX_MAX_DIM} per axis",
            d[0], d[1], d[2]
        ))
        .fix("sculpt with a larger --voxel or smaller --bounds, or use --export ply"));
    }
    Ok(())
}

/// The `.vox` bytes of `obj`; errors when a dimension exceeds [`VOX_MAX_DIM`].
pub fn encode_vox(obj: &VoxelObject) -> Result<Vec<u8>> {
    vox_fits(obj)?;
    let d = obj.grid.dims;
    let (palette, index_of) = palette(obj);
    let chunk = |id: &[u8; 4], content: &[u8], children: &[u8]| {
        let mut c = Vec::with_capacity(12 + content.len() + children.len());
        c.extend_from_slice(id);
        c.extend_from_slice(&(content.len() as u32).to_le_bytes());
        c.extend_from_slice(&(children.len() as u32).to_le_bytes());
        c.extend_from_slice(content);
        c.extend_from_slice(children);
        c
    };
    let size: Vec<u8> = d.iter().flat_map(|&n| n.to_le_bytes()).collect();
    let mut xyzi = (obj.len() as u32).to_le_bytes().to_vec();
    for ([x, y, z], c) in obj.voxels() {
        xyzi.extend_from_slice(&[x as u8, y as u8, z as u8, index_of(c)]);
    }
    let mut rgba = Vec::with_capacity(1024);
    for i in 0..256 {
        let c = palette.get(i).copied().unwrap_or([0, 0, 0]);
        rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
    }
    let children = [
        chunk(b"SIZE", &size, &[]),
        chunk(b"XYZI", &xyzi, &[]),
        chunk(b"RGBA", &rgba, &[]),
    ]
    .concat();
    let mut out = b"VOX ".to_vec();
    out.extend_from_slice(&150u32.to_le_bytes());
    out.extend(chunk(b"MAIN", &[], &children));
    Ok(out)
}

/// Maps a voxel colour to its palette index (1..=255).
type IndexOf<'a> = Box<dyn Fn([u8; 3]) -> u8 + 'a>;

/// Palette entries (entry `k` is colour index `k + 1`) and the index of each colour.
fn palette(obj: &VoxelObject) -> (Vec<[u8; 3]>, IndexOf<'_>) {
    let mut distinct: BTreeMap<[u8; 3], u8> = BTreeMap::new();
    for &c in &obj.colours {
        if distinct.len() > 255 {
            break;
        }
        distinct.insert(c, 0);
    }
    if distinct.len() <= 255 {
        for (k, v) in distinct.values_mut().enumerate() {
            *v = k as u8 + 1;
        }
        let entries = distinct.keys().copied().collect();
        return (entries, Box::new(move |c| distinct[&c]));
    }
    const LEVELS: [u32; 3] = [6, 7, 6];
    let level = |v: u8, n: u32| (v as u32 * (n - 1) + 127) / 255;
    let mut entries = Vec::with_capacity(252);
    for r in 0..LEVELS[0] {
        for g in 0..LEVELS[1] {
            for b in 0..LEVELS[2] {
                let lv = |l: u32, n: u32| (l * 255 / (n - 1)) as u8;
                entries.push([lv(r, LEVELS[0]), lv(g, LEVELS[1]), lv(b, LEVELS[2])]);
            }
        }
    }
    let index = move |c: [u8; 3]| {
        (1 + (level(c[0], LEVELS[0]) * LEVELS[1] + level(c[1], LEVELS[1])) * LEVELS[2]
            + level(c[2], LEVELS[2])) as u8
    };
    (entries, Box::new(index))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::voxel::grid::VoxelGrid;

    /// Parse a .vox file back: (size, voxels (x, y, z, index), palette).
    fn parse_vox(b: &[u8]) -> ([u32; 3], Vec<[u8; 4]>, Vec<[u8; 4]>) {
        assert_eq!(&b[..4], b"VOX ");
        assert_eq!(u32::from_le_bytes(b[4..8].try_into().unwrap()), 150);
        assert_eq!(&b[8..12], b"MAIN");
        let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as usize;
        assert_eq!(u(12), 0);
        assert_eq!(u(16), b.len() - 20, "MAIN's children fill the file");
        let (mut off, mut size, mut vox, mut pal) = (20, [0u32; 3], vec![], vec![]);
        while off < b.len() {
            let (id, n) = (&b[off..off + 4], u(off + 4));
            let c = &b[off + 12..off + 12 + n];
            match id {
                b"SIZE" => {
                    size = [0, 1, 2]
                        .map(|k| u32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap()))
                }
                b"XYZI" => {
                    let count = u32::from_le_bytes(c[..4].try_into().unwrap()) as usize;
                    assert_eq!(n, 4 + 4 * count);
                    vox = c[4..]
                        .chunks_exact(4)
                        .map(|v| [v[0], v[1], v[2], v[3]])
                        .collect();
                }
                b"RGBA" => {
                    pal = c
                        .chunks_exact(4)
                        .map(|v| [v[0], v[1], v[2], v[3]])
                        .collect()
                }
                other => panic!("unexpected chunk {other:?}"),
            }
            off += 12 + n;
        }
        (size, vox, pal)
    }

    #[test]
    fn vox_round_trips_positions_and_exact_palette() {
        let g = VoxelGrid::new([0.0; 3], 1.0, [3, 4, 5]).unwrap();
        let o = VoxelObject::from_fn(g, |p, _| {
            (p[2] < 2.0).then(|| {
                if p[0] < 1.0 {
                    [200, 10, 10]
                } else {
                    [10, 200, 10]
                }
            })
        });
        let (size, vox, pal) = parse_vox(&encode_vox(&o).unwrap());
        assert_eq!(size, [3, 4, 5]);
        assert_eq!(pal.len(), 256);
        assert_eq!(vox.len(), o.len());
        for (v, (xyz, c)) in vox.iter().zip(o.voxels()) {
            assert_eq!([v[0] as u32, v[1] as u32, v[2] as u32], xyz);
            let p = pal[v[3] as usize - 1];
            assert_eq!([p[0], p[1], p[2]], c);
        }
    }

    #[test]
    fn vox_quantises_many_colours_and_rejects_oversize() {
        let g = VoxelGrid::new([0.0; 3], 1.0, [16, 16, 4]).unwrap();
        let o = VoxelObject::from_fn(g, |p, i| {
            Some([(p[0] * 16.0) as u8, (p[1] * 16.0) as u8, (i % 251) as u8])
        });
        let (_, vox, pal) = parse_vox(&encode_vox(&o).unwrap());
        for (v, (_, c)) in vox.iter().zip(o.voxels()) {
            assert!(v[3] >= 1);
            let p = pal[v[3] as usize - 1];
            for k in 0..3 {
                assert!((p[k] as i32 - c[k] as i32).abs() <= 26, "{p:?} vs {c:?}");
            }
        }
        let big = VoxelObject::from_fn(
            VoxelGrid::new([0.0; 3], 1.0, [257, 1, 1]).unwrap(),
            |_, _| Some([1, 1, 1]),
        );
        assert!(encode_vox(&big)
            .unwrap_err()
            .to_string()
            .contains("at most 256 per axis"));
    }

    #[test]
    fn ply_has_one_vertex_per_voxel_at_world_centres() {
        let dir = tempfile::tempdir().unwrap();
        let g = VoxelGrid::new([500_000.0, 5_000_000.0, 10.0], 0.5, [2, 2, 2]).unwrap();
        let o = VoxelObject::from_fn(g, |p, _| (p[0] < 500_000.5).then_some([1, 2, 3]));
        let p = dir.path().join("o.ply");
        write_ply(&p, &o).unwrap();
        let b = std::fs::read(&p).unwrap();
        let end = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        assert!(std::str::from_utf8(&b[..end])
            .unwrap()
            .contains("element vertex 4\n"));
        assert_eq!(b.len() - end, 4 * 27);
        let x = f64::from_le_bytes(b[end..end + 8].try_into().unwrap());
        let y = f64::from_le_bytes(b[end + 8..end + 16].try_into().unwrap());
        assert_eq!((x, y), (500_000.25, 5_000_000.25));
        assert_eq!(&b[end + 24..end + 27], &[1, 2, 3]);
    }
}
