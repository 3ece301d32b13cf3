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
use crate::raster::{linear_to_srgb, srgb_to_linear};
use serde_json::{json, Map, Value};

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

/// Decode what `write_glb` wrote back into parts in world metres (adds `origin` back) with sRGB
/// colours; anything else (other glTF features) is an `Error` naming the problem.
///
/// One part per primitive, in order, lit as its material says. Colour alpha is not read (the
/// materials are opaque). The error's problem starts with `glTF binary:`; it names no file, so
/// a caller reading one attaches it with [`Error::in_file`].
pub fn read_glb(bytes: &[u8], origin: [f64; 3]) -> Result<Vec<Part>> {
    read(bytes, origin).map_err(|problem| {
        Error::msg(format!("glTF binary: {problem}"))
            .fix("give a .glb that dbms wrote (dbms export mesh), or write it again")
    })
}

/// What went wrong reading, in words.
type Problem = String;

/// [`read_glb`] with the problem in words, before the common prefix and fix.
fn read(bytes: &[u8], origin: [f64; 3]) -> std::result::Result<Vec<Part>, Problem> {
    let (json, bin) = chunks(bytes)?;
    let root: Value = serde_json::from_slice(json).map_err(|e| format!("JSON chunk: {e}"))?;
    let keys = [
        "asset",
        "extensionsUsed",
        "extensionsRequired",
        "scene",
        "scenes",
        "nodes",
        "meshes",
        "materials",
        "accessors",
        "bufferViews",
        "buffers",
        "images",
        "textures",
        "samplers",
    ];
    only_keys(&root, "the JSON", &keys)?;
    let version = root.pointer("/asset/version").and_then(Value::as_str);
    if version != Some("2.0") {
        return Err(format!("asset version {version:?}, expected \"2.0\""));
    }
    let used = strings(&root, "extensionsUsed")?;
    if let Some(e) = used.iter().find(|e| ![QUANTIZATION, UNLIT].contains(e)) {
        return Err(format!("uses the extension {e}, which dbms does not read"));
    }
    let required = strings(&root, "extensionsRequired")?;
    if let Some(e) = required.iter().find(|e| **e != QUANTIZATION) {
        return Err(format!(
            "requires the extension {e}, which dbms does not read"
        ));
    }
    let quantised = required.contains(&QUANTIZATION);

    let scene = root.get("scene").map_or(Some(0), Value::as_u64);
    let nodes = root.pointer("/scenes/0/nodes");
    if scene != Some(0) || array(&root, "scenes")?.len() != 1 || nodes != Some(&json!([0])) {
        return Err("expected one scene holding node 0".into());
    }
    let node = match array(&root, "nodes")? {
        [n] => n,
        _ => return Err("expected exactly one node".into()),
    };
    only_keys(node, "node 0", &["mesh", "translation", "scale"])?;
    if node.get("mesh") != Some(&json!(0)) {
        return Err("node 0 does not hold mesh 0".into());
    }
    let translation = vec3(node, "translation", [0.0; 3])?;
    let scale = vec3(node, "scale", [1.0; 3])?;
    let mesh = match array(&root, "meshes")? {
        [m] => m,
        _ => return Err("expected exactly one mesh".into()),
    };
    only_keys(mesh, "mesh 0", &["primitives"])?;
    let primitives = array(mesh, "primitives")?;
    if primitives.is_empty() {
        return Err("mesh 0 has no primitive".into());
    }
    let materials = array(&root, "materials")?;
    let file = File {
        root: &root,
        bin: buffer(&root, bin)?,
        quantised,
    };
    primitives
        .iter()
        .enumerate()
        .map(|(i, p)| {
            file.primitive(p, materials, |l| {
                let world = std::array::from_fn(|k| translation[k] + scale[k] * l[k]);
                to_world(world, origin)
            })
            .map_err(|e| format!("primitive {i}: {e}"))
        })
        .collect()
}

/// The JSON and BIN chunks of a GLB container.
fn chunks(bytes: &[u8]) -> std::result::Result<(&[u8], &[u8]), Problem> {
    let word = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes(b.try_into().ok()?))
    };
    if word(0) != Some(GLB_MAGIC) {
        return Err("not a glTF binary (no \"glTF\" magic bytes)".into());
    }
    match word(4) {
        Some(GLB_VERSION) => {}
        Some(v) => return Err(format!("container version {v}, expected 2")),
        None => return Err("header ends early".into()),
    }
    let length = word(8).ok_or("header ends early")? as usize;
    if length != bytes.len() {
        return Err(format!(
            "the header says {length} bytes, the data has {} (truncated?)",
            bytes.len()
        ));
    }
    let mut at = 12;
    let mut chunk = |kind: u32, name: &str| -> std::result::Result<&[u8], Problem> {
        let (len, k) = word(at)
            .zip(word(at + 4))
            .ok_or(format!("no {name} chunk"))?;
        if k != kind {
            return Err(format!("expected the {name} chunk, found type {k:#010x}"));
        }
        let start = at + 8;
        let data = start
            .checked_add(len as usize)
            .and_then(|end| bytes.get(start..end))
            .ok_or(format!("the {name} chunk runs past the end"))?;
        at = start + data.len();
        Ok(data)
    };
    let json = chunk(CHUNK_JSON, "JSON")?;
    let bin = chunk(CHUNK_BIN, "BIN")?;
    if at != bytes.len() {
        return Err(format!("{} bytes after the BIN chunk", bytes.len() - at));
    }
    Ok((json, bin))
}

/// The one buffer's bytes: the BIN chunk, cut to the buffer's length.
fn buffer<'a>(root: &Value, bin: &'a [u8]) -> std::result::Result<&'a [u8], Problem> {
    let b = match array(root, "buffers")? {
        [b] => b,
        _ => return Err("expected exactly one buffer".into()),
    };
    only_keys(b, "buffer 0", &["byteLength"])?;
    let len = b.get("byteLength").and_then(Value::as_u64);
    len.and_then(|n| bin.get(..usize::try_from(n).ok()?))
        .ok_or(format!(
            "buffer 0's byteLength {len:?} is not within the BIN chunk"
        ))
}

/// The array `root[key]`, empty when absent.
fn array<'a>(root: &'a Value, key: &str) -> std::result::Result<&'a [Value], Problem> {
    match root.get(key) {
        None => Ok(&[]),
        Some(Value::Array(a)) => Ok(a),
        Some(_) => Err(format!("{key} is not an array")),
    }
}

/// The array of strings `root[key]`, empty when absent.
fn strings<'a>(root: &'a Value, key: &str) -> std::result::Result<Vec<&'a str>, Problem> {
    array(root, key)?
        .iter()
        .map(|s| s.as_str().ok_or(format!("{key} holds a non-string")))
        .collect()
}

/// Refuse an object with a key outside `keys` (a feature dbms does not read).
fn only_keys(v: &Value, what: &str, keys: &[&str]) -> std::result::Result<(), Problem> {
    let obj = v.as_object().ok_or(format!("{what} is not an object"))?;
    match obj.keys().find(|k| !keys.contains(&k.as_str())) {
        Some(k) => Err(format!("{what} has {k}, which dbms does not read")),
        None => Ok(()),
    }
}

/// Three finite numbers at `v[key]`, or `default` when absent.
fn vec3(v: &Value, key: &str, default: [f64; 3]) -> std::result::Result<[f64; 3], Problem> {
    let Some(a) = v.get(key) else {
        return Ok(default);
    };
    let nums: Option<Vec<f64>> = a
        .as_array()
        .map(|a| a.iter().map(Value::as_f64).collect())
        .unwrap_or(None);
    match nums.as_deref() {
        Some(&[x, y, z]) if [x, y, z].iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("{key} is not three numbers")),
    }
}

/// A file being read: its JSON, its buffer and whether positions may be 16-bit.
struct File<'a> {
    root: &'a Value,
    bin: &'a [u8],
    quantised: bool,
}

/// An accessor's elements: `count` runs of `size` bytes, `stride` apart.
struct Elements<'a> {
    bytes: &'a [u8],
    count: usize,
    stride: usize,
    size: usize,
}

impl<'a> Elements<'a> {
    fn iter(&self) -> impl Iterator<Item = &'a [u8]> + '_ {
        (0..self.count).map(|i| &self.bytes[i * self.stride..][..self.size])
    }
}

/// Little-endian u16s of `b`.
fn u16s(b: &[u8]) -> impl Iterator<Item = u16> + '_ {
    b.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]))
}

impl File<'_> {
    /// The part of primitive `p`; `place` turns a stored position into world metres.
    fn primitive(
        &self,
        p: &Value,
        materials: &[Value],
        place: impl Fn([f64; 3]) -> [f64; 3],
    ) -> std::result::Result<Part, Problem> {
        only_keys(p, "it", &["attributes", "indices", "material", "mode"])?;
        if p.get("mode").is_some_and(|m| m.as_u64() != Some(TRIANGLES)) {
            return Err("mode is not 4 (triangles)".into());
        }
        let attributes = p.get("attributes").ok_or("no attributes")?;
        only_keys(
            attributes,
            "attributes",
            &["POSITION", "COLOR_0", "TEXCOORD_0"],
        )?;
        let index = |key: &str| -> std::result::Result<usize, Problem> {
            p.pointer(key)
                .and_then(Value::as_u64)
                .and_then(|i| usize::try_from(i).ok())
                .ok_or(format!("no {}", &key[1..]))
        };

        let pos = self.accessor(index("/attributes/POSITION")?)?;
        let positions: Vec<[f64; 3]> = match pos.get("componentType").and_then(Value::as_u64) {
            Some(UNSIGNED_SHORT) if !self.quantised => {
                return Err(format!("16-bit positions without {QUANTIZATION} required"));
            }
            Some(UNSIGNED_SHORT) => {
                let e = self.elements(pos, UNSIGNED_SHORT, "VEC3", false)?;
                let q = e.iter().map(|b| {
                    let mut v = u16s(b).map(f64::from);
                    [0; 3].map(|_| v.next().unwrap_or(0.0))
                });
                q.map(&place).collect()
            }
            _ => {
                let e = self.elements(pos, FLOAT, "VEC3", false)?;
                let f = e.iter().map(|b| {
                    let mut v = b
                        .chunks_exact(4)
                        .map(|c| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])));
                    [0; 3].map(|_| v.next().unwrap_or(f64::NAN))
                });
                let f: Vec<[f64; 3]> = f.collect();
                if f.iter().flatten().any(|c| !c.is_finite()) {
                    return Err("a position is not finite".into());
                }
                f.into_iter().map(&place).collect()
            }
        };

        let material = materials
            .get(index("/material")?)
            .ok_or("its material does not exist")?;
        only_keys(
            material,
            "its material",
            &["name", "pbrMetallicRoughness", "extensions"],
        )?;
        let lighting = match material.get("extensions") {
            None => Lighting::Lit,
            Some(e) if *e == json!({ UNLIT: {} }) => Lighting::Unlit,
            Some(_) => return Err("its material has extensions dbms does not read".into()),
        };
        let texture = material.pointer("/pbrMetallicRoughness/baseColorTexture/index");
        let (colours, drape) = match (texture, attributes.get("TEXCOORD_0")) {
            (None, None) => (
                self.colours(index("/attributes/COLOR_0")?, positions.len())?,
                None,
            ),
            (Some(t), Some(_)) => {
                let uv = self.accessor(index("/attributes/TEXCOORD_0")?)?;
                let uv = self.elements(uv, FLOAT, "VEC2", false)?;
                let uv: Vec<[f32; 2]> = uv
                    .iter()
                    .map(|b| {
                        [0, 4].map(|k| f32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]))
                    })
                    .collect();
                if uv.len() != positions.len() {
                    return Err(format!(
                        "{} texture coordinates for {} positions",
                        uv.len(),
                        positions.len()
                    ));
                }
                let drape = self.image(t, uv)?;
                (
                    drape.uv.iter().map(|&c| drape.colour_at(c)).collect(),
                    Some(drape),
                )
            }
            _ => {
                return Err("a texture without texture coordinates, or the other way round".into())
            }
        };

        let ind = self.accessor(index("/indices")?)?;
        let indices: Vec<u32> = match ind.get("componentType").and_then(Value::as_u64) {
            Some(UNSIGNED_INT) => {
                let e = self.elements(ind, UNSIGNED_INT, "SCALAR", false)?;
                e.iter()
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .collect()
            }
            _ => {
                let e = self.elements(ind, UNSIGNED_SHORT, "SCALAR", false)?;
                e.iter().flat_map(u16s).map(u32::from).collect()
            }
        };
        if !indices.len().is_multiple_of(3) {
            return Err(format!("{} indices, not whole triangles", indices.len()));
        }
        if let Some(i) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(format!("index {i} past the {} positions", positions.len()));
        }
        let triangles = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();

        Ok(Part {
            mesh: Mesh {
                positions,
                colours,
                triangles,
            },
            lighting,
            drape,
        })
    }

    /// The sRGB colours of COLOR_0 accessor `i`, which must have `n` of them.
    fn colours(&self, i: usize, n: usize) -> std::result::Result<Vec<[u8; 3]>, Problem> {
        let col = self.elements(self.accessor(i)?, UNSIGNED_SHORT, "VEC4", true)?;
        if col.count != n {
            return Err(format!("{} colours for {n} positions", col.count));
        }
        Ok(col
            .iter()
            .map(|b| {
                let mut v = u16s(b).map(|c| linear_to_srgb(f64::from(c) / 65535.0));
                [0; 3].map(|_| v.next().unwrap_or(0))
            })
            .collect())
    }

    /// Texture `t`'s PNG image (in the buffer) as a drape sampled at `uv`.
    fn image(&self, t: &Value, uv: Vec<[f32; 2]>) -> std::result::Result<Drape, Problem> {
        let t = t
            .as_u64()
            .and_then(|t| usize::try_from(t).ok())
            .ok_or("a texture index is not a number")?;
        let texture = array(self.root, "textures")?
            .get(t)
            .ok_or(format!("texture {t} does not exist"))?;
        let source = texture
            .get("source")
            .and_then(Value::as_u64)
            .ok_or(format!("texture {t} has no source"))?;
        let image = array(self.root, "images")?
            .get(usize::try_from(source).unwrap_or(usize::MAX))
            .ok_or(format!("image {source} does not exist"))?;
        only_keys(image, "an image", &["bufferView", "mimeType"])?;
        if image.get("mimeType").and_then(Value::as_str) != Some("image/png") {
            return Err(format!("image {source} is not a PNG"));
        }
        let v = image
            .get("bufferView")
            .and_then(Value::as_u64)
            .ok_or("an image has no bufferView")?;
        let view = array(self.root, "bufferViews")?
            .get(usize::try_from(v).unwrap_or(usize::MAX))
            .ok_or(format!("buffer view {v} does not exist"))?;
        let field = |key: &str| {
            view.get(key)
                .and_then(Value::as_u64)
                .and_then(|n| usize::try_from(n).ok())
        };
        let bytes = field("byteLength")
            .and_then(|len| {
                let start = field("byteOffset").unwrap_or(0);
                self.bin.get(start..start.checked_add(len)?)
            })
            .ok_or(format!("image {source}'s data is not within the buffer"))?;
        let rgb = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
            .map_err(|e| format!("image {source}: {e}"))?
            .to_rgb8();
        let (width, height) = rgb.dimensions();
        let texels = rgb.pixels().map(|p| p.0).collect();
        Ok(Drape {
            width,
            height,
            texels,
            uv,
        })
    }

    /// Accessor `i`, refusing sparse ones and other unread features.
    fn accessor(&self, i: usize) -> std::result::Result<&Value, Problem> {
        let a = array(self.root, "accessors")?
            .get(i)
            .ok_or(format!("accessor {i} does not exist"))?;
        let keys = [
            "bufferView",
            "byteOffset",
            "componentType",
            "type",
            "count",
            "normalized",
            "min",
            "max",
        ];
        only_keys(a, &format!("accessor {i}"), &keys)?;
        Ok(a)
    }

    /// The elements of `accessor`, which must have this component type, type and
    /// normalisation, and lie within its buffer view and the buffer.
    fn elements(
        &self,
        a: &Value,
        component: u64,
        kind: &str,
        normalized: bool,
    ) -> std::result::Result<Elements<'_>, Problem> {
        let field = |v: &Value, key: &str| v.get(key).and_then(Value::as_u64);
        let want = (Some(component), Some(kind), normalized);
        let have = (
            field(a, "componentType"),
            a.get("type").and_then(Value::as_str),
            a.get("normalized")
                .and_then(Value::as_bool)
                .unwrap_or(false),
        );
        if have != want {
            return Err(format!(
                "an accessor has (componentType, type, normalized) {have:?}, expected {want:?}"
            ));
        }
        let v = field(a, "bufferView").ok_or("an accessor has no bufferView")?;
        let view = array(self.root, "bufferViews")?
            .get(usize::try_from(v).unwrap_or(usize::MAX))
            .ok_or(format!("buffer view {v} does not exist"))?;
        let what = format!("buffer view {v}");
        only_keys(
            view,
            &what,
            &["buffer", "byteOffset", "byteLength", "byteStride", "target"],
        )?;
        if field(view, "buffer") != Some(0) {
            return Err(format!("{what} is not in buffer 0"));
        }
        let size = match component {
            UNSIGNED_SHORT => 2,
            _ => 4,
        } * match kind {
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 1,
        };
        let to_usize = |n: Option<u64>| n.and_then(|n| usize::try_from(n).ok());
        let range = (|| {
            let start = to_usize(field(view, "byteOffset").or(Some(0)))?;
            let len = to_usize(field(view, "byteLength"))?;
            let bytes = self.bin.get(start..start.checked_add(len)?)?;
            let offset = to_usize(field(a, "byteOffset").or(Some(0)))?;
            let stride = to_usize(field(view, "byteStride").or(Some(size as u64)))?;
            let count = to_usize(field(a, "count"))?;
            let need = match count {
                0 => 0,
                n => (n - 1).checked_mul(stride)?.checked_add(size)?,
            };
            let bytes = bytes.get(offset..offset.checked_add(need)?)?;
            (stride >= size).then_some(Elements {
                bytes,
                count,
                stride,
                size,
            })
        })();
        range.ok_or(format!(
            "an accessor's data is not within {what} and the buffer"
        ))
    }
}

#[cfg(test)]
#[path = "gltf_tests.rs"]
mod tests;
