//! Polygon export: the database as triangle meshes, for polygon image generators and 3-D
//! viewers (`dbms export mesh`).
//!
//! The same database that the ray caster reads as max-Z tiles is written as triangles:
//! terrain as a triangulated irregular network simplified to a stated vertical error
//! ([`tin`]), buildings as prisms, placed voxel objects as merged faces, in glTF 2.0 binary
//! files ([`gltf`]) under a 3D Tiles 1.1 tileset.
//!
//! Invariant of every [`Mesh`]: one colour per position, every index below the number of
//! positions, triangles counter-clockwise seen from their outer side (from above for terrain
//! and roofs, from outside for walls and objects).

pub mod creases;
pub mod export;
pub mod gltf;
pub mod prisms;
pub mod tileset;
pub mod tin;
pub mod voxels;

/// A triangle mesh in world coordinates with one colour per vertex.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions: world x (east), y (north), z (up), metres in the database's CRS.
    pub positions: Vec<[f64; 3]>,
    /// Vertex colours, sRGB.
    pub colours: Vec<[u8; 3]>,
    /// Triangles as indices into `positions`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Whether the mesh has no triangle.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Append `other`'s vertices and triangles (its indices shifted past ours).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.colours.extend_from_slice(&other.colours);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
    }

    /// The smallest box holding every position (world metres): `(min, max)`, or `None` for a
    /// mesh without positions.
    pub fn bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1]), lo[2].min(p[2])],
                [hi[0].max(p[0]), hi[1].max(p[1]), hi[2].max(p[2])],
            )
        }))
    }
}

/// How a viewer lights a part's colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lighting {
    /// The colours already hold the light (the orthophoto saw the sun): shown as they are
    /// (glTF `KHR_materials_unlit`).
    Unlit,
    /// The colours are albedo: the viewer shades the faces (walls, roofs, objects).
    Lit,
}

/// A piece of a tile's content: a mesh, how it is lit, and the image draped over it.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// The triangles.
    pub mesh: Mesh,
    /// How a viewer lights them.
    pub lighting: Lighting,
    /// An image whose colours a viewer shows instead of the vertex colours.
    pub drape: Option<Drape>,
}

/// An image draped over a part's triangles (the orthophoto over a terrain tile): a viewer
/// interpolates each triangle's texture coordinates and samples the image between them, so the
/// picture keeps its detail whatever the number of triangles.
///
/// Invariant: `texels.len() == width × height` and `uv` has one entry per vertex of the part's
/// mesh; each vertex's colour in [`Mesh::colours`] is [`Drape::colour_at`] its `uv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Drape {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// sRGB texels, row-major, row 0 at the image's top (north).
    pub texels: Vec<[u8; 3]>,
    /// Per vertex: where it samples the image, in image widths and heights from the image's
    /// top-left corner (glTF's texture coordinates).
    pub uv: Vec<[f32; 2]>,
}

impl Drape {
    /// The texel holding texture coordinate `uv` (clamped to the image).
    pub fn colour_at(&self, [u, v]: [f32; 2]) -> [u8; 3] {
        let at = |t: f32, n: u32| ((t * n as f32).floor().max(0.0) as u32).min(n - 1);
        let (x, y) = (at(u, self.width), at(v, self.height));
        self.texels[(y * self.width + x) as usize]
    }
}
