//! `geodex path` end to end: the built binary on NPY files; the answer is
//! compared with the exact straight path of a unit cost, and bad flags give
//! one stderr line naming the flag.

use std::path::Path;
use std::process::{Command, Output};

use ndarray::{ArrayD, IxDyn};
use ndarray_npy::write_npy;
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

fn one_error_line(args: &[&str]) -> String {
    let o = geodex(args);
    assert!(!o.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{args:?}: stderr is not one line: {err:?}");
    assert!(lines[0].starts_with("geodex: "), "{err}");
    lines[0].to_string()
}

#[test]
fn unit_cost_paths_are_the_straight_segments() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("paths.json");
    let o = geodex(&[
        "path",
        "--shape",
        "48,48",
        "--source",
        "4,5",
        "--to",
        "40,30",
        "--to",
        "10,44",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let paths = v["paths"].as_array().unwrap();
    assert_eq!(paths.len(), 2);
    for (p, end) in paths.iter().zip([[40.0, 30.0], [10.0, 44.0]]) {
        let exact = ((end[0] - 4.0f64).powi(2) + (end[1] - 5.0f64).powi(2)).sqrt();
        let len = p["euclidean_length"].as_f64().unwrap();
        assert!((len - exact).abs() < 0.05, "{len} vs {exact}");
        assert_eq!(p["points"][0], serde_json::json!([4.0, 5.0]));
    }
}

#[test]
fn designed_metric_contour_and_svg_from_an_image_file() {
    let dir = TempDir::new().unwrap();
    // A bright ring of radius 12 around (24, 24).
    let img = ArrayD::from_shape_fn(IxDyn(&[48, 48]), |ix| {
        let r = ((ix[0] as f64 - 24.0).powi(2) + (ix[1] as f64 - 24.0).powi(2)).sqrt();
        if (r - 12.0).abs() <= 1.5 {
            1.0f64
        } else {
            0.0
        }
    });
    let file = dir.path().join("ring.npy");
    write_npy(&file, &img).unwrap();
    let out = dir.path().join("contour.json");
    let o = geodex(&[
        "path",
        "--cost",
        s(&file),
        "--design",
        r#"{"kind": "intensity"}"#,
        "--contour",
        "12,24",
        "--contour",
        "30,34.4",
        "--contour",
        "30,13.6",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(v["chain"]["closed"], true);
    for p in v["chain"]["points"].as_array().unwrap() {
        let r = ((p[0].as_f64().unwrap() - 24.0).powi(2) + (p[1].as_f64().unwrap() - 24.0).powi(2))
            .sqrt();
        assert!((r - 12.0).abs() <= 1.5, "{p} is off the ring (r = {r})");
    }
    let svg = dir.path().join("contour.svg");
    let o = geodex(&[
        "path",
        "--cost",
        s(&file),
        "--design",
        r#"{"kind": "intensity"}"#,
        "--contour",
        "12,24",
        "--contour",
        "30,34.4",
        "--contour",
        "30,13.6",
        "--format",
        "svg",
        "--out",
        s(&svg),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.contains("<polygon"));
}

#[test]
fn bad_flags_name_themselves() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("p.json");
    let o = s(&out);
    let e = one_error_line(&[
        "path", "--shape", "16,16", "--source", "1,1", "--to", "3,3", "--to", "40,3", "--out", o,
    ]);
    assert!(e.starts_with("geodex: --to 2: "), "{e}");
    let e = one_error_line(&["path", "--shape", "16,16", "--waypoint", "1,1", "--out", o]);
    assert!(e.starts_with("geodex: --waypoint: "), "{e}");
    let e = one_error_line(&[
        "path",
        "--shape",
        "16,16",
        "--design",
        "{\"kind\": \"edges\"}",
        "--source",
        "1,1",
        "--to",
        "3,3",
        "--out",
        o,
    ]);
    assert!(e.starts_with("geodex: --design: "), "{e}");
    let e = one_error_line(&[
        "path", "--shape", "16,16", "--source", "1,1", "--to", "3,x", "--out", o,
    ]);
    assert!(e.starts_with("geodex: --to 1: "), "{e}");
}

#[test]
fn tensor_paths_follow_the_straight_geodesic_of_a_constant_metric() {
    let dir = TempDir::new().unwrap();
    // Cheap along axis 1 (1), expensive along axis 0 (25), with a shear.
    let m = [20.0, -6.0, 4.0];
    let t = dir.path().join("t.npy");
    write_npy(
        &t,
        &ArrayD::from_shape_fn(IxDyn(&[41, 41, 3]), |ix| m[ix[2]]),
    )
    .unwrap();
    let out = dir.path().join("paths.json");
    let o = geodex(&[
        "path",
        "--tensor",
        s(&t),
        "--source",
        "8,6",
        "--to",
        "30,34",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let p = &v["paths"][0];
    let d = [22.0f64, 28.0];
    let exact = (m[0] * d[0] * d[0] + 2.0 * m[1] * d[0] * d[1] + m[2] * d[1] * d[1]).sqrt();
    let len = p["geodesic_length"].as_f64().unwrap();
    assert!((len - exact).abs() < 0.05 * exact, "{len} vs {exact}");
    let norm = (d[0] * d[0] + d[1] * d[1]).sqrt();
    for q in p["points"].as_array().unwrap() {
        let (a, b) = (q[0].as_f64().unwrap() - 8.0, q[1].as_f64().unwrap() - 6.0);
        let off = (a * d[1] - b * d[0]).abs() / norm;
        assert!(off < 1.5, "{q} is {off} cells off the straight line");
    }

    // A bad tensor file names the flag and the first bad cell.
    let mut bad = ArrayD::from_shape_fn(IxDyn(&[8, 8, 3]), |ix| m[ix[2]]);
    bad[[5, 2, 0]] = -1.0;
    let badf = dir.path().join("bad.npy");
    write_npy(&badf, &bad).unwrap();
    let line = one_error_line(&[
        "path",
        "--tensor",
        s(&badf),
        "--source",
        "1,1",
        "--to",
        "6,6",
        "--out",
        s(&out),
    ]);
    assert!(
        line.contains("--tensor") && line.contains("cell [5, 2]"),
        "{line}"
    );
    let line = one_error_line(&[
        "path",
        "--tensor",
        s(&t),
        "--design",
        r#"{"kind": "edges"}"#,
        "--source",
        "1,1",
        "--to",
        "6,6",
        "--out",
        s(&out),
    ]);
    assert!(
        line.contains("--design") || line.contains("--tensor"),
        "{line}"
    );
}
