//! `geodex mesh`, `geodex mesh-domain` and `geodex remesh` end to end: the
//! built binary writes the format its `--out` names (PLY, OBJ, JSON, GLB),
//! the picture of an image mesh, and one clear error line for an unknown
//! extension.

use std::path::Path;
use std::process::{Command, Output};

use geodex::io::mesh::write::write_obj;
use geodex::io::mesh::{read_mesh, MeshFormat, MeshLimits};
use geodex::numerics::mesh::shapes::icosphere;
use ndarray::Array2;
use tempfile::TempDir;

fn geodex(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args(args)
        .output()
        .expect("the geodex binary runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The triangle count of a GLB file, read with an independent reader.
fn glb_triangles(path: &Path) -> usize {
    let bytes = std::fs::read(path).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid GLB");
    let blob = gltf.blob.as_deref().unwrap();
    let prim = gltf
        .document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap();
    let reader = prim.reader(|_| Some(blob));
    reader.read_indices().unwrap().into_u32().count() / 3
}

#[test]
fn image_meshes_come_as_glb_with_a_picture() {
    let dir = TempDir::new().unwrap();
    let image = Array2::from_shape_fn((40, 50), |(r, c)| {
        let d = (r as f64 - 20.0).hypot(c as f64 - 25.0);
        1.0 / (1.0 + ((d - 12.0) / 1.5).exp())
    });
    let img = dir.path().join("img.npy");
    ndarray_npy::write_npy(&img, &image).unwrap();
    let (glb, png, stats) = (
        dir.path().join("m.glb"),
        dir.path().join("m.png"),
        dir.path().join("s.json"),
    );
    ok(&geodex(&[
        "mesh",
        "--image",
        s(&img),
        "--count",
        "60",
        "--out",
        s(&glb),
        "--picture",
        s(&png),
        "--stats",
        s(&stats),
    ]));
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let nt = doc["stats"]["triangles"].as_u64().unwrap() as usize;
    assert_eq!(glb_triangles(&glb), nt);
    let pic = image::open(&png).expect("a PNG").to_rgb8();
    // 1024 / 50 rounds to 20, capped at 4.
    assert_eq!(pic.dimensions(), (200, 160));
    assert!(pic
        .pixels()
        .any(|p| p.0 == geodex::io::mesh_picture::VERTEX));
}

#[test]
fn domain_and_surface_meshes_follow_the_extension_and_refuse_unknown_ones() {
    let dir = TempDir::new().unwrap();
    let square = dir.path().join("square.json");
    std::fs::write(
        &square,
        r#"{"type": "Polygon", "coordinates": [[[0, 0], [20, 0], [20, 20], [0, 20], [0, 0]]]}"#,
    )
    .unwrap();
    let obj = dir.path().join("d.obj");
    ok(&geodex(&[
        "mesh-domain",
        "--polygons",
        s(&square),
        "--count",
        "200",
        "--out",
        s(&obj),
    ]));
    let bytes = std::fs::read(&obj).unwrap();
    let m = read_mesh(&bytes, Some(MeshFormat::Obj), &MeshLimits::default()).unwrap();
    assert!(m.mesh.num_vertices().abs_diff(200) <= 20);

    let sphere = dir.path().join("sphere.obj");
    std::fs::write(&sphere, write_obj(&icosphere(4, 1.0))).unwrap();
    let glb = dir.path().join("r.glb");
    ok(&geodex(&[
        "remesh",
        "--mesh",
        s(&sphere),
        "--count",
        "300",
        "--out",
        s(&glb),
    ]));
    // A closed genus-0 surface of nv vertices has 2 nv - 4 triangles.
    let nt = glb_triangles(&glb);
    assert!((2 * 270..=2 * 330).contains(&nt), "{nt}");

    let bad = geodex(&[
        "remesh",
        "--mesh",
        s(&sphere),
        "--count",
        "300",
        "--out",
        s(&dir.path().join("r.stl")),
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--out") && err.contains(".glb"), "{err}");
}
