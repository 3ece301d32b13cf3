//! glTF 2.0 binary (`.glb`): a tile's [`Part`]s as one file a browser viewer (three.js,
//! CesiumJS) loads as it is, and read back for tests and checks.
//!
//! **Axes.** Our world is x east, y north, z up, in metres; glTF is y up. A world position is
//! first taken relative to the tile's `origin` (the origin of the tile's local frame, world
//! metres), then turned: glTF (x, y, z) = (east, up, −north). The turn is a proper rotation, so
//! counter-clockwise triangles stay counter-clockwise.
//!
//! **Positions: the tile origin plus small deltas.** Over all parts of a file, q0 is the min
//! corner of the local box and the step along each axis is its extent / 65535. When the worst
//! rounding error, half the largest step, is at most [`MAX_ROUNDING`] (1 mm: boxes up to
//! 131.07 m along each axis), positions are stored as unsigned 16-bit integers (not
//! normalised) under `KHR_mesh_quantization`, which the file then requires; the node's
//! `translation` is q0 and its `scale` the steps, so a viewer places vertex q at
//! q0 + q · step, within half a step of the input. An axis of zero extent gets a step of 1 and
//! every value 0 (no error). A larger box is stored as 32-bit floats relative to q0 (node
//! translation q0, scale 1): the error is the float's rounding, at most extent · 2⁻²⁴
//! (12 µm for 200 m). A u16 VEC3 is 6 bytes; vertex attributes must start on 4-byte
//! boundaries, so its buffer view has a byte stride of 8.
//!
//! **Colours.** glTF vertex colours (`COLOR_0`) are linear, ours ([`Mesh::colours`]) sRGB bytes:
//! they are stored linear as normalised unsigned 16-bit RGBA (alpha 65535, opaque). Sixteen
//! bits keep every one of the 256 sRGB values apart, so [`read_glb`] gets the exact bytes back.
//! Vertex colours multiply the material's base colour, which is white.
//!
//! **Drapes.** A part with a [`Drape`] has no `COLOR_0`: its image is stored in the buffer as
//! an 8-bit RGB PNG (an `image` with its own buffer view), its texture coordinates as
//! `TEXCOORD_0` floats, and a material of its own (after the undraped parts' two) takes its
//! base colour from that texture (sampler: linear, mipmapped, clamped at the edges so
//! neighbouring tiles' images do not bleed in). [`read_glb`] decodes the image and gives each
//! vertex the texel at its coordinates as its colour. Images need not be powers of two (the
//! validator notes that as information: WebGL 2 and glTF viewers take them).
//!
//! **Indices.** Unsigned 16-bit when every index of the part is below 65535 (65535 is the
//! primitive-restart value, which glTF forbids), else unsigned 32-bit.
//!
//! **No normals.** `NORMAL` is left out: the glTF spec has clients compute flat normals when it
//! is absent (three.js and CesiumJS do), which is what prisms, objects and a TIN want.
//!
//! **Materials.** Only those used: undraped [`Lighting::Unlit`] parts get one named `unlit` with
//! `KHR_materials_unlit` (used, not required: a viewer without it lights the colours, which is
//! still a picture), [`Lighting::Lit`] parts a plain one named `lit`; both white, metallic 0,
//! roughness 1.
//!
//! One scene, one node, one mesh, one triangle primitive per non-empty part. The same parts
//! give the same bytes. Every file passes the Khronos glTF validator with no error and no
//! warning (`samples/web/validate-gltf.mjs`).

use super::{Drape, Lighting, Mesh, Part};
use crate::error::{Error, Result};
use crate::raster::srgb_to_linear;
use serde_json::{json, Map, Value};

mod read;
pub use read::read_glb;

/// The largest position error (metres) the 16-bit encoding may make; a box needing more is
/// stored as floats.
pub const MAX_ROUNDING: f64 = 0.001;

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const GLB_VERSION: u32 = 2;
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"

const UNSIGNED_SHORT: u64 = 5123;
const UNSIGNED_INT: u64 = 5125;
const FLOAT: u64 = 5126;
const ARRAY_BUFFER: u64 = 34962;
const ELEMENT_ARRAY_BUFFER: u64 = 34963;
const TRIANGLES: u64 = 4;
const LINEAR: u64 = 9729;
const LINEAR_MIPMAP_LINEAR: u64 = 9987;
const CLAMP_TO_EDGE: u64 = 33071;
/// The largest index stored as an unsigned short (65535 is the primitive-restart value).
const MAX_SHORT_INDEX: u32 = 65534;

const QUANTIZATION: &str = "KHR_mesh_quantization";
const UNLIT: &str = "KHR_materials_unlit";

/// World (east, north, up) relative to `origin` → glTF (east, up, −north).
fn to_local(p: [f64; 3], origin: [f64; 3]) -> [f64; 3] {
    [p[0] - origin[0], p[2] - origin[2], -(p[1] - origin[1])]
}

/// glTF (east, up, −north) → world (east, north, up) with `origin` added back.
fn to_world(l: [f64; 3], origin: [f64; 3]) -> [f64; 3] {
    [origin[0] + l[0], origin[1] - l[2], origin[2] + l[1]]
}

/// How positions are stored: the node's transform and the encoding of the deltas.
struct Frame {
    /// Min corner of the local box (glTF axes, metres): the node's translation.
    q0: [f64; 3],
    /// Metres per unit of a 16-bit value along each axis, or `None` for floats.
    steps: Option<[f64; 3]>,
}

impl Frame {
    /// The frame of the local box `lo`..`hi`: 16-bit when half the largest step is at most
    /// [`MAX_ROUNDING`] (axes of zero extent make no error and do not count).
    fn new(lo: [f64; 3], hi: [f64; 3]) -> Frame {
        let extent: [f64; 3] = std::array::from_fn(|i| hi[i] - lo[i]);
        let worst = extent.iter().fold(0.0f64, |w, e| w.max(e / 65535.0 / 2.0));
        let steps = (worst <= MAX_ROUNDING)
            .then(|| extent.map(|e| if e > 0.0 { e / 65535.0 } else { 1.0 }));
        Frame { q0: lo, steps }
    }
}

/// Encode `parts` as one glTF 2.0 binary. World positions (x east, y north, z up, metres)
/// are taken relative to `origin` (world metres: the origin of the tile's frame) and turned
/// to glTF's y-up axes: glTF (x, y, z) = (east, up, -north).
///
/// Parts without triangles are left out; if no part has one, the result is an error, as is a
/// mesh breaking [`Mesh`]'s invariant (a colour per position, indices below the number of
/// positions) or holding a non-finite position. The encoding is in the module doc.
pub fn write_glb(parts: &[Part], origin: [f64; 3]) -> Result<Vec<u8>> {
    let parts: Vec<&Part> = parts.iter().filter(|p| !p.mesh.is_empty()).collect();
    if parts.is_empty() {
        return Err(Error::msg(
            "a glTF file needs at least one triangle; the parts have none",
        ));
    }
    for (i, part) in parts.iter().enumerate() {
        check_mesh(&part.mesh)
            .and_then(|()| {
                part.drape
                    .as_ref()
                    .map_or(Ok(()), |d| check_drape(d, &part.mesh))
            })
            .map_err(|e| Error::msg(format!("glTF part {i}: {e}")))?;
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in parts.iter().flat_map(|p| &p.mesh.positions) {
        let l = to_local(*p, origin);
        for i in 0..3 {
            lo[i] = lo[i].min(l[i]);
            hi[i] = hi[i].max(l[i]);
        }
    }
    if (0..3).any(|i| !(hi[i] - lo[i]).is_finite()) {
        return Err(Error::msg(format!(
            "the parts span {lo:?}..{hi:?} m from the tile origin, too far for a glTF file"
        )));
    }
    let frame = Frame::new(lo, hi);

    // A material per lighting for the parts without a drape, unlit before lit; one per drape
    // after them, each with its own image.
    let mut materials: Vec<(Lighting, Option<usize>)> = [Lighting::Unlit, Lighting::Lit]
        .into_iter()
        .filter(|l| parts.iter().any(|p| p.lighting == *l && p.drape.is_none()))
        .map(|l| (l, None))
        .collect();
    let mut out = Binary::default();
    let mut images = Vec::new();
    let primitives: Vec<Value> = parts
        .iter()
        .map(|part| {
            let position = out.positions(&part.mesh.positions, origin, &frame);
            let (attributes, material) = match &part.drape {
                None => {
                    let material = materials.iter().position(|m| *m == (part.lighting, None));
                    let colours = out.colours(&part.mesh.colours);
                    (
                        json!({ "POSITION": position, "COLOR_0": colours }),
                        material.expect("every undraped part's lighting has a material"),
                    )
                }
                Some(drape) => {
                    images.push(json!({
                        "bufferView": out.view(&png(drape), None, None),
                        "mimeType": "image/png",
                    }));
                    materials.push((part.lighting, Some(images.len() - 1)));
                    let uv = out.texcoords(&drape.uv);
                    (
                        json!({ "POSITION": position, "TEXCOORD_0": uv }),
                        materials.len() - 1,
                    )
                }
            };
            json!({
                "attributes": attributes,
                "indices": out.indices(&part.mesh.triangles),
                "material": material,
                "mode": TRIANGLES,
            })
        })
        .collect();

    let mut node = Map::new();
    node.insert("mesh".into(), json!(0));
    node.insert("translation".into(), json!(frame.q0));
    if let Some(steps) = frame.steps {
        node.insert("scale".into(), json!(steps));
    }
    let mut used = Vec::new();
    if frame.steps.is_some() {
        used.push(QUANTIZATION);
    }
    if materials.iter().any(|m| m.0 == Lighting::Unlit) {
        used.push(UNLIT);
    }
    let mut root = json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("dbms ", env!("CARGO_PKG_VERSION")),
        },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [node],
        "meshes": [{ "primitives": primitives }],
        "materials": materials.iter().map(|&(l, t)| material(l, t)).collect::<Vec<_>>(),
        "accessors": out.accessors,
        "bufferViews": out.views,
        "buffers": [{ "byteLength": out.bin.len() }],
    });
    if !images.is_empty() {
        let textures: Vec<Value> = (0..images.len())
            .map(|i| json!({ "sampler": 0, "source": i }))
            .collect();
        root["images"] = json!(images);
        root["textures"] = json!(textures);
        // Linear between texels and mipmaps, clamped at the edges (neighbouring tiles'
        // images must not bleed into each other).
        root["samplers"] = json!([{
            "magFilter": LINEAR,
            "minFilter": LINEAR_MIPMAP_LINEAR,
            "wrapS": CLAMP_TO_EDGE,
            "wrapT": CLAMP_TO_EDGE,
        }]);
    }
    if !used.is_empty() {
        root["extensionsUsed"] = json!(used);
    }
    if frame.steps.is_some() {
        root["extensionsRequired"] = json!([QUANTIZATION]);
    }
    glb(
        &serde_json::to_vec(&root).expect("a JSON value serialises"),
        out.bin,
    )
}

/// The problem with a mesh that breaks [`Mesh`]'s invariant or has a non-finite position.
fn check_mesh(m: &Mesh) -> std::result::Result<(), String> {
    if m.colours.len() != m.positions.len() {
        return Err(format!(
            "{} colours for {} positions (one colour per position)",
            m.colours.len(),
            m.positions.len()
        ));
    }
    let n = m.positions.len();
    if let Some(t) = m
        .triangles
        .iter()
        .find(|t| t.iter().any(|&i| i as usize >= n))
    {
        return Err(format!("triangle {t:?} indexes past the {n} positions"));
    }
    if let Some(p) = m
        .positions
        .iter()
        .find(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(format!("position {p:?} is not finite"));
    }
    Ok(())
}

/// The problem with a drape that breaks [`Drape`]'s invariant for `mesh`.
fn check_drape(d: &Drape, mesh: &Mesh) -> std::result::Result<(), String> {
    if d.width == 0 || d.height == 0 || d.texels.len() != d.width as usize * d.height as usize {
        return Err(format!(
            "a {} × {} image with {} texels",
            d.width,
            d.height,
            d.texels.len()
        ));
    }
    if d.uv.len() != mesh.positions.len() {
        return Err(format!(
            "{} texture coordinates for {} positions",
            d.uv.len(),
            mesh.positions.len()
        ));
    }
    if d.uv.iter().flatten().any(|t| !t.is_finite()) {
        return Err("a texture coordinate is not finite".into());
    }
    Ok(())
}

/// A drape's image as PNG (RGB, 8 bits; the same texels give the same bytes).
fn png(d: &Drape) -> Vec<u8> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Default, FilterType::Adaptive)
        .write_image(
            d.texels.as_flattened(),
            d.width,
            d.height,
            image::ExtendedColorType::Rgb8,
        )
        .expect("encoding RGB texels of a checked size into memory cannot fail");
    out
}

/// The material of `lighting` (white, not metallic, fully rough; unlit ones with
/// `KHR_materials_unlit`), coloured by texture `texture` when given.
fn material(lighting: Lighting, texture: Option<usize>) -> Value {
    let mut m = json!({
        "name": match lighting {
            Lighting::Unlit => "unlit",
            Lighting::Lit => "lit",
        },
        "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0,
        },
    });
    if lighting == Lighting::Unlit {
        m["extensions"] = json!({ UNLIT: {} });
    }
    if let Some(t) = texture {
        m["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": t });
    }
    m
}

/// The BIN chunk as it grows, with the buffer views and accessors that describe it.
#[derive(Default)]
struct Binary {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Binary {
    /// Append `data` as a buffer view starting on a 4-byte boundary; its index. Images'
    /// views have no target.
    fn view(&mut self, data: &[u8], stride: Option<usize>, target: Option<u64>) -> usize {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let mut v = json!({
            "buffer": 0,
            "byteOffset": self.bin.len(),
            "byteLength": data.len(),
        });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        if let Some(s) = stride {
            v["byteStride"] = json!(s);
        }
        self.bin.extend_from_slice(data);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Append an accessor (`fields` plus the view and count); its index.
    fn accessor(&mut self, view: usize, count: usize, mut fields: Value) -> usize {
        fields["bufferView"] = json!(view);
        fields["count"] = json!(count);
        self.accessors.push(fields);
        self.accessors.len() - 1
    }

    /// The POSITION accessor of `positions` in `frame`, with its exact min and max.
    fn positions(&mut self, positions: &[[f64; 3]], origin: [f64; 3], frame: &Frame) -> usize {
        let delta = |p: &[f64; 3]| {
            let l = to_local(*p, origin);
            std::array::from_fn::<f64, 3, _>(|i| l[i] - frame.q0[i])
        };
        let n = positions.len();
        match frame.steps {
            Some(steps) => {
                let q: Vec<[u16; 3]> = positions
                    .iter()
                    .map(|p| {
                        let d = delta(p);
                        std::array::from_fn(|i| {
                            (d[i] / steps[i]).round().clamp(0.0, 65535.0) as u16
                        })
                    })
                    .collect();
                let mut data = Vec::with_capacity(8 * n);
                for v in &q {
                    v.iter()
                        .for_each(|c| data.extend_from_slice(&c.to_le_bytes()));
                    data.extend_from_slice(&[0, 0]);
                }
                let (min, max) = min_max(&q, |c| f64::from(*c));
                let view = self.view(&data, Some(8), Some(ARRAY_BUFFER));
                self.accessor(
                    view,
                    n,
                    json!({
                        "componentType": UNSIGNED_SHORT,
                        "type": "VEC3",
                        "min": min,
                        "max": max,
                    }),
                )
            }
            None => {
                let f: Vec<[f32; 3]> = positions
                    .iter()
                    .map(|p| delta(p).map(|c| c as f32))
                    .collect();
                let data: Vec<u8> = f.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
                // The f32 widened to f64 prints exactly, so min and max match the data.
                let (min, max) = min_max(&f, |c| f64::from(*c));
                let view = self.view(&data, None, Some(ARRAY_BUFFER));
                self.accessor(
                    view,
                    n,
                    json!({ "componentType": FLOAT, "type": "VEC3", "min": min, "max": max }),
                )
            }
        }
    }

    /// The COLOR_0 accessor: linear RGBA, normalised unsigned shorts, opaque.
    fn colours(&mut self, colours: &[[u8; 3]]) -> usize {
        let lut: [u16; 256] =
            std::array::from_fn(|v| (srgb_to_linear(v as u8) * 65535.0).round() as u16);
        let data: Vec<u8> = colours
            .iter()
            .flat_map(|c| {
                [
                    lut[c[0] as usize],
                    lut[c[1] as usize],
                    lut[c[2] as usize],
                    65535,
                ]
            })
            .flat_map(u16::to_le_bytes)
            .collect();
        let view = self.view(&data, None, Some(ARRAY_BUFFER));
        self.accessor(
            view,
            colours.len(),
            json!({ "componentType": UNSIGNED_SHORT, "type": "VEC4", "normalized": true }),
        )
    }

    /// The TEXCOORD_0 accessor: floats.
    fn texcoords(&mut self, uv: &[[f32; 2]]) -> usize {
        let data: Vec<u8> = uv.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
        let view = self.view(&data, None, Some(ARRAY_BUFFER));
        self.accessor(
            view,
            uv.len(),
            json!({ "componentType": FLOAT, "type": "VEC2" }),
        )
    }

    /// The indices accessor: unsigned shorts when every index is at most 65534, else
    /// unsigned ints.
    fn indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let flat = triangles.iter().flatten();
        let short = flat.clone().all(|&i| i <= MAX_SHORT_INDEX);
        let (data, component): (Vec<u8>, _) = if short {
            let d = flat.flat_map(|&i| (i as u16).to_le_bytes()).collect();
            (d, UNSIGNED_SHORT)
        } else {
            (flat.flat_map(|i| i.to_le_bytes()).collect(), UNSIGNED_INT)
        };
        let view = self.view(&data, None, Some(ELEMENT_ARRAY_BUFFER));
        self.accessor(
            view,
            3 * triangles.len(),
            json!({ "componentType": component, "type": "SCALAR" }),
        )
    }
}

/// Per-component min and max of non-empty `values`, as JSON numbers.
fn min_max<T>(values: &[[T; 3]], num: impl Fn(&T) -> f64) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in values {
        for i in 0..3 {
            lo[i] = lo[i].min(num(&v[i]));
            hi[i] = hi[i].max(num(&v[i]));
        }
    }
    (lo, hi)
}

/// The GLB container: header, JSON chunk padded with spaces, BIN chunk padded with zeros.
fn glb(json: &[u8], mut bin: Vec<u8>) -> Result<Vec<u8>> {
    let mut json = json.to_vec();
    json.resize(json.len().next_multiple_of(4), b' ');
    bin.resize(bin.len().next_multiple_of(4), 0);
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total32 = u32::try_from(total).map_err(|_| {
        Error::msg(format!(
            "a glTF binary of {total} bytes is over the format's 4 GiB limit"
        ))
        .fix("split the tile into smaller ones")
    })?;
    let mut out = Vec::with_capacity(total);
    for word in [GLB_MAGIC, GLB_VERSION, total32] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    for (kind, data) in [(CHUNK_JSON, &json), (CHUNK_BIN, &bin)] {
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(&kind.to_le_bytes());
        out.extend_from_slice(data);
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
