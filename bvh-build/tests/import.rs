//! Scene import: OBJ + MTL, glTF node transforms, scene descriptions, malformed inputs, and the
//! shipped scene descriptions.

use bvh_build::Scene;
use bvh_build::import::{ImportError, ImportOptions, defaults, load};
use glam::Vec3;
use std::path::{Path, PathBuf};
use tests::Scratch;

/// A fresh directory for one test, removed when the test ends (pass or fail: a panic unwinds
/// through the drop).
fn temp_dir(tag: &str) -> Scratch {
    Scratch::new(&format!("import-{tag}"))
}

fn write(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn opts() -> ImportOptions {
    ImportOptions::default()
}

fn assert_unit_normals(s: &Scene) {
    assert_eq!(s.normals.len(), s.positions.len());
    assert_eq!(s.material_ids.len(), s.positions.len());
    for (t, n) in s.normals.iter().enumerate() {
        for v in n {
            assert!(v.is_finite() && (v.length() - 1.0).abs() < 1e-4, "triangle {t}: normal {v}");
        }
    }
    for &m in &s.material_ids {
        assert!((m as usize) < s.materials.len());
    }
    assert_eq!(s.materials.len(), s.material_names.len());
    for m in &s.materials {
        assert!(!(m.kr > 0.0 && m.kt > 0.0));
        assert!((0.0..=1.0).contains(&m.kr) && (0.0..=1.0).contains(&m.kt) && m.ior > 0.0);
    }
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-4
}

fn material<'a>(s: &'a Scene, name: &str) -> &'a bvh_format::Material {
    let i = s.material_names.iter().position(|n| n == name).unwrap_or_else(|| panic!("no material {name}"));
    &s.materials[i]
}

// ---------------------------------------------------------------------------------------------
// OBJ

const MTL: &str = "\
newmtl red
Kd 0.8 0.1 0.1
Ks 0.2 0.2 0.2
Ns 20
illum 2

newmtl mirror
Kd 0 0 0
Ks 0.9 0.9 0.9
illum 3

newmtl glass
Kd 0.1 0.1 0.1
d 0.25
Ni 1.45
illum 4
";

const OBJ: &str = "\
mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0.5 1.5 0
vn 0 0 1
o loose
f 1 2 3
o quad
usemtl red
f 1/ 2 3 4
o pentagon
usemtl mirror
f 1//1 2//1 3//1 5//1 4//1
o single
usemtl glass
f 2 3 4
";

#[test]
fn obj_with_mtl_triangulates_and_maps_materials() {
    let dir = temp_dir("obj");
    write(&dir, "scene.mtl", MTL);
    let path = write(&dir, "scene.obj", OBJ.replace("f 1/ 2", "f 1 2"));
    let s = load(&path, &opts()).unwrap();
    // 1 triangle, a quad as 2, a pentagon as 3, 1 triangle: in file order.
    assert_eq!(s.triangle_count(), 7);
    assert_unit_normals(&s);
    let names: Vec<&str> = s.material_ids.iter().map(|&m| s.material_names[m as usize].as_str()).collect();
    assert_eq!(names, ["default", "red", "red", "mirror", "mirror", "mirror", "glass"]);
    assert_eq!(s.positions[0], [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]);
    // The quad's two triangles cover it.
    let area: f32 = s.positions[1..3].iter().map(|p| (p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0).sum();
    assert!((area - 1.0).abs() < 1e-6);
    // Flat normals without vn, the file's normals with vn.
    assert_eq!(s.normals[1], [Vec3::Z; 3]);
    assert_eq!(s.normals[4], [Vec3::Z; 3]);

    let red = material(&s, "red");
    assert_eq!((red.kd, red.ks, red.shininess, red.kr, red.kt), ([0.8, 0.1, 0.1], [0.2; 3], 20.0, 0.0, 0.0));
    let mirror = material(&s, "mirror");
    assert!((mirror.kr - 0.9).abs() < 1e-6 && mirror.kt == 0.0);
    let glass = material(&s, "glass");
    assert_eq!((glass.kt, glass.ior, glass.kr), (0.75, 1.45, 0.0));
    let default = material(&s, "default");
    assert_eq!(*default, bvh_format::Material::default());

    // A file's scene gets the default cameras and light, and indirections for its mirror.
    let names: Vec<_> = s.cameras.iter().map(|c| c.name().unwrap()).collect();
    assert_eq!(names, defaults::CAMERA_NAMES);
    assert_eq!(s.lights.len(), 1);
    assert_eq!(s.settings.max_indirections, 2);
    bvh_build::compile(&s, &Default::default(), Default::default()).unwrap();
}

#[test]
fn obj_smooth_normals_average_over_shared_vertices() {
    let dir = temp_dir("smooth");
    // A roof: two slopes meeting at a ridge along x (vertices 3 and 4).
    let path = write(
        &dir,
        "roof.obj",
        "v 0 0 0\nv 1 0 0\nv 1 1 1\nv 0 1 1\nv 0 0 2\nv 1 0 2\nf 1 3 2\nf 1 4 3\nf 4 6 3\nf 4 5 6\n",
    );
    let (front, back) = (Vec3::new(0.0, 1.0, -1.0).normalize(), Vec3::new(0.0, 1.0, 1.0).normalize());
    let flat = load(&path, &opts()).unwrap();
    assert_unit_normals(&flat);
    assert_eq!(flat.normals.iter().map(|n| n[0]).collect::<Vec<_>>().len(), 4);
    assert!(close(flat.normals[0][1], front) && close(flat.normals[2][2], back));
    let smooth = load(&path, &ImportOptions { smooth_normals: true }).unwrap();
    assert_unit_normals(&smooth);
    // Ridge vertex 3 lies in two front triangles and one back triangle, all of equal area.
    assert!(close(smooth.normals[0][1], Vec3::new(0.0, 3.0, -1.0).normalize()));
    assert!(close(smooth.normals[2][2], Vec3::new(0.0, 3.0, -1.0).normalize()));
    // Vertex 2 belongs to the front slope only.
    assert!(close(smooth.normals[0][2], front));
}

#[test]
fn zero_area_triangles_get_finite_unit_normals() {
    let dir = temp_dir("degenerate");
    let path = write(&dir, "d.obj", "v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\nf 1 1 1\n");
    for smooth in [false, true] {
        let s = load(&path, &ImportOptions { smooth_normals: smooth }).unwrap();
        assert_unit_normals(&s);
    }
}

#[test]
fn obj_nan_vertex_names_file_and_vertex() {
    let dir = temp_dir("nan");
    let path = write(&dir, "bad.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
    let e = load(&path, &opts()).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ImportError::NonFinite { .. }), "{msg}");
    assert!(msg.contains("bad.obj") && msg.contains("vertex 2") && msg.contains("line 2"), "{msg}");
    let path = write(&dir, "inf.obj", "v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n");
    let msg = load(&path, &opts()).unwrap_err().to_string();
    assert!(msg.contains("inf.obj") && msg.contains("vertex 3"), "{msg}");
}

#[test]
fn malformed_obj_inputs_are_errors() {
    let dir = temp_dir("badobj");
    let cases: &[(&str, &str)] = &[
        ("index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
        ("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"),
        ("negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -7\n"),
        ("garbage.obj", "v a b c\nf 1 2 3\n"),
        ("face.obj", "v 0 0 0\nf 1/x 2 3\n"),
        ("huge.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/9223372036854775806 2/1 3/1\n"),
        ("empty.obj", ""),
        ("points.obj", "v 0 0 0\nv 1 0 0\np 1\nl 1 2\n"),
        ("binary.obj", "\u{0}\u{1}\u{2}\u{ff}"),
    ];
    for (name, text) in cases {
        let path = write(&dir, name, text);
        let r = load(&path, &opts());
        assert!(r.is_err(), "{name} loaded");
        let msg = r.unwrap_err().to_string();
        assert!(msg.contains(name), "{name}: {msg}");
    }
}

#[test]
fn obj_errors_carry_line_numbers_and_short_faces_are_counted() {
    let dir = temp_dir("objlines");
    for (name, text, needle) in [
        ("index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n# c\nf 1 2 9\n", "line 5"),
        ("corner.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n", "line 4"),
        ("coord.obj", "v 0 0 0\nv 1 zero 0\n", "line 2"),
    ] {
        let msg = load(&write(&dir, name, text), &opts()).unwrap_err().to_string();
        assert!(msg.contains(name) && msg.contains(needle), "{name}: {msg}");
    }
    let path = write(&dir, "two.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\nf 2 3\nf 1 2 3\n");
    let s = load(&path, &opts()).unwrap();
    assert_eq!(s.triangle_count(), 1);
    assert_eq!(s.warnings.len(), 1);
    assert!(s.warnings[0].contains("two.obj") && s.warnings[0].contains("2 faces"), "{:?}", s.warnings);
}

#[test]
fn obj_material_library_problems_are_errors() {
    let dir = temp_dir("mtl");
    let path = write(&dir, "a.obj", "mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let msg = load(&path, &opts()).unwrap_err().to_string();
    assert!(msg.contains("a.obj") && msg.contains("missing.mtl"), "{msg}");
    write(&dir, "short.mtl", "newmtl x\nKd 0.5 0.5\n");
    let path = write(&dir, "b.obj", "mtllib short.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n");
    let msg = load(&path, &opts()).unwrap_err().to_string();
    assert!(msg.contains("short.mtl") && msg.contains("line 2"), "{msg}");
    // A single value is a grey the MTL specification allows.
    write(&dir, "grey.mtl", "newmtl x\nKd 0.5\n");
    let path = write(&dir, "c.obj", "mtllib grey.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n");
    assert_eq!(material(&load(&path, &opts()).unwrap(), "x").kd, [0.5; 3]);
}

#[test]
fn unreadable_and_unsupported_files_are_errors() {
    let dir = temp_dir("misc");
    let e = load(&dir.join("nothing.obj"), &opts()).unwrap_err();
    assert!(matches!(e, ImportError::Read { .. }) && e.to_string().contains("nothing.obj"));
    let path = write(&dir, "scene.ply", "ply\n");
    let e = load(&path, &opts()).unwrap_err();
    assert!(matches!(e, ImportError::UnsupportedExtension { .. }) && e.to_string().contains("scene.ply"));
    let path = write(&dir, "noext", "");
    assert!(matches!(load(&path, &opts()), Err(ImportError::UnsupportedExtension { .. })));
}

// ---------------------------------------------------------------------------------------------
// glTF

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n =
            (u32::from(c[0]) << 16) | (u32::from(*c.get(1).unwrap_or(&0)) << 8) | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A glTF with one mesh (positions, u32 indices, optional normals) and the given nodes, scene
/// node list and materials (JSON fragments).
fn gltf(
    positions: &[[f32; 3]],
    indices: &[u32],
    normals: Option<&[[f32; 3]]>,
    nodes: &str,
    scene: &str,
    extra: &str,
) -> String {
    let mut buf = Vec::new();
    for p in positions {
        p.iter().for_each(|v| buf.extend(v.to_le_bytes()));
    }
    let pos_len = buf.len();
    indices.iter().for_each(|i| buf.extend(i.to_le_bytes()));
    let idx_len = buf.len() - pos_len;
    if let Some(n) = normals {
        for p in n {
            p.iter().for_each(|v| buf.extend(v.to_le_bytes()));
        }
    }
    let nrm_len = buf.len() - pos_len - idx_len;
    let normal_attr = if normals.is_some() { r#", "NORMAL": 2"# } else { "" };
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "buffers": [{{"byteLength": {len}, "uri": "data:application/octet-stream;base64,{data}"}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {pos_len}}},
    {{"buffer": 0, "byteOffset": {pos_len}, "byteLength": {idx_len}}},
    {{"buffer": 0, "byteOffset": {nrm_off}, "byteLength": {nrm_len_or_1}}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {np}, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5125, "count": {ni}, "type": "SCALAR"}},
    {{"bufferView": 2, "componentType": 5126, "count": {nn}, "type": "VEC3"}}
  ],
  "meshes": [{{"name": "m", "primitives": [{{"attributes": {{"POSITION": 0{normal_attr}}}, "indices": 1, "material": 0}}]}}],
  "materials": [{{"name": "mat", "pbrMetallicRoughness": {{"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0}}}}],
  "nodes": [{nodes}],
  "scenes": [{{"nodes": [{scene}]}}],
  "scene": 0
  {extra}
}}"#,
        len = buf.len(),
        data = base64(&buf),
        nrm_off = pos_len + idx_len,
        nrm_len_or_1 = nrm_len.max(1),
        np = positions.len(),
        ni = indices.len(),
        nn = normals.map_or(1, |n| n.len()),
    )
}

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

#[test]
fn gltf_node_transforms_compose_down_the_tree() {
    let dir = temp_dir("gltf");
    // Node 0: translate (10, 0, 0), children 1 and 2.
    // Node 1: scale 2 with the mesh.
    // Node 2: rotate 90 degrees about z (TRS), child 3.
    // Node 3: matrix translating by (0, 0, 5), with the mesh.
    // Node 4: the mesh, not in the scene.
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let nodes = format!(
        r#"{{"translation": [10, 0, 0], "children": [1, 2]}},
           {{"scale": [2, 2, 2], "mesh": 0}},
           {{"rotation": [0, 0, {s}, {s}], "children": [3]}},
           {{"matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,5,1], "mesh": 0}},
           {{"mesh": 0}}"#
    );
    let path = write(&dir, "t.gltf", gltf(&TRI, &[0, 1, 2], None, &nodes, "0", ""));
    let sc = load(&path, &opts()).unwrap();
    assert_unit_normals(&sc);
    assert_eq!(sc.triangle_count(), 2);
    let [a, b, c] = sc.positions[0];
    assert!(
        close(a, Vec3::new(10.0, 0.0, 0.0))
            && close(b, Vec3::new(12.0, 0.0, 0.0))
            && close(c, Vec3::new(10.0, 2.0, 0.0))
    );
    let [a, b, c] = sc.positions[1];
    // Translate(10) * Rz(90) * Translate(0, 0, 5): x -> y, y -> -x.
    assert!(close(a, Vec3::new(10.0, 0.0, 5.0)), "{a}");
    assert!(close(b, Vec3::new(10.0, 1.0, 5.0)), "{b}");
    assert!(close(c, Vec3::new(9.0, 0.0, 5.0)), "{c}");
    assert!(close(sc.normals[1][0], Vec3::Z));
    assert_eq!(material(&sc, "mat").kd, [0.5; 3]);
}

#[test]
fn gltf_normals_use_the_inverse_transpose_and_mirrors_flip_winding() {
    let dir = temp_dir("gltfn");
    let n = Vec3::new(1.0, 1.0, 0.0).normalize().to_array();
    let nodes = r#"{"scale": [1, 4, 1], "mesh": 0}, {"scale": [-1, 1, 1], "mesh": 0}"#;
    let path = write(&dir, "n.gltf", gltf(&TRI, &[0, 1, 2], Some(&[n, n, n]), nodes, "0, 1", ""));
    let sc = load(&path, &opts()).unwrap();
    assert_unit_normals(&sc);
    // (1, 1, 0) under diag(1, 4, 1)^-T = diag(1, 1/4, 1): (1, 0.25, 0), normalized.
    assert!(close(sc.normals[0][0], Vec3::new(1.0, 0.25, 0.0).normalize()));
    // Mirrored in x: the normal's x flips, and the triangle swaps two vertices so that its winding
    // (right-hand rule) still agrees with the flat normal +z.
    assert!(close(sc.normals[1][0], Vec3::new(-1.0, 1.0, 0.0).normalize()));
    let [a, b, c] = sc.positions[1];
    assert!((b - a).cross(c - a).z > 0.0);
}

#[test]
fn gltf_without_normals_is_flat_or_smooth() {
    let dir = temp_dir("gltfs");
    // Two triangles folded along the y axis, sharing vertices 0 and 2.
    let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 1.0]];
    let path = write(&dir, "f.gltf", gltf(&p, &[0, 1, 2, 0, 2, 3], None, r#"{"mesh": 0}"#, "0", ""));
    let flat = load(&path, &opts()).unwrap();
    assert_unit_normals(&flat);
    assert_eq!(flat.normals[0][0], flat.normals[0][1]);
    let smooth = load(&path, &ImportOptions { smooth_normals: true }).unwrap();
    assert_unit_normals(&smooth);
    assert!(close(smooth.normals[0][0], Vec3::Z));
    assert!(close(smooth.normals[1][1], Vec3::Z));
}

#[test]
fn gltf_cameras_become_named_cameras_after_the_defaults() {
    let dir = temp_dir("gltfc");
    let nodes = r#"{"mesh": 0}, {"name": "top", "camera": 0, "translation": [0, 0, 10]}"#;
    let extra = r#", "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}]"#;
    let path = write(&dir, "c.gltf", gltf(&TRI, &[0, 1, 2], None, nodes, "0, 1", extra));
    let sc = load(&path, &opts()).unwrap();
    let names: Vec<_> = sc.cameras.iter().map(|c| c.name().unwrap()).collect();
    assert_eq!(names, ["medium", "close-up", "wide", "top"]);
    let top = sc.cameras[3];
    assert_eq!(top.eye, [0.0, 0.0, 10.0]);
    assert!(top.at[2] < 10.0 && (top.fov_deg - 0.5f32.to_degrees()).abs() < 1e-4);
}

#[test]
fn gltf_index_out_of_range_is_an_error() {
    let dir = temp_dir("gltfi");
    let path = write(&dir, "i.gltf", gltf(&TRI, &[0, 1, 7], None, r#"{"mesh": 0}"#, "0", ""));
    let e = load(&path, &opts()).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ImportError::IndexOutOfRange { .. }), "{msg}");
    assert!(msg.contains("i.gltf") && msg.contains("triangle 0") && msg.contains('7'), "{msg}");
}

#[test]
fn gltf_non_finite_positions_name_the_vertex_also_after_transforms() {
    let dir = temp_dir("gltfnan");
    let p = [[0.0, 0.0, 0.0], [1.0, f32::NAN, 0.0], [0.0, 1.0, 0.0]];
    let path = write(&dir, "nan.gltf", gltf(&p, &[0, 1, 2], None, r#"{"mesh": 0}"#, "0", ""));
    let e = load(&path, &opts()).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, ImportError::NonFinite { .. }) && msg.contains("nan.gltf") && msg.contains("vertex 1"),
        "{msg}"
    );

    let p = [[0.0, 0.0, 0.0], [3e38, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let path = write(&dir, "huge.gltf", gltf(&p, &[0, 1, 2], None, r#"{"scale": [10, 10, 10], "mesh": 0}"#, "0", ""));
    let e = load(&path, &opts()).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ImportError::NonFinite { .. }), "{msg}");
    assert!(msg.contains("huge.gltf") && msg.contains("vertex 1") && msg.contains("transform"), "{msg}");
}

#[test]
fn malformed_gltf_inputs_are_errors() {
    let dir = temp_dir("badgltf");
    let good = gltf(&TRI, &[0, 1, 2], None, r#"{"mesh": 0}"#, "0", "");
    let cases: Vec<(&str, String)> = vec![
        ("json.gltf", "{ not json".to_owned()),
        ("empty.gltf", String::new()),
        ("truncated.glb", "glTF\u{2}\u{0}\u{0}\u{0}".to_owned()),
        ("nomesh.gltf", r#"{"asset": {"version": "2.0"}}"#.to_owned()),
        ("past_end.gltf", good.replace(r#""count": 3, "type": "VEC3""#, r#""count": 300, "type": "VEC3""#)),
        ("zero_count.gltf", good.replace(r#""count": 3, "type": "SCALAR""#, r#""count": 0, "type": "SCALAR""#)),
        ("wrong_type.gltf", good.replacen(r#""type": "VEC3""#, r#""type": "VEC2""#, 1)),
        ("bad_index_type.gltf", good.replace("5125", "5126")),
        ("cycle.gltf", good.replace(r#""nodes": [{"mesh": 0}]"#, r#""nodes": [{"mesh": 0, "children": [0]}]"#)),
        ("bad_ref.gltf", good.replace(r#""mesh": 0}"#, r#""mesh": 5}"#)),
        ("missing_bin.gltf", good.replace("data:application/octet-stream;base64,", "missing.bin#")),
        ("zero_quat.gltf", good.replace(r#"{"mesh": 0}"#, r#"{"mesh": 0, "rotation": [0, 0, 0, 0]}"#)),
    ];
    for (name, text) in cases {
        let path = write(&dir, name, &text);
        match load(&path, &opts()) {
            Ok(_) => panic!("{name} loaded"),
            Err(e) => assert!(e.to_string().contains(name), "{name}: {e}"),
        }
    }
    // A missing buffer file is named.
    let msg = load(&dir.join("missing_bin.gltf"), &opts()).unwrap_err().to_string();
    assert!(msg.contains("missing.bin") && msg.contains("buffer 0"), "{msg}");
}

#[test]
fn load_bytes_reads_referenced_files_through_the_callers_reader() {
    // A glTF whose buffer is an external file, served from memory; and the same with a short
    // file, a percent escape that is not UTF-8 (the gltf crate's loader panics on it) and a GLB
    // buffer without a binary chunk.
    let embedded = gltf(&TRI, &[0, 1, 2], None, r#"{"mesh": 0}"#, "0", "");
    let start = embedded.find("data:").unwrap();
    let end = start + embedded[start..].find('"').unwrap();
    let payload: Vec<u8> = {
        // Decode the test's own base64 back into bytes.
        let a = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let digits: Vec<u32> = embedded[start..end]
            .split(',')
            .nth(1)
            .unwrap()
            .bytes()
            .filter(|&c| c != b'=')
            .map(|c| a.iter().position(|&x| x == c).unwrap() as u32)
            .collect();
        let mut out = Vec::new();
        for q in digits.chunks(4) {
            let n = q.iter().enumerate().fold(0, |n, (k, &d)| n | d << (18 - 6 * k));
            out.extend(&n.to_be_bytes()[1..q.len()]);
        }
        out
    };
    let external = |uri: &str| format!("{}{uri}{}", &embedded[..start], &embedded[end..]);
    let served = |bytes: Vec<u8>| {
        move |p: &Path| {
            assert_eq!(p, Path::new("models/mesh data.bin"), "the buffer is looked up beside the glTF file");
            Ok(bytes.clone())
        }
    };
    let load_with = |text: &str, read: &dyn Fn(&Path) -> std::io::Result<Vec<u8>>| {
        bvh_build::import::load_bytes(Path::new("models/a.gltf"), text.as_bytes(), &opts(), read)
    };
    let s = load_with(&external("mesh%20data.bin"), &served(payload.clone())).unwrap();
    assert_eq!(s.positions, vec![TRI.map(Vec3::from)]);
    let msg = load_with(&external("mesh%20data.bin"), &served(payload[..10].to_vec())).unwrap_err().to_string();
    assert!(msg.contains("buffer 0 holds 10 bytes, fewer than the"), "{msg}");
    let refuse = |_: &Path| Err(std::io::Error::other("no files here"));
    let msg = load_with(&external("%FF%FE.bin"), &refuse).unwrap_err().to_string();
    assert!(
        msg.contains("models/a.gltf") && msg.contains("buffer 0 refers to") && msg.contains("no files here"),
        "{msg}"
    );
    let no_chunk = embedded.replace(&embedded[start - 10..end + 1], "");
    assert!(!no_chunk.contains("uri"), "{no_chunk}");
    let msg = load_with(&no_chunk, &refuse).unwrap_err().to_string();
    assert!(msg.contains("buffer 0 refers to a binary chunk that the file does not have"), "{msg}");
}

// ---------------------------------------------------------------------------------------------
// Scene descriptions

fn description(dir: &Path, text: &str) -> Result<Scene, ImportError> {
    load(&write(dir, "scene.toml", text), &opts())
}

#[test]
fn description_places_meshes_and_shapes_in_file_order() {
    let dir = temp_dir("desc");
    write(&dir, "scene.mtl", MTL);
    write(&dir, "tri.obj", "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl glass\nf 1 2 3\n");
    let text = r#"
indirections = 3
ambient = [0.1, 0.1, 0.1]
background = [0.2, 0.3, 0.4]

[material.floor]
kd = [0.5, 0.5, 0.5]
kr = 0.2

[material.water]
kt = 0.8
ior = 1.33

[[object]]
type = "quad"
centre = [0, -1, 0]
size = [10, 10]
material = "floor"
frame = false

[[object]]
type = "mesh"
file = "tri.obj"
scale = 2
rotate = [0, 0, 90]
translate = [1, 0, 0]

[[object]]
type = "mesh"
file = "tri.obj"
overrides = { glass = "water" }
axis = [0, 1, 0]
angle = 180
scale = [1, 3, 1]

[[object]]
type = "sphere"
radius = 0.5
segments = 8
rings = 4

[[object]]
type = "box"
center = [0, 0, 5]
size = [1, 1, 1]
material = "floor"

[[object]]
type = "torus"
major = 2
minor = 0.5
segments = 10
sides = 6

[[light]]
position = [0, 10, 0]
color = [0.5, 0.5, 0.5]
"#;
    let s = description(&dir, text).unwrap();
    assert_unit_normals(&s);
    assert_eq!(s.triangle_count(), 2 + 1 + 1 + 2 * 8 * 3 + 12 + 2 * 10 * 6);
    // Object 2: scaled by 2, rotated 90 degrees about z (x -> y), moved by (1, 0, 0).
    let [a, b, c] = s.positions[2];
    assert!(
        close(a, Vec3::new(1.0, 0.0, 0.0)) && close(b, Vec3::new(1.0, 2.0, 0.0)) && close(c, Vec3::new(-1.0, 0.0, 0.0))
    );
    // Object 3: scaled (1, 3, 1), then half a turn about y (x -> -x); the winding is kept.
    let [a, b, c] = s.positions[3];
    assert!(
        close(a, Vec3::ZERO) && close(b, Vec3::new(-1.0, 0.0, 0.0)) && close(c, Vec3::new(0.0, 3.0, 0.0)),
        "{a} {b} {c}"
    );
    assert!(close(s.normals[3][0], Vec3::NEG_Z));
    let name = |t: usize| s.material_names[s.material_ids[t] as usize].as_str();
    assert_eq!(
        [name(0), name(1), name(2), name(3), name(4), name(53)],
        ["floor", "floor", "glass", "water", "default", "floor"]
    );
    assert_eq!(material(&s, "water").kt, 0.8);
    assert_eq!(material(&s, "glass").kt, 0.75);
    // Materials used twice appear once.
    assert_eq!(s.material_names.iter().filter(|n| *n == "floor").count(), 1);
    assert_eq!(
        (s.settings.max_indirections, s.settings.ambient, s.settings.background),
        (3, [0.1; 3], [0.2, 0.3, 0.4])
    );
    assert_eq!(s.lights.len(), 1);
    assert_eq!(s.lights[0].colour, [0.5; 3]);
    // Default cameras frame everything but the floor.
    let framed_hi = s.positions[2..].iter().flatten().fold(Vec3::MIN, |m, &p| m.max(p));
    let framed_lo = s.positions[2..].iter().flatten().fold(Vec3::MAX, |m, &p| m.min(p));
    assert_eq!(s.cameras, defaults::cameras(framed_lo, framed_hi));
    bvh_build::compile(&s, &Default::default(), Default::default()).unwrap();
}

#[test]
fn description_cameras_and_defaults_combine() {
    let dir = temp_dir("cams");
    let s = description(
        &dir,
        r#"
[[object]]
type = "box"
size = [2, 2, 2]

[[camera]]
name = "front"
eye = [0, 0, 10]
at = [0, 0, 0]
fov = 30
"#,
    )
    .unwrap();
    assert_eq!(s.cameras.len(), 1);
    assert_eq!(s.cameras[0].name(), Some("front"));
    assert_eq!(s.cameras[0].fov_deg, 30.0);
    // The default light is placed from the first camera (the default view), beside and above it.
    assert_eq!(s.lights, vec![defaults::light_for(&s.cameras[0], Vec3::splat(-1.0), Vec3::splat(1.0))]);
    assert!(s.lights[0].position[1] > 0.0 && s.lights[0].position[2] > 5.0, "{:?}", s.lights[0]);
}

#[test]
fn the_default_light_of_an_interior_lights_what_its_camera_sees() {
    // A closed box seen from inside (a cathedral in small): a light derived from the bounds
    // alone would stand outside the walls and leave the view black.
    let dir = temp_dir("interior");
    let s = description(
        &dir,
        r#"
[[object]]
type = "box"
size = [10, 6, 20]

[[camera]]
name = "nave"
eye = [0, 2, 8]
at = [0, 2, -8]
"#,
    )
    .unwrap();
    let p = Vec3::from(s.lights[0].position);
    assert!(p.abs().cmplt(Vec3::new(5.0, 3.0, 10.0)).all(), "the light {p} lies outside the box");
    assert!(p.distance(Vec3::new(0.0, 2.0, 8.0)) < 1.0, "the light {p} stands near the eye");
}

#[test]
fn an_unknown_key_is_reported_at_its_own_line() {
    let dir = temp_dir("keyline");
    let text =
        "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n\n[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\ncolour = 3\n";
    let msg = description(&dir, text).unwrap_err().to_string();
    assert!(msg.contains("line 8, object 2") && msg.contains("colour"), "{msg}");
    let msg = description(&dir, "[[object]]\ntype = \"box\"\n\n[[object]]\ntype = \"box\"\n").unwrap_err().to_string();
    assert!(msg.contains("line 1, object 1") && msg.contains("size"), "{msg}");
}

#[test]
fn huge_coordinates_name_the_values_that_overflow() {
    let dir = temp_dir("huge");
    let text = "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\ntranslate = [3e38, 0, 0]\n[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n";
    let msg = description(&dir, text).unwrap_err().to_string();
    assert!(msg.contains("3.000e38") && msg.contains("camera 'medium'") && msg.contains("inf"), "{msg}");
    assert!(!msg.contains("section"), "{msg}");
}

#[test]
fn description_errors_are_clear() {
    let dir = temp_dir("descerr");
    write(&dir, "tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let cases: &[(&str, &str)] = &[
        ("[[object]]\ntype = \"sphere\"\nradus = 1\n", "radus"),
        ("[[object]]\ntype = \"sphre\"\nradius = 1\n", "sphre"),
        ("ambiant = [0, 0, 0]\n", "ambiant"),
        ("[[object]]\ntype = \"sphere\"\nradius = 1\nmaterial = \"nope\"\n", "nope"),
        ("[[object]]\ntype = \"mesh\"\nfile = \"missing.obj\"\n", "missing.obj"),
        ("[[object]]\ntype = \"mesh\"\nfile = \"tri.obj\"\noverrides = { Glass = \"x\" }\n", "Glass"),
        ("[[object]]\ntype = \"mesh\"\nfile = \"scene.toml\"\n", "description"),
        ("[[object]]\ntype = \"sphere\"\nradius = -1\n", "radius"),
        ("[[object]]\ntype = \"torus\"\nmajor = 1\nminor = 2\n", "minor"),
        ("[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\nscale = 0\n", "scale"),
        ("[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\naxis = [0, 1, 0]\n", "angle"),
        ("[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\ntranslate = [inf, 0, 0]\n", "translation"),
        ("[[object]]\ntype = \"sphere\"\nradius = 1\nsegments = 100000\nrings = 100000\n", "triangles"),
        // A sphere at the limit (2 * 2048 * 1024 = 2^22 triangles) after a box's 12.
        (
            "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n[[object]]\ntype = \"sphere\"\nradius = 1\nsegments = 2048\nrings = 1025\n",
            "object 2 (sphere): it would have 4194304 triangles, more than the 4194292 left",
        ),
        // Counts whose triangle count wraps past u64 to under the limit (it used to generate 2^63
        // triangles).
        ("[[object]]\ntype = \"sphere\"\nradius = 1\nsegments = 4294901791\nrings = 2147516402\n", "triangles"),
        (
            "[[object]]\ntype = \"torus\"\nmajor = 2\nminor = 1\nsegments = 4294901791\nsides = 2147516401\n",
            "triangles",
        ),
        ("[material.m]\nkr = 0.5\nkt = 0.5\n", "not both"),
        ("[material.m]\nkt = 1.5\n", "between 0 and 1"),
        (
            "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n[[camera]]\nname = \"c\"\neye = [0, 0, 0]\nat = [0, 0, 0]\n",
            "camera 'c'",
        ),
        (
            "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n[[camera]]\nname = \"a-very-long-camera-name\"\neye = [0, 0, 1]\nat = [0, 0, 0]\n",
            "name",
        ),
        (
            "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n[[light]]\nposition = [0, 0, 0]\ncolour = [-1, 0, 0]\n",
            "light 1",
        ),
        ("indirections = -1\n", "line 1, column 16"),
        ("this is not toml", "line 1"),
        ("", "no triangles"),
    ];
    for (text, needle) in cases {
        let r = description(&dir, text);
        let msg = match r {
            Ok(_) => panic!("loaded: {text}"),
            Err(e) => e.to_string(),
        };
        assert!(msg.contains("scene.toml") || msg.contains("missing.obj"), "{msg}");
        assert!(msg.contains(needle), "expected '{needle}' in: {msg}");
        assert!(!msg.contains('\n'), "not one line: {msg}");
    }
    // A description transform that overflows is reported after the transform.
    let msg =
        description(&dir, "[[object]]\ntype = \"box\"\nsize = [1e30, 1, 1]\nscale = 1e20\n").unwrap_err().to_string();
    assert!(msg.contains("triangle 0") && msg.contains("placement transform"), "{msg}");
}

// ---------------------------------------------------------------------------------------------
// The shipped scenes

fn shipped(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name);
    let s = load(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
    assert_unit_normals(&s);
    s
}

fn camera_names(s: &Scene) -> Vec<&str> {
    s.cameras.iter().map(|c| c.name().unwrap()).collect()
}

const BUNNY: usize = 69_451;
const DRAGON: usize = 871_414;
const TOYCAR: usize = 108_936;

#[test]
fn shipped_bunny_loads() {
    let s = shipped("bunny.toml");
    assert_eq!(s.triangle_count(), BUNNY + 2);
    assert_eq!(camera_names(&s), defaults::CAMERA_NAMES);
    assert_eq!(s.settings.max_indirections, 1);
    assert!(s.materials.iter().any(|m| (m.kr - 0.2).abs() < 1e-6));
}

#[test]
fn shipped_dragon_loads() {
    let s = shipped("dragon.toml");
    assert_eq!(s.triangle_count(), DRAGON + 2);
    assert_eq!(camera_names(&s), defaults::CAMERA_NAMES);
    assert_eq!(s.settings.max_indirections, 1);
}

#[test]
fn shipped_million_loads() {
    let s = shipped("million.toml");
    assert_eq!(s.triangle_count(), DRAGON + 2 * BUNNY + 2);
    assert!(s.triangle_count() > 1_000_000);
    assert_eq!(camera_names(&s), defaults::CAMERA_NAMES);
}

#[test]
fn shipped_car_loads() {
    let s = shipped("car.toml");
    assert_eq!(s.triangle_count(), TOYCAR + 2 + 3 * 2);
    assert_eq!(camera_names(&s), defaults::CAMERA_NAMES);
    assert_eq!(s.settings.max_indirections, 2);
    let glass = material(&s, "car_glass");
    assert!(glass.kt > 0.8 && glass.ior > 1.0);
    assert!(material(&s, "mirror").kr >= 0.8);
    assert!(!s.material_names.iter().any(|n| n == "Glass"), "the Glass override was not applied");
}

#[test]
fn shipped_forest_loads() {
    let s = shipped("forest.toml");
    let env = 2 + 3 * 12 + 3 * 36;
    let rings = 4 * 2 * 128 * 24;
    assert_eq!(s.triangle_count(), env + BUNNY + DRAGON + TOYCAR + rings);
    assert_eq!(camera_names(&s), defaults::CAMERA_NAMES);
    assert_eq!(s.settings.max_indirections, 5);
    let rings: Vec<_> = s.materials.iter().filter(|m| m.kt > 0.0 && m.kt < 0.95).collect();
    assert!(rings.len() >= 2);
}

#[test]
fn documented_example_loads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let doc = std::fs::read_to_string(root.join("docs/scene-description.md")).unwrap();
    let start = doc.find("```toml\n").unwrap() + "```toml\n".len();
    let example = &doc[start..start + doc[start..].find("```").unwrap()];
    let car = root.join("scenes/toycar.glb");
    let text = example.replace("\"toycar.glb\"", &format!("{:?}", car.to_str().unwrap()));
    let s = description(&temp_dir("doc"), &text).unwrap();
    assert_eq!(s.triangle_count(), TOYCAR + 2 + 2 * 48 * 16);
    assert_eq!(camera_names(&s), ["front"]);
    assert_eq!(material(&s, "glass").kt, 0.9);
}

// ---------------------------------------------------------------------------------------------
// No input panics

mod never_panics {
    use super::*;
    use proptest::prelude::*;

    fn obj_line() -> impl Strategy<Value = String> {
        let num = prop_oneof![
            Just("0".to_owned()),
            Just("1".to_owned()),
            Just("-1".to_owned()),
            Just("nan".to_owned()),
            Just("1e39".to_owned()),
            Just("x".to_owned()),
            (-5i64..10).prop_map(|v| v.to_string()),
            Just("9223372036854775807".to_owned()),
        ];
        let nums = proptest::collection::vec(num, 0..6);
        let key = prop_oneof![
            Just("v"),
            Just("vn"),
            Just("vt"),
            Just("f"),
            Just("l"),
            Just("p"),
            Just("o"),
            Just("usemtl"),
            Just("mtllib"),
            Just("s")
        ];
        (key, nums, any::<bool>()).prop_map(|(k, n, slashes)| {
            let sep = if slashes && k == "f" { "/" } else { " " };
            format!("{k} {}", n.join(if sep == "/" { " " } else { sep }))
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 96, failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn random_obj(lines in proptest::collection::vec(obj_line(), 0..24)) {
            let dir = temp_dir("fuzzobj");
            let path = write(&dir, "f.obj", lines.join("\n"));
            if let Ok(s) = load(&path, &opts()) {
                assert_unit_normals(&s);
            }
            std::fs::remove_dir_all(dir).ok();
        }

        #[test]
        fn gltf_with_random_numbers(picks in proptest::collection::vec((any::<prop::sample::Index>(), 0usize..10), 1..4)) {
            let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
            let mut text = gltf(&p, &[0, 1, 2, 2, 1, 3], Some(&p), r#"{"mesh": 0, "children": [1]}, {"mesh": 0}"#, "0", "");
            let replacements = ["0", "1", "3", "4", "12", "255", "65535", "4294967295", "-1", "1e30"];
            for (at, r) in picks {
                // Replace one whole number of the JSON (outside the base64 data).
                let data = text.find("base64,").unwrap();
                let numbers: Vec<(usize, usize)> = text[data..]
                    .find('"')
                    .map(|end| data + end)
                    .into_iter()
                    .flat_map(|from| {
                        let bytes = text.as_bytes();
                        let mut v = Vec::new();
                        let mut i = from;
                        while i < bytes.len() {
                            if bytes[i].is_ascii_digit() && !bytes[i - 1].is_ascii_alphanumeric() {
                                let s = i;
                                while i < bytes.len() && bytes[i].is_ascii_digit() {
                                    i += 1;
                                }
                                v.push((s, i));
                            }
                            i += 1;
                        }
                        v
                    })
                    .collect();
                let (s, e) = numbers[at.index(numbers.len())];
                text.replace_range(s..e, replacements[r]);
            }
            let dir = temp_dir("fuzzgltf");
            let path = write(&dir, "f.gltf", &text);
            if let Ok(s) = load(&path, &opts()) {
                assert_unit_normals(&s);
            }
            std::fs::remove_dir_all(dir).ok();
        }
    }
}

#[test]
fn gltf_accessor_without_data_is_bounded() {
    let dir = temp_dir("zeros");
    let good = gltf(&TRI, &[0, 1, 2], None, r#"{"mesh": 0}"#, "0", "");
    let text = good.replace(
        r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}"#,
        r#"{"componentType": 5126, "count": 4294967295, "type": "VEC3"}"#,
    );
    assert_ne!(text, good);
    let msg = load(&write(&dir, "z.gltf", text), &opts()).unwrap_err().to_string();
    // The crate's validation already demands a buffer view here; the reader's own bound stays
    // as a second line.
    assert!(msg.contains("z.gltf") && (msg.contains("no data") || msg.contains("bufferView")), "{msg}");
}
