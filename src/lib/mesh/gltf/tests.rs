use super::read::chunks;
use super::*;
use std::path::Path;

/// A tile origin far from zero, as a projected CRS gives.
const ORIGIN: [f64; 3] = [512_000.0, 4_180_000.0, 250.0];

/// A terrain-like grid of `nx` × `ny` vertices over `w` × `h` metres east and north of
/// `ORIGIN` + `at`, heights from `z`, colours varying; triangles counter-clockwise from above.
fn grid(
    nx: u32,
    ny: u32,
    (w, h): (f64, f64),
    at: [f64; 3],
    z: impl Fn(f64, f64) -> f64,
    lighting: Lighting,
) -> Part {
    let mut mesh = Mesh::default();
    for j in 0..ny {
        for i in 0..nx {
            let x = w * f64::from(i) / f64::from(nx - 1);
            let y = h * f64::from(j) / f64::from(ny - 1);
            mesh.positions.push([
                ORIGIN[0] + at[0] + x,
                ORIGIN[1] + at[1] + y,
                ORIGIN[2] + at[2] + z(x, y),
            ]);
            mesh.colours.push([
                (i * 7 % 256) as u8,
                (j * 13 % 256) as u8,
                ((i + j) % 256) as u8,
            ]);
        }
    }
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let v = j * nx + i;
            mesh.triangles.push([v, v + 1, v + nx + 1]);
            mesh.triangles.push([v, v + nx + 1, v + nx]);
        }
    }
    Part {
        mesh,
        lighting,
        drape: None,
    }
}

/// `part` with a `w` × `h` image draped over it: each vertex samples the texel its own colour
/// came from (vertex k's colour is texel k mod w·h), as the exporter drapes the photo.
fn draped(mut part: Part, w: u32, h: u32) -> Part {
    let texels: Vec<[u8; 3]> = (0..w * h)
        .map(|t| [(t * 37 % 256) as u8, (t * 11 % 256) as u8, (t % 256) as u8])
        .collect();
    let uv: Vec<[f32; 2]> = (0..part.mesh.positions.len() as u32)
        .map(|k| {
            let t = k % (w * h);
            [
                ((t % w) as f32 + 0.5) / w as f32,
                ((t / w) as f32 + 0.5) / h as f32,
            ]
        })
        .collect();
    let drape = Drape {
        width: w,
        height: h,
        texels,
        uv,
    };
    part.mesh.colours = drape.uv.iter().map(|&c| drape.colour_at(c)).collect();
    part.drape = Some(drape);
    part
}

fn hill(x: f64, y: f64) -> f64 {
    10.0 * (x / 17.0).sin() * (y / 23.0).cos()
}

/// The glTF JSON of a glb.
fn json_of(glb: &[u8]) -> Value {
    let (json, _) = chunks(glb).unwrap();
    serde_json::from_slice(json).unwrap()
}

/// `glb` with its JSON edited by `edit` (the BIN chunk kept).
fn edited(glb: &[u8], edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let (_, bin) = chunks(glb).unwrap();
    let mut root = json_of(glb);
    edit(&mut root);
    super::glb(&serde_json::to_vec(&root).unwrap(), bin.to_vec()).unwrap()
}

/// The half steps of the 16-bit encoding of a box of `extent` (glTF axes).
fn half_steps(extent: [f64; 3]) -> [f64; 3] {
    extent.map(|e| e / 65535.0 / 2.0)
}

/// `back` is `want` with positions within `tol` (world axes) and colours and triangles exact.
fn assert_close(want: &[Part], back: &[Part], tol: [f64; 3]) {
    assert_eq!(want.len(), back.len());
    for (w, b) in want.iter().zip(back) {
        assert_eq!(w.lighting, b.lighting);
        assert_eq!(w.mesh.triangles, b.mesh.triangles);
        assert_eq!(w.mesh.colours, b.mesh.colours);
        assert_eq!(w.mesh.positions.len(), b.mesh.positions.len());
        for (p, q) in w.mesh.positions.iter().zip(&b.mesh.positions) {
            for k in 0..3 {
                // 1e-8 m: the f64 arithmetic at a few million metres.
                assert!(
                    (p[k] - q[k]).abs() <= tol[k] + 1e-8,
                    "{p:?} read back as {q:?}"
                );
            }
        }
    }
}

fn position_accessor(root: &Value, primitive: usize) -> &Value {
    let i = root["meshes"][0]["primitives"][primitive]["attributes"]["POSITION"]
        .as_u64()
        .unwrap();
    &root["accessors"][i as usize]
}

#[test]
fn a_60_m_tile_is_16_bit_and_reads_back_within_half_a_step() {
    let parts = [
        grid(40, 30, (60.0, 45.0), [3.0, 5.0, 0.0], hill, Lighting::Unlit),
        grid(
            5,
            5,
            (8.0, 8.0),
            [20.0, 20.0, 12.0],
            |_, _| 0.0,
            Lighting::Lit,
        ),
    ];
    let glb = write_glb(&parts, ORIGIN).unwrap();
    let root = json_of(&glb);
    assert_eq!(root["extensionsRequired"], json!([QUANTIZATION]));
    assert_eq!(root["extensionsUsed"], json!([QUANTIZATION, UNLIT]));
    let pos = position_accessor(&root, 0);
    assert_eq!(pos["componentType"], json!(UNSIGNED_SHORT));
    assert_eq!(pos.get("normalized"), None);
    let view = &root["bufferViews"][pos["bufferView"].as_u64().unwrap() as usize];
    assert_eq!(view["byteStride"], json!(8));
    // The node's scale is the step: east 60 m, up 32 m (hills ±10 and the roof at 12), north
    // 45 m.
    let scale = &root["nodes"][0]["scale"];
    let (lo, hi) = parts[0].mesh.bounds().unwrap();
    let (lo2, hi2) = parts[1].mesh.bounds().unwrap();
    let up = hi[2].max(hi2[2]) - lo[2].min(lo2[2]);
    assert_eq!(scale[0].as_f64().unwrap(), 60.0 / 65535.0);
    assert_eq!(scale[1].as_f64().unwrap(), up / 65535.0);
    let back = read_glb(&glb, ORIGIN).unwrap();
    let h = half_steps([60.0, up, 45.0]);
    assert_close(&parts, &back, [h[0], h[2], h[1]]);
}

#[test]
fn a_200_m_tile_is_float_and_reads_back_within_float_rounding() {
    let parts = [grid(50, 50, (200.0, 150.0), [0.0; 3], hill, Lighting::Lit)];
    let glb = write_glb(&parts, ORIGIN).unwrap();
    let root = json_of(&glb);
    assert_eq!(root.get("extensionsRequired"), None);
    assert_eq!(root.get("extensionsUsed"), None);
    assert_eq!(position_accessor(&root, 0)["componentType"], json!(FLOAT));
    assert_eq!(root["nodes"][0].get("scale"), None);
    let back = read_glb(&glb, ORIGIN).unwrap();
    assert_close(&parts, &back, [200.0 * 2f64.powi(-24); 3]);
}

/// Half the largest step against 1 mm: 131 m is 16-bit, 131.2 m is not, whichever the axis.
#[test]
fn the_encoding_switches_where_half_a_step_passes_1_mm() {
    for (size, quantised) in [(131.0, true), (131.2, false)] {
        for axis in 0..3 {
            let mut far = ORIGIN;
            far[axis] += size;
            let part = Part {
                mesh: Mesh {
                    positions: vec![ORIGIN, far, [ORIGIN[0] + 1.0, ORIGIN[1] + 1.0, ORIGIN[2]]],
                    colours: vec![[0; 3]; 3],
                    triangles: vec![[0, 1, 2]],
                },
                lighting: Lighting::Lit,
                drape: None,
            };
            let root = json_of(&write_glb(&[part], ORIGIN).unwrap());
            let c = &position_accessor(&root, 0)["componentType"];
            let want = if quantised { UNSIGNED_SHORT } else { FLOAT };
            assert_eq!(*c, json!(want), "{size} m along axis {axis}");
        }
    }
}

/// World (1, 2, 3) from the origin is glTF (1, 3, −2); the node's translation is the min corner;
/// a flat axis gets a step of 1 and no error.
#[test]
fn axes_turn_to_y_up_and_a_flat_axis_is_exact() {
    let o = ORIGIN;
    let part = Part {
        mesh: Mesh {
            positions: vec![o, [o[0] + 1.0, o[1], o[2]], [o[0], o[1] + 2.0, o[2]]],
            colours: vec![[10, 20, 30]; 3],
            triangles: vec![[0, 1, 2]],
        },
        lighting: Lighting::Unlit,
        drape: None,
    };
    let glb = write_glb(std::slice::from_ref(&part), o).unwrap();
    let root = json_of(&glb);
    assert_eq!(root["nodes"][0]["translation"], json!([0.0, 0.0, -2.0]));
    assert_eq!(
        root["nodes"][0]["scale"],
        json!([1.0 / 65535.0, 1.0, 2.0 / 65535.0])
    );
    let pos = position_accessor(&root, 0);
    assert_eq!(pos["min"], json!([0.0, 0.0, 0.0]));
    assert_eq!(pos["max"], json!([65535.0, 0.0, 65535.0]));
    assert_eq!(read_glb(&glb, o).unwrap()[0].mesh.positions[0][2], o[2]);
    let back = read_glb(&glb, o).unwrap();
    assert_close(&[part], &back, [1e-9; 3]);
}

#[test]
fn every_srgb_value_round_trips_exactly() {
    let n = 256u32;
    let part = Part {
        mesh: Mesh {
            positions: (0..n)
                .map(|i| {
                    [
                        ORIGIN[0] + f64::from(i),
                        ORIGIN[1] + f64::from(i % 2),
                        ORIGIN[2],
                    ]
                })
                .collect(),
            colours: (0..n)
                .map(|v| [v as u8, (255 - v) as u8, (v * 3 % 256) as u8])
                .collect(),
            triangles: (0..n - 2).map(|i| [i, i + 1, i + 2]).collect(),
        },
        lighting: Lighting::Unlit,
        drape: None,
    };
    let back = read_glb(
        &write_glb(std::slice::from_ref(&part), ORIGIN).unwrap(),
        ORIGIN,
    )
    .unwrap();
    assert_eq!(back[0].mesh.colours, part.mesh.colours);
    // Stored linear: sRGB 128 is about 0.216 of full scale, not a half.
    assert_eq!((srgb_to_linear(128) * 65535.0).round(), 14_146.0);
}

/// A strip over `n` vertices: indices up to n − 1.
fn strip(n: u32) -> Part {
    Part {
        mesh: Mesh {
            positions: (0..n)
                .map(|i| {
                    let x = f64::from(i / 2) * 0.001;
                    [ORIGIN[0] + x, ORIGIN[1] + f64::from(i % 2), ORIGIN[2]]
                })
                .collect(),
            colours: vec![[90, 120, 60]; n as usize],
            triangles: (0..n - 2)
                .map(|i| {
                    if i % 2 == 0 {
                        [i, i + 2, i + 1]
                    } else {
                        [i, i + 1, i + 2]
                    }
                })
                .collect(),
        },
        lighting: Lighting::Lit,
        drape: None,
    }
}

#[test]
fn indices_are_32_bit_from_index_65535() {
    for (n, want) in [(65_535, UNSIGNED_SHORT), (65_536, UNSIGNED_INT)] {
        let part = strip(n);
        let glb = write_glb(std::slice::from_ref(&part), ORIGIN).unwrap();
        let root = json_of(&glb);
        let i = root["meshes"][0]["primitives"][0]["indices"]
            .as_u64()
            .unwrap() as usize;
        assert_eq!(
            root["accessors"][i]["componentType"],
            json!(want),
            "{n} vertices"
        );
        let view = root["accessors"][i]["bufferView"].as_u64().unwrap() as usize;
        assert_eq!(
            root["bufferViews"][view]["target"],
            json!(ELEMENT_ARRAY_BUFFER)
        );
        let back = read_glb(&glb, ORIGIN).unwrap();
        assert_eq!(back[0].mesh.triangles, part.mesh.triangles);
    }
}

#[test]
fn no_triangle_is_an_error_and_empty_parts_are_left_out() {
    let empty = Part {
        mesh: Mesh {
            positions: vec![ORIGIN],
            colours: vec![[0; 3]],
            triangles: vec![],
        },
        lighting: Lighting::Unlit,
        drape: None,
    };
    for parts in [vec![], vec![empty.clone()]] {
        let e = write_glb(&parts, ORIGIN).unwrap_err().to_string();
        assert!(e.contains("at least one triangle"), "{e}");
    }
    let lit = grid(3, 3, (1.0, 1.0), [0.0; 3], hill, Lighting::Lit);
    let glb = write_glb(&[empty, lit.clone()], ORIGIN).unwrap();
    let root = json_of(&glb);
    // Only the material used, and no unlit extension.
    assert_eq!(root["materials"].as_array().unwrap().len(), 1);
    assert_eq!(root["materials"][0]["name"], json!("lit"));
    assert_eq!(root["extensionsUsed"], json!([QUANTIZATION]));
    assert_eq!(read_glb(&glb, ORIGIN).unwrap().len(), 1);
}

#[test]
fn a_mesh_breaking_the_invariant_is_an_error() {
    let good = grid(3, 3, (1.0, 1.0), [0.0; 3], hill, Lighting::Lit);
    let mut few_colours = good.clone();
    few_colours.mesh.colours.pop();
    let mut far_index = good.clone();
    far_index.mesh.triangles.push([0, 1, 9]);
    let mut nan = good.clone();
    nan.mesh.positions[4][2] = f64::NAN;
    for (bad, want) in [
        (few_colours, "8 colours for 9 positions"),
        (far_index, "past the 9 positions"),
        (nan, "not finite"),
    ] {
        let e = write_glb(&[good.clone(), bad], ORIGIN)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("glTF part 1: ") && e.contains(want), "{e}");
    }
}

#[test]
fn the_same_parts_give_the_same_bytes() {
    let parts = [
        grid(20, 20, (30.0, 30.0), [0.0; 3], hill, Lighting::Lit),
        grid(4, 4, (3.0, 3.0), [5.0, 5.0, 2.0], hill, Lighting::Unlit),
    ];
    assert_eq!(
        write_glb(&parts, ORIGIN).unwrap(),
        write_glb(&parts, ORIGIN).unwrap()
    );
}

#[test]
fn the_container_follows_the_glb_layout() {
    let parts = [grid(3, 2, (1.0, 1.0), [0.0; 3], hill, Lighting::Unlit)];
    let glb = write_glb(&parts, ORIGIN).unwrap();
    assert_eq!(&glb[..4], b"glTF");
    assert_eq!(u32::from_le_bytes(glb[4..8].try_into().unwrap()), 2);
    assert_eq!(
        u32::from_le_bytes(glb[8..12].try_into().unwrap()) as usize,
        glb.len()
    );
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    assert_eq!(&glb[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let json = std::str::from_utf8(&glb[20..20 + json_len]).unwrap();
    assert!(json.starts_with('{'), "{json}");
    assert!(json.trim_end().ends_with('}') && json.trim_end_matches(' ').ends_with('}'));
    let bin = 20 + json_len;
    assert_eq!(&glb[bin + 4..bin + 8], b"BIN\0");
    assert_eq!(
        u32::from_le_bytes(glb[bin..bin + 4].try_into().unwrap()) % 4,
        0
    );
    let root = json_of(&glb);
    assert_eq!(root["asset"]["version"], json!("2.0"));
    assert_eq!(
        root["asset"]["generator"],
        json!(format!("dbms {}", env!("CARGO_PKG_VERSION")))
    );
    let m = &root["materials"][0];
    assert_eq!(m["name"], json!("unlit"));
    assert_eq!(m["extensions"], json!({ UNLIT: {} }));
    assert_eq!(m["pbrMetallicRoughness"]["metallicFactor"], json!(0.0));
    assert_eq!(m["pbrMetallicRoughness"]["roughnessFactor"], json!(1.0));
    let p = &root["meshes"][0]["primitives"][0];
    assert_eq!(p["mode"], json!(4));
    assert_eq!(
        p["attributes"].as_object().unwrap().len(),
        2,
        "no NORMAL: {p}"
    );
    let c = &root["accessors"][p["attributes"]["COLOR_0"].as_u64().unwrap() as usize];
    assert_eq!(
        (&c["componentType"], &c["type"], &c["normalized"]),
        (&json!(UNSIGNED_SHORT), &json!("VEC4"), &json!(true))
    );
}

#[test]
fn truncated_or_corrupted_bytes_are_errors_not_panics() {
    let parts = [
        grid(3, 3, (2.0, 2.0), [0.0; 3], hill, Lighting::Unlit),
        grid(2, 2, (1.0, 1.0), [0.0; 3], hill, Lighting::Lit),
    ];
    let glb = write_glb(&parts, ORIGIN).unwrap();
    for n in 0..glb.len() {
        let e = read_glb(&glb[..n], ORIGIN).unwrap_err();
        assert!(e.problem.starts_with("glTF binary: "), "{e}");
    }
    // Every byte flipped in turn: some flips still decode (a colour, a position), none panics.
    for i in 0..glb.len() {
        for mask in [0x01, 0x80, 0xFF] {
            let mut bad = glb.clone();
            bad[i] ^= mask;
            let _ = read_glb(&bad, ORIGIN);
        }
    }
}

#[test]
fn read_refuses_a_non_glb_and_features_it_does_not_read() {
    for junk in [
        &b""[..],
        b"hello",
        b"{\"asset\":{\"version\":\"2.0\"}}",
        &[0u8; 64],
    ] {
        let e = read_glb(junk, ORIGIN).unwrap_err().to_string();
        assert!(e.contains("not a glTF binary"), "{e}");
    }
    let glb = write_glb(
        &[grid(3, 3, (2.0, 2.0), [0.0; 3], hill, Lighting::Lit)],
        ORIGIN,
    )
    .unwrap();
    let refused = |edit: fn(&mut Value), want: &str| {
        let e = read_glb(&edited(&glb, edit), ORIGIN)
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{want}: {e}");
    };
    refused(|r| r["animations"] = json!([]), "animations");
    refused(
        |r| r["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]),
        "draco",
    );
    refused(
        |r| r["extensionsRequired"] = json!([]),
        "16-bit positions without",
    );
    refused(
        |r| r["meshes"][0]["primitives"][0]["mode"] = json!(1),
        "mode",
    );
    refused(
        |r| r["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = json!(0),
        "NORMAL",
    );
    refused(
        |r| r["nodes"][0]["rotation"] = json!([0, 0, 0, 1]),
        "rotation",
    );
    refused(
        |r| r["accessors"][0]["count"] = json!(1u64 << 40),
        "not within",
    );
    refused(|r| r["accessors"][2]["count"] = json!(4), "whole triangles");
    refused(
        |r| r["bufferViews"][1]["byteOffset"] = json!(u64::MAX),
        "not within",
    );
    refused(
        |r| r["buffers"][0]["byteLength"] = json!(1 << 30),
        "byteLength",
    );
    refused(|r| r["asset"]["version"] = json!("1.0"), "asset version");
}

/// A draped part comes back with its image, texture coordinates and colours as written, its
/// positions within half a step; beside an undraped part, each keeps its own material.
#[test]
fn a_draped_part_reads_back_with_its_image() {
    let terrain = draped(
        grid(30, 20, (60.0, 40.0), [0.0; 3], hill, Lighting::Unlit),
        7,
        5,
    );
    let roof = grid(
        3,
        3,
        (6.0, 6.0),
        [10.0, 10.0, 15.0],
        |_, _| 0.0,
        Lighting::Lit,
    );
    let parts = vec![terrain, roof];
    let glb = write_glb(&parts, ORIGIN).unwrap();
    let root = json_of(&glb);
    assert_eq!(root["images"][0]["mimeType"], json!("image/png"));
    assert_eq!(root["materials"].as_array().unwrap().len(), 2);
    assert!(root["meshes"][0]["primitives"][0]["attributes"]
        .get("COLOR_0")
        .is_none());
    let back = read_glb(&glb, ORIGIN).unwrap();
    assert_close(&parts, &back, half_steps([60.0, 40.0 + 15.0 - 0.0, 50.0]));
    assert_eq!(back[0].drape, parts[0].drape);
    assert_eq!(back[0].mesh.colours, parts[0].mesh.colours);
    assert_eq!(back[1].drape, None);
    assert_eq!(back[1].lighting, Lighting::Lit);
}

/// A drape that breaks its invariant is an error naming the problem, never a panic.
#[test]
fn a_drape_breaking_its_invariant_is_an_error() {
    let good = draped(
        grid(3, 3, (6.0, 6.0), [0.0; 3], hill, Lighting::Unlit),
        2,
        2,
    );
    let mut short = good.clone();
    short.drape.as_mut().unwrap().uv.pop();
    let mut texels = good.clone();
    texels.drape.as_mut().unwrap().texels.pop();
    let mut nan = good.clone();
    nan.drape.as_mut().unwrap().uv[0][1] = f32::NAN;
    for (part, says) in [
        (short, "texture coordinates"),
        (texels, "texels"),
        (nan, "not finite"),
    ] {
        let e = write_glb(&[part], ORIGIN).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
}

/// Writes sample files and runs `samples/web/validate-gltf.mjs` on them: the Khronos validator
/// must find no error and no warning, and must fail a broken file. Needs Node and
/// `npm ci` in samples/web: `cargo test --lib mesh::gltf -- --ignored`.
#[test]
#[ignore = "needs node and `npm ci` in samples/web"]
fn the_khronos_validator_passes_every_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, parts: &[Part]| {
        std::fs::write(dir.path().join(name), write_glb(parts, ORIGIN).unwrap()).unwrap();
    };
    let terrain = |size: f64, lighting| grid(60, 50, (size, size * 0.8), [0.0; 3], hill, lighting);
    let roof = grid(
        4,
        4,
        (6.0, 6.0),
        [10.0, 10.0, 15.0],
        |_, _| 0.0,
        Lighting::Lit,
    );
    write("quantised-unlit.glb", &[terrain(60.0, Lighting::Unlit)]);
    write(
        "quantised-both.glb",
        &[terrain(60.0, Lighting::Unlit), roof.clone()],
    );
    write("float-lit.glb", &[terrain(200.0, Lighting::Lit)]);
    write(
        "float-both.glb",
        &[roof.clone(), terrain(200.0, Lighting::Unlit)],
    );
    write(
        "draped.glb",
        &[draped(terrain(60.0, Lighting::Unlit), 17, 13), roof],
    );
    write(
        "flat.glb",
        &[grid(
            9,
            9,
            (50.0, 50.0),
            [0.0; 3],
            |_, _| 0.0,
            Lighting::Unlit,
        )],
    );
    std::fs::create_dir(dir.path().join("big")).unwrap();
    let big = grid(300, 300, (100.0, 100.0), [0.0; 3], hill, Lighting::Unlit);
    write("big/u32-indices.glb", &[big, strip(65_535)]);

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/web/validate-gltf.mjs");
    let run = |dir: &Path| {
        let out = std::process::Command::new("node")
            .arg(&script)
            .arg(dir)
            .output()
            .expect("node runs");
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        eprintln!("{text}");
        (out.status.code(), text)
    };
    let (code, text) = run(dir.path());
    assert_eq!(code, Some(0), "{text}");
    assert_eq!(
        text.lines()
            .filter(|l| l.contains("0 errors, 0 warnings"))
            .count(),
        7
    );

    let broken = tempfile::tempdir().unwrap();
    let glb = write_glb(&[strip(10)], ORIGIN).unwrap();
    let bad = edited(&glb, |r| r["accessors"][0]["max"][0] = json!(1.0));
    std::fs::write(broken.path().join("wrong-max.glb"), bad).unwrap();
    assert_eq!(run(broken.path()).0, Some(1));
    let empty = tempfile::tempdir().unwrap();
    assert_eq!(run(empty.path()).0, Some(1));
}
