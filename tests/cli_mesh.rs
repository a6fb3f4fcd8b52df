//! `geodex mesh-distance` end to end: the built binary on mesh files in a
//! temporary directory, D.npy / L.npy compared with the library's
//! `mesh_distance` on the same (parsed) mesh, and one clear stderr line for
//! each kind of bad input. Also `geodex correspond` on two mesh files.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use geodex::io::mesh::write::write_obj;
use geodex::io::mesh::{read_mesh, MeshFormat, MeshLimits};
use geodex::numerics::mesh::shapes::icosphere;
use geodex::numerics::mesh::solve::{mesh_distance, MeshDistanceOptions, MeshMethod};
use geodex::numerics::mesh::SurfacePoint;
use geodex::numerics::Control;
use ndarray::Array1;
use ndarray_npy::read_npy;
use tempfile::TempDir;

fn geodex(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_geodex"))
        .arg("mesh-distance")
        .args(args)
        .output()
        .expect("the geodex binary runs")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// An icosphere (642 vertices) written as OBJ; returns its path and bytes.
fn sphere_obj(dir: &TempDir) -> (PathBuf, Vec<u8>) {
    let bytes = write_obj(&icosphere(3, 1.0));
    let p = dir.path().join("sphere.obj");
    std::fs::write(&p, &bytes).unwrap();
    (p, bytes)
}

#[test]
fn every_method_writes_the_library_result() {
    let dir = TempDir::new().unwrap();
    let (mesh_path, bytes) = sphere_obj(&dir);
    let loaded = read_mesh(&bytes, Some(MeshFormat::Obj), &MeshLimits::default()).unwrap();
    let sources = [
        SurfacePoint::Vertex(7),
        SurfacePoint::Face {
            face: 300,
            bary: [0.2, 0.3, 0.5],
        },
    ];
    for (name, method) in [
        ("fast_marching", MeshMethod::FastMarching),
        ("heat", MeshMethod::Heat),
        ("exact", MeshMethod::Exact),
        ("dijkstra", MeshMethod::Dijkstra),
    ] {
        let out = dir.path().join(format!("d-{name}.npy"));
        let labels = dir.path().join(format!("l-{name}.npy"));
        let o = geodex(&[
            "--mesh",
            s(&mesh_path),
            "--source-vertex",
            "7",
            "--source-face",
            "300,0.2,0.3,0.5",
            "--method",
            name,
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ]);
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("642 vertices"), "{name}: {err}");
        let d: Array1<f64> = read_npy(&out).unwrap();
        let l: Array1<i32> = read_npy(&labels).unwrap();
        let expected = mesh_distance(
            &loaded.mesh,
            &loaded.topology,
            &sources,
            &MeshDistanceOptions {
                method,
                ..Default::default()
            },
            None,
            &Control::new(),
        )
        .unwrap();
        assert_eq!(d.len(), 642, "{name}");
        for (v, (a, b)) in d.iter().zip(&expected.distance).enumerate() {
            assert!(
                (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                "{name} {v}: {a} vs {b}"
            );
        }
        assert_eq!(l.to_vec(), expected.labels, "{name}");
        assert_eq!(d[7], 0.0, "{name}");
        assert!(
            l.iter().any(|&x| x == 0) && l.iter().any(|&x| x == 1),
            "{name}"
        );
        assert!(d.iter().all(|x| x.is_finite() && *x < 3.2), "{name}");
    }
}

#[test]
fn the_old_method_spelling_is_refused_naming_the_new_one() {
    let dir = TempDir::new().unwrap();
    let (mesh_path, _) = sphere_obj(&dir);
    let out = dir.path().join("d.npy");
    let o = geodex(&[
        "--mesh",
        s(&mesh_path),
        "--source-vertex",
        "0",
        "--method",
        "fast-marching",
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("`fast-marching` was renamed `fast_marching`"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn max_distance_leaves_far_vertices_infinite() {
    let dir = TempDir::new().unwrap();
    let (mesh_path, _) = sphere_obj(&dir);
    let out = dir.path().join("d.npy");
    let o = geodex(&[
        "--mesh",
        s(&mesh_path),
        "--source-vertex",
        "0",
        "--max-distance",
        "1.0",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let d: Array1<f64> = read_npy(&out).unwrap();
    assert!(d.iter().any(|x| x.is_infinite()));
    assert!(d.iter().filter(|x| x.is_finite()).all(|&x| x <= 1.0));
}

/// Runs a command that must fail and returns its single stderr line.
fn one_error_line(args: &[&str]) -> String {
    let o = geodex(args);
    assert!(!o.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    // A successful parse reports the mesh first; the error is the last line.
    let lines: Vec<&str> = err.lines().filter(|l| !l.contains(" vertices (")).collect();
    assert_eq!(lines.len(), 1, "{args:?}: stderr is not one line: {err:?}");
    assert!(lines[0].starts_with("geodex: "), "{err}");
    lines[0].to_string()
}

#[test]
fn bad_inputs_exit_non_zero_with_one_line_naming_the_problem() {
    let dir = TempDir::new().unwrap();
    let (mesh_path, _) = sphere_obj(&dir);
    let m = s(&mesh_path);
    let out = dir.path().join("d.npy");
    let o = s(&out);
    let empty = dir.path().join("empty.obj");
    std::fs::write(&empty, b"").unwrap();
    let bad_index = dir.path().join("bad.obj");
    std::fs::write(&bad_index, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let nan = dir.path().join("nan.obj");
    std::fs::write(&nan, b"v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let missing = dir.path().join("missing.obj");
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (
            vec!["--mesh", s(&missing), "--source-vertex", "0", "--out", o],
            &["--mesh", "missing.obj"],
        ),
        (
            vec!["--mesh", s(&empty), "--source-vertex", "0", "--out", o],
            &["--mesh", "empty.obj"],
        ),
        (
            vec!["--mesh", s(&bad_index), "--source-vertex", "0", "--out", o],
            &["--mesh", "bad.obj"],
        ),
        (
            vec!["--mesh", s(&nan), "--source-vertex", "0", "--out", o],
            &["--mesh", "nan.obj"],
        ),
        (vec!["--mesh", m, "--out", o], &["--source-vertex"]),
        (
            vec!["--mesh", m, "--source-vertex", "642", "--out", o],
            &["--source-vertex 1: ", "vertex 642"],
        ),
        (
            vec!["--mesh", m, "--source-face", "3,0.5,0.5", "--out", o],
            &["--source-face 1", "F,B0,B1,B2"],
        ),
        (
            vec![
                "--mesh",
                m,
                "--source-face",
                "99999,0.2,0.3,0.5",
                "--out",
                o,
            ],
            &["--source-face 1: "],
        ),
        (
            vec![
                "--mesh",
                m,
                "--source-vertex",
                "0",
                "--method",
                "magic",
                "--out",
                o,
            ],
            &["magic"],
        ),
        (
            vec![
                "--mesh",
                m,
                "--source-vertex",
                "0",
                "--heat-m",
                "-1",
                "--method",
                "heat",
                "--out",
                o,
            ],
            &["m"],
        ),
        (
            vec![
                "--mesh",
                m,
                "--source-vertex",
                "0",
                "--out",
                "/nonexistent-dir/d.npy",
            ],
            &["--out"],
        ),
    ];
    for (args, needles) in cases {
        let line = one_error_line(&args);
        for n in needles {
            assert!(line.contains(n), "{args:?}: {line:?} lacks {n:?}");
        }
        // The command's flags, never the request's fields.
        assert!(!line.contains("sources["), "{args:?}: {line:?}");
    }
    assert!(!out.exists(), "no output is written on failure");
}

/// `geodex descriptor`: the operation's descriptor as JSON, the same as the
/// library's; a bad option is refused naming its flag.
#[test]
fn descriptor_writes_the_library_descriptor_and_names_the_flag() {
    use geodex::numerics::mesh::Topology;
    use geodex::numerics::shape::descriptor::{descriptor, DescriptorOptions};
    let dir = tempfile::tempdir().unwrap();
    let (mesh, bytes) = sphere_obj(&dir);
    let out = dir.path().join("d.json");
    let run = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args(["descriptor", "--mesh", s(&mesh), "--landmarks", "12"])
        .args(["--bins", "8", "--out", s(&out)])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let got: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let loaded = read_mesh(&bytes, Some(MeshFormat::Obj), &MeshLimits::default()).unwrap();
    let m = &loaded.mesh;
    let want = descriptor(
        m,
        &Topology::new(m),
        &DescriptorOptions {
            landmarks: 12,
            bins: 8,
            method: MeshMethod::FastMarching,
        },
        None,
        &Control::new(),
    )
    .unwrap();
    let vector: Vec<f64> = got["vector"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(vector.len(), 2 * 8 + 9);
    for (a, b) in vector.iter().zip(want.to_vector()) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args(["descriptor", "--mesh", s(&mesh), "--bins", "1"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--bins"), "{err}");
}

/// A flat right trapezoid of 121 vertices, scaled by `s` and turned by `angle`.
fn trapezoid_obj(dir: &TempDir, name: &str, s: f64, angle: f64) -> PathBuf {
    let m = geodex::numerics::mesh::shapes::flat_square(10, 1.0, 0.0);
    let (c, sn) = (angle.cos(), angle.sin());
    let pos = m
        .positions()
        .iter()
        .map(|p| {
            let (x, y) = (2.0 * p[0], p[1] * (0.4 + 0.6 * p[0]));
            [s * (c * x - sn * y), s * (sn * x + c * y), 0.0]
        })
        .collect();
    let mesh = geodex::numerics::mesh::TriMesh::new(pos, m.faces().to_vec()).unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, write_obj(&mesh)).unwrap();
    p
}

#[test]
fn correspond_writes_the_matches_and_names_a_bad_scale() {
    let dir = TempDir::new().unwrap();
    let a = trapezoid_obj(&dir, "a.obj", 1.0, 0.0);
    let b = trapezoid_obj(&dir, "b.obj", 1.0, 0.7);
    let out = dir.path().join("matched.ply");
    let face = dir.path().join("f.npy");
    let bary = dir.path().join("l.npy");
    let run = |b: &Path, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_geodex"))
            .arg("correspond")
            .args([
                "--a",
                s(&a),
                "--b",
                s(b),
                "--landmarks",
                "20",
                "--out",
                s(&out),
            ])
            .args(["--face", s(&face), "--bary", s(&bary)])
            .args(extra)
            .output()
            .expect("the geodex binary runs")
    };
    let o = run(&b, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f: ndarray::Array1<i32> = read_npy(&face).unwrap();
    let l: ndarray::Array2<f64> = read_npy(&bary).unwrap();
    assert_eq!((f.len(), l.dim()), (121, (121, 3)));
    let ply = std::fs::read(&out).unwrap();
    let header = String::from_utf8_lossy(&ply[..ply.len().min(2000)]).to_string();
    for p in ["match_face", "match_vertex", "match_bary0", "confidence"] {
        assert!(header.contains(p), "{p} missing from {header}");
    }
    // Twice the size: one line naming --b and the way out (--scale).
    let big = trapezoid_obj(&dir, "big.obj", 2.0, 0.7);
    let o = run(&big, &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    let last = err.lines().last().unwrap_or("");
    assert!(last.contains("--b") && last.contains("scale"), "{err}");
    let o = run(&big, &["--scale"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `--metric` and `--weights`: the file named in the metric section is read
/// from disk, the result equals the library's design + fast marching, and a
/// bad section or a missing file is one line naming the flag.
#[test]
fn metric_and_weights_flags_read_their_files() {
    use geodex::numerics::mesh::design::{design, FieldMode, MeshDesign};
    use geodex::numerics::mesh::Topology;
    let dir = TempDir::new().unwrap();
    let (mesh_path, bytes) = sphere_obj(&dir);
    let loaded = read_mesh(&bytes, Some(MeshFormat::Obj), &MeshLimits::default()).unwrap();
    let mesh = &loaded.mesh;
    let n = mesh.num_vertices();
    // A texture: the height z.
    let field: Vec<f64> = mesh.positions().iter().map(|p| p[2]).collect();
    let field_path = dir.path().join("texture.npy");
    ndarray_npy::write_npy(&field_path, &Array1::from(field.clone())).unwrap();
    let topo = Topology::new(mesh);
    let w = design(
        mesh,
        &topo,
        &MeshDesign::Field {
            values: &field,
            mode: FieldMode::Follow,
            epsilon: 0.01,
            power: 1.0,
        },
        &Control::new(),
    )
    .unwrap();
    let expected = mesh_distance(
        mesh,
        &topo,
        &[SurfacePoint::Vertex(3)],
        &MeshDistanceOptions {
            weights: Some(&w),
            ..Default::default()
        },
        None,
        &Control::new(),
    )
    .unwrap();
    let out = dir.path().join("d.npy");
    let metric = format!(
        r#"{{"kind": "field", "field": "{}", "mode": "follow"}}"#,
        s(&field_path)
    );
    let o = geodex(&[
        "--mesh",
        s(&mesh_path),
        "--source-vertex",
        "3",
        "--out",
        s(&out),
        "--metric",
        &metric,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let d: Array1<f64> = read_npy(&out).unwrap();
    assert_eq!(d.len(), n);
    for (a, b) in d.iter().zip(&expected.distance) {
        assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
    }
    // The same weights as a file.
    let w_path = dir.path().join("w.npy");
    ndarray_npy::write_npy(&w_path, &Array1::from(w.clone())).unwrap();
    let o = geodex(&[
        "--mesh",
        s(&mesh_path),
        "--source-vertex",
        "3",
        "--out",
        s(&out),
        "--weights",
        s(&w_path),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let d2: Array1<f64> = read_npy(&out).unwrap();
    assert_eq!(d, d2);
    // Misuse: one line naming the flag.
    for (args, needle) in [
        (vec!["--metric", "{\"kind\": \"nope\"}"], "--metric"),
        (
            vec![
                "--metric",
                "{\"kind\": \"field\", \"field\": \"/nonexistent.npy\"}",
            ],
            "--metric",
        ),
        (
            vec![
                "--metric",
                "{\"kind\": \"curvature_tensors\"}",
                "--method",
                "heat",
            ],
            "--metric",
        ),
        (vec!["--weights", "/nonexistent.npy"], "--weights"),
    ] {
        let mut all = vec![
            "--mesh",
            s(&mesh_path),
            "--source-vertex",
            "0",
            "--out",
            s(&out),
        ];
        all.extend(args);
        let line = one_error_line(&all);
        assert!(line.contains(needle), "{all:?}: {line}");
    }
}

/// `geodex mesh-curvature`: a unit sphere's mean curvature is 1 at every
/// vertex in the N × 4 NPY (k1, k2, mean, gaussian), the PLY carries the
/// four properties, and too much smoothing is one line naming the flag.
#[test]
fn mesh_curvature_writes_the_table_and_the_mesh() {
    let dir = TempDir::new().unwrap();
    let (mesh_path, _) = sphere_obj(&dir);
    let (ply, npy) = (dir.path().join("c.ply"), dir.path().join("c.npy"));
    let o = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args([
            "mesh-curvature",
            "--mesh",
            s(&mesh_path),
            "--out",
            s(&ply),
            "--npy",
            s(&npy),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table: ndarray::Array2<f64> = read_npy(&npy).unwrap();
    assert_eq!(table.shape(), &[642, 4]);
    for row in table.rows() {
        assert!((row[2] - 1.0).abs() < 0.03, "mean {}", row[2]);
        assert!(row[0] >= row[1] && (row[3] - row[0] * row[1]).abs() < 1e-12);
    }
    let header = std::fs::read(&ply).unwrap();
    let text = String::from_utf8_lossy(&header[..400.min(header.len())]).to_string();
    for p in ["k1", "k2", "mean", "gaussian"] {
        assert!(text.contains(&format!("property double {p}")), "{text}");
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args([
            "mesh-curvature",
            "--mesh",
            s(&mesh_path),
            "--out",
            s(&ply),
            "--smoothing",
            "2000",
        ])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--smoothing"), "{err}");
}

/// `geodex distance-matrix --metric` and `--weights`: each row is what
/// `geodex mesh-distance` writes from that source under the same metric,
/// the metric changes the rows, and a method that cannot run it is one line
/// naming the flag.
#[test]
fn distance_matrix_takes_the_metric_flags() {
    let dir = TempDir::new().unwrap();
    let (mesh_path, _) = sphere_obj(&dir);
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_geodex"))
            .args(args)
            .output()
            .unwrap()
    };
    let metric = r#"{"kind": "curvature_tensors", "max_ratio": 4}"#;
    // The rows from vertices 0 and 7, with `extra` flags.
    let rows = |extra: &[&str], name: &str| -> ndarray::Array2<f64> {
        let out = dir.path().join(name);
        let mut args = vec![
            "distance-matrix",
            "--mesh",
            s(&mesh_path),
            "--source-vertex",
            "0",
            "--source-vertex",
            "7",
            "--out",
            s(&out),
        ];
        args.extend(extra);
        let o = run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        read_npy(&out).unwrap()
    };
    let m = rows(&["--metric", metric], "m.npy");
    assert_eq!(m.shape()[0], 2);
    // The source block is averaged (d(0, 7) and d(7, 0) may differ under
    // tensors), so compare the rows off it.
    let row = dir.path().join("d.npy");
    for (i, v) in ["0", "7"].into_iter().enumerate() {
        let o = run(&[
            "mesh-distance",
            "--mesh",
            s(&mesh_path),
            "--source-vertex",
            v,
            "--metric",
            metric,
            "--out",
            s(&row),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let d: Array1<f64> = read_npy(&row).unwrap();
        for (j, (a, b)) in m.row(i).iter().zip(&d).enumerate() {
            if j != 0 && j != 7 {
                assert_eq!(a, b, "row {i}, vertex {j}");
            }
        }
    }
    let p = rows(&[], "p.npy");
    assert!((&m - &p).iter().map(|x| x.abs()).fold(0.0, f64::max) > 1e-3);
    let plain = dir.path().join("p.npy");
    let bad = run(&[
        "distance-matrix",
        "--mesh",
        s(&mesh_path),
        "--landmarks",
        "3",
        "--method",
        "heat",
        "--metric",
        metric,
        "--out",
        s(&plain),
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--metric"), "{err}");
}
