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

/// `geodex shape-from-shading` with a perspective camera: the depth of a
/// rendered dent (`Z = 3 - exp(-|x/f|²/0.2²)`, light at the optical centre,
/// `1/r²` falloff) as NPY within 8 % RMS of its range at 64² (measured 0.073: first order; 0.025 at 128² in numerics::shading), the surface as PLY with
/// two triangles per pixel quad; a bad focal names `--focal`.
#[test]
fn shape_from_shading_writes_the_depth_and_the_surface_mesh() {
    let dir = TempDir::new().unwrap();
    let n = 64usize;
    let f = n as f64;
    let c = (n - 1) as f64 / 2.0;
    let depth = |a: usize, b: usize| {
        let x = [a as f64 - c, b as f64 - c];
        let r2 = (x[0] * x[0] + x[1] * x[1]) / (f * f);
        let bump = (-r2 / 0.04).exp();
        let z = 3.0 - bump;
        let p = [
            bump * 2.0 * x[0] / (0.04 * f * f) / z,
            bump * 2.0 * x[1] / (0.04 * f * f) / z,
        ];
        let xp = 1.0 + x[0] * p[0] + x[1] * p[1];
        let s = (f * f * (p[0] * p[0] + p[1] * p[1]) + xp * xp).sqrt();
        let d2 = x[0] * x[0] + x[1] * x[1] + f * f;
        (z, f.powi(3) / (z * z * d2 * d2.sqrt() * s))
    };
    let image = Array2::from_shape_fn((n, n), |(a, b)| depth(a, b).1);
    let img = dir.path().join("img.npy");
    ndarray_npy::write_npy(&img, &image).unwrap();
    let (out, ply, stats) = (
        dir.path().join("d.npy"),
        dir.path().join("d.ply"),
        dir.path().join("s.json"),
    );
    ok(&geodex(&[
        "shape-from-shading",
        "--image",
        s(&img),
        "--focal",
        "64",
        "--albedo",
        "1",
        "--out",
        s(&out),
        "--mesh",
        s(&ply),
        "--stats",
        s(&stats),
    ]));
    let got: Array2<f64> = ndarray_npy::read_npy(&out).unwrap();
    let mut sum = 0.0f64;
    for ((a, b), &z) in got.indexed_iter() {
        sum += (z - depth(a, b).0).powi(2);
    }
    let e = (sum / (n * n) as f64).sqrt();
    eprintln!("geodex shape-from-shading, 64²: RMS depth error {e} (range 1)");
    assert!(e <= 0.08, "RMS depth error {e} (range 1)");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(doc["stats"]["stop"], "converged", "{doc}");
    let m = read_mesh(
        &std::fs::read(&ply).unwrap(),
        Some(MeshFormat::Ply),
        &MeshLimits::default(),
    )
    .unwrap();
    assert_eq!(m.mesh.num_vertices(), n * n);
    assert_eq!(m.mesh.num_faces(), 2 * (n - 1) * (n - 1));
    let bad = geodex(&[
        "shape-from-shading",
        "--image",
        s(&img),
        "--focal",
        "-1",
        "--out",
        s(&out),
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--focal"), "{err}");
}
