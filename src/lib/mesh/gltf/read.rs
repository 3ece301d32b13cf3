//! Reading a `.glb` back: only what [`super::write_glb`] writes; every other glTF feature is an
//! error naming it.

use super::{
    to_world, CHUNK_BIN, CHUNK_JSON, FLOAT, GLB_MAGIC, GLB_VERSION, QUANTIZATION, TRIANGLES, UNLIT,
    UNSIGNED_INT, UNSIGNED_SHORT,
};
use crate::error::{Error, Result};
use crate::mesh::{Drape, Lighting, Mesh, Part};
use crate::raster::linear_to_srgb;
use serde_json::{json, Value};

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
pub(super) fn chunks(bytes: &[u8]) -> std::result::Result<(&[u8], &[u8]), Problem> {
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
