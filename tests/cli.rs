//! `geodex distance` end to end: the built binary, NPY files in a temporary
//! directory, outputs compared with the library's `solve` on the same problem,
//! and one clear stderr line for each kind of bad input.

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use geodex::numerics::eikonal::{Method, Order, StopRules};
use geodex::numerics::metric::{CostValues, Interpretation};
use geodex::numerics::{
    solve, Control, EikonalOptions, EikonalProblem, Grid, IsotropicCost, Source,
};
use ndarray::{ArrayD, IxDyn};
use ndarray_npy::{read_npy, write_npy};
use tempfile::TempDir;

fn geodex(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_geodex"))
        .args(args)
        .output()
        .expect("the geodex binary runs")
}

fn path(dir: &TempDir, name: &str) -> PathBuf {
    dir.path().join(name)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A smooth positive cost `1 + 0.5 sin(0.3 i) cos(0.2 j) (+ 0.1 k)`.
fn cost_field(shape: &[usize]) -> ArrayD<f64> {
    ArrayD::from_shape_fn(IxDyn(shape), |ix| {
        let i = ix[0] as f64;
        let j = ix[1] as f64;
        let k = if shape.len() == 3 { ix[2] as f64 } else { 0.0 };
        1.0 + 0.5 * (0.3 * i).sin() * (0.2 * j).cos() + 0.01 * k
    })
}

/// Runs `geodex distance`, checks that it succeeded, and returns `(U, labels)`.
fn distance_ok(args: &[&str], out: &Path, labels: &Path) -> (ArrayD<f64>, ArrayD<i32>) {
    let o = geodex(args);
    assert!(
        o.status.success(),
        "geodex failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    (read_npy(out).unwrap(), read_npy(labels).unwrap())
}

fn assert_same(u: &ArrayD<f64>, expected: &ArrayD<f64>) {
    assert_eq!(u.shape(), expected.shape());
    for (a, b) in u.iter().zip(expected.iter()) {
        assert!(a == b || (a - b).abs() <= 1e-12, "{a} vs {b}");
    }
}

#[test]
fn f32_cost_2d_with_two_sources_matches_the_library() {
    let dir = TempDir::new().unwrap();
    let (cost, out, labels) = (
        path(&dir, "w.npy"),
        path(&dir, "u.npy"),
        path(&dir, "l.npy"),
    );
    let w = cost_field(&[40, 50]).mapv(|v| v as f32);
    write_npy(&cost, &w).unwrap();
    let (u, l) = distance_ok(
        &[
            "distance",
            "--cost",
            s(&cost),
            "--source",
            "10,12",
            "--source",
            "30.5,40",
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ],
        &out,
        &labels,
    );
    let grid = Grid::unit(&[40, 50]).unwrap();
    let values = w.as_slice().unwrap();
    let problem = EikonalProblem {
        cost: IsotropicCost::new(
            &grid,
            CostValues::F32(Cow::Borrowed(values)),
            Interpretation::Cost,
            None,
        )
        .unwrap(),
        grid,
        sources: vec![
            Source::Point(vec![10.0, 12.0]),
            Source::Point(vec![30.5, 40.0]),
        ],
    };
    let expected = solve(&problem, &EikonalOptions::DEFAULT, &Control::new()).unwrap();
    assert_same(&u, &expected.distance);
    assert_eq!(l, expected.labels);
    assert_eq!(u[[10, 12]], 0.0);
    assert_eq!(l[[0, 0]], 0);
    assert_eq!(l[[39, 49]], 1);
}

#[test]
fn f64_cost_3d_with_spacing_and_fast_sweeping_matches_the_library() {
    let dir = TempDir::new().unwrap();
    let (cost, out, labels) = (
        path(&dir, "w.npy"),
        path(&dir, "u.npy"),
        path(&dir, "l.npy"),
    );
    let w = cost_field(&[12, 14, 10]);
    write_npy(&cost, &w).unwrap();
    let (u, l) = distance_ok(
        &[
            "distance",
            "--cost",
            s(&cost),
            "--source",
            "3,4,5",
            "--spacing",
            "1,0.5,2",
            "--method",
            "fast_sweeping",
            "--order",
            "1",
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ],
        &out,
        &labels,
    );
    let grid = Grid::new(&[12, 14, 10], &[1.0, 0.5, 2.0]).unwrap();
    let problem = EikonalProblem {
        cost: IsotropicCost::new(
            &grid,
            CostValues::F64(Cow::Borrowed(w.as_slice().unwrap())),
            Interpretation::Cost,
            None,
        )
        .unwrap(),
        grid,
        sources: vec![Source::Point(vec![3.0, 4.0, 5.0])],
    };
    let options = EikonalOptions::DEFAULT
        .with_method(Method::FastSweeping)
        .with_order(Order::First);
    let expected = solve(&problem, &options, &Control::new()).unwrap();
    assert_same(&u, &expected.distance);
    assert!(l.iter().all(|&x| x == 0));
}

#[test]
fn unit_shape_3d_is_close_to_the_euclidean_distance() {
    // Exact solution of |∇U| = 1 with a point source: U = |x - p|.
    let dir = TempDir::new().unwrap();
    let (out, labels) = (path(&dir, "u.npy"), path(&dir, "l.npy"));
    let (u, _) = distance_ok(
        &[
            "distance",
            "--shape",
            "21,22,23",
            "--source",
            "10,11,12",
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ],
        &out,
        &labels,
    );
    assert_eq!(u.shape(), &[21, 22, 23]);
    let (mut max, mut sum) = (0.0f64, 0.0);
    for (ix, &v) in u.indexed_iter() {
        let r = ((ix[0] as f64 - 10.0).powi(2)
            + (ix[1] as f64 - 11.0).powi(2)
            + (ix[2] as f64 - 12.0).powi(2))
        .sqrt();
        max = max.max((v - r).abs());
        sum += (v - r).abs();
    }
    let mean = sum / u.len() as f64;
    assert!(max < 0.15 && max > 0.0, "max {max}");
    assert!(mean < 0.05, "mean {mean}");
}

#[test]
fn speed_obstacles_and_stop_rules_match_the_library() {
    let dir = TempDir::new().unwrap();
    let (speed, mask, out, labels) = (
        path(&dir, "f.npy"),
        path(&dir, "m.npy"),
        path(&dir, "u.npy"),
        path(&dir, "l.npy"),
    );
    let f = cost_field(&[30, 30]);
    let m = ArrayD::from_shape_fn(IxDyn(&[30, 30]), |ix| ix[1] == 15 && ix[0] < 25);
    write_npy(&speed, &f).unwrap();
    write_npy(&mask, &m).unwrap();
    let (u, l) = distance_ok(
        &[
            "distance",
            "--cost",
            s(&speed),
            "--speed",
            "--obstacles",
            s(&mask),
            "--source",
            "5,5",
            "--max-distance",
            "20",
            "--method",
            "dijkstra",
            "--connectivity",
            "extended",
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ],
        &out,
        &labels,
    );
    let grid = Grid::unit(&[30, 30]).unwrap();
    let problem = EikonalProblem {
        cost: IsotropicCost::new(
            &grid,
            CostValues::F64(Cow::Borrowed(f.as_slice().unwrap())),
            Interpretation::Speed,
            Some(Cow::Owned(m.iter().copied().collect())),
        )
        .unwrap(),
        grid,
        sources: vec![Source::Point(vec![5.0, 5.0])],
    };
    let options = EikonalOptions::DEFAULT
        .with_method(Method::Dijkstra)
        .with_connectivity(geodex::numerics::Connectivity::Extended)
        .with_stop(StopRules {
            max_distance: Some(20.0),
            ..Default::default()
        });
    let expected = solve(&problem, &options, &Control::new()).unwrap();
    assert_same(&u, &expected.distance);
    assert_eq!(l, expected.labels);
    assert_eq!(u[[5, 15]], f64::INFINITY);
    assert!(u.iter().any(|v| v.is_infinite()) && u.iter().any(|v| *v > 10.0 && v.is_finite()));
}

/// Runs a command that must fail and returns its single stderr line.
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
fn bad_inputs_exit_non_zero_with_one_line_naming_the_problem() {
    let dir = TempDir::new().unwrap();
    let out = path(&dir, "u.npy");
    let o = s(&out);
    let write = |name: &str, a: ArrayD<f64>| {
        let p = path(&dir, name);
        write_npy(&p, &a).unwrap();
        p
    };
    let good = write("good.npy", ArrayD::from_elem(IxDyn(&[256, 256]), 1.0));
    let mut nan = ArrayD::from_elem(IxDyn(&[8, 8]), 1.0);
    nan[[2, 3]] = f64::NAN;
    let nan = write("nan.npy", nan);
    let mut neg = ArrayD::from_elem(IxDyn(&[8, 8]), 1.0);
    neg[[4, 1]] = -2.0;
    let neg = write("neg.npy", neg);
    let one_d = write("1d.npy", ArrayD::from_elem(IxDyn(&[8]), 1.0));
    let four_d = write("4d.npy", ArrayD::from_elem(IxDyn(&[2, 2, 2, 2]), 1.0));
    let mut walls = ArrayD::from_elem(IxDyn(&[8, 8]), 1.0);
    walls[[3, 3]] = f64::INFINITY;
    let walls = write("walls.npy", walls);
    let missing = path(&dir, "missing.npy");

    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (
            vec!["--cost", s(&missing), "--source", "1,1"],
            &["--cost: cannot read", "missing.npy"],
        ),
        (
            vec!["--cost", s(&nan), "--source", "1,1"],
            &["--cost: ", "[2, 3]", "NaN"],
        ),
        (
            vec!["--cost", s(&neg), "--source", "1,1"],
            &["--cost: ", "[4, 1]", "-2"],
        ),
        (
            vec!["--cost", s(&good), "--source", "4,4", "--source", "300,4"],
            &["--source 2: point [300.0, 4.0] is outside the grid of shape [256, 256]"],
        ),
        (
            vec!["--cost", s(&walls), "--source", "3,3"],
            &["--source 1: ", "obstacle"],
        ),
        (
            vec!["--cost", s(&one_d), "--source", "1,1"],
            &["--cost: ", "2D or 3D"],
        ),
        (vec!["--cost", s(&four_d), "--source", "1,1"], &["--cost: "]),
        (
            vec!["--shape", "8,8", "--source", "1,x"],
            &["--source 1: '1,x' is not a point"],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,2,3,4"],
            &["--source 1: "],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1,1"],
            &["--source 1: ", "3 coordinates"],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1", "--spacing", "1,0"],
            &["--spacing value 2: 0 must be"],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1", "--spacing", "1"],
            &["--spacing: "],
        ),
        (
            vec!["--shape", "8", "--source", "1,1"],
            &["--shape: ", "2D or 3D"],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1", "--target", "9,9"],
            &["--target 1: ", "outside"],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1", "--max-distance", "-1"],
            &["--max-distance: "],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1", "--order", "3"],
            &["--order"],
        ),
        (
            vec!["--shape", "8,8", "--source", "1,1", "--method", "magic"],
            &["--method", "magic"],
        ),
        (vec!["--shape", "8,x", "--source", "1,1"], &["--shape"]),
        (
            vec!["--cost", s(&good), "--shape", "8,8", "--source", "1,1"],
            &["--cost", "--shape"],
        ),
        (vec!["--shape", "8,8"], &["--source"]),
    ];
    for (extra, needles) in cases {
        let mut args = vec!["distance"];
        args.extend(extra.iter().copied());
        if !extra.contains(&"--out") {
            args.extend(["--out", o]);
        }
        let line = one_error_line(&args);
        for n in needles {
            assert!(line.contains(n), "{args:?}: {line:?} lacks {n:?}");
        }
        eprintln!("{line}");
    }
    // Missing --out, and an output that cannot be written.
    let line = one_error_line(&["distance", "--shape", "8,8", "--source", "1,1"]);
    assert!(line.contains("--out"), "{line}");
    let line = one_error_line(&[
        "distance",
        "--shape",
        "8,8",
        "--source",
        "1,1",
        "--out",
        "/nonexistent/dir/u.npy",
    ]);
    assert!(line.starts_with("geodex: --out: cannot write"), "{line}");
}

/// `[m11, m12, m22]` of eigenvalues `l1` along `(cos t, sin t)` (axis 0 first) and `l2` across.
fn eigen2(l1: f64, l2: f64, t: f64) -> [f64; 3] {
    let (c, s) = (t.cos(), t.sin());
    [
        l1 * c * c + l2 * s * s,
        (l1 - l2) * c * s,
        l1 * s * s + l2 * c * c,
    ]
}

#[test]
fn tensor_distance_2d_matches_the_exact_riemannian_distance() {
    let dir = TempDir::new().unwrap();
    let (t, out, labels) = (
        path(&dir, "t.npy"),
        path(&dir, "u.npy"),
        path(&dir, "l.npy"),
    );
    let m = eigen2(1.0, 16.0, 0.5);
    let field = ArrayD::from_shape_fn(IxDyn(&[41, 41, 3]), |ix| m[ix[2]]);
    write_npy(&t, &field).unwrap();
    let (u, l) = distance_ok(
        &[
            "distance",
            "--tensor",
            s(&t),
            "--source",
            "20,20",
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ],
        &out,
        &labels,
    );
    assert_eq!(u.shape(), &[41, 41]);
    assert!(l.iter().all(|&v| v == 0));
    let mut worst: f64 = 0.0;
    for ((i, j), v) in u.indexed_iter().map(|(ix, v)| ((ix[0], ix[1]), *v)) {
        let (a, b) = (i as f64 - 20.0, j as f64 - 20.0);
        let exact = (m[0] * a * a + 2.0 * m[1] * a * b + m[2] * b * b).sqrt();
        if exact >= 5.0 {
            worst = worst.max((v - exact).abs() / exact);
        }
    }
    assert!(worst < 0.03, "relative max error {worst}");
}

/// A 3D field `(n0, n1, n2, 6)`: a constant diagonal metric diag(1, 4, 9),
/// exact `U = √(x² + 4y² + 9z²)` from the centre.
#[test]
fn tensor_distance_3d_reads_six_components_per_voxel() {
    let dir = TempDir::new().unwrap();
    let (t, out, labels) = (
        path(&dir, "t3.npy"),
        path(&dir, "u3.npy"),
        path(&dir, "l3.npy"),
    );
    let m = [1.0, 0.0, 0.0, 4.0, 0.0, 9.0];
    let field = ArrayD::from_shape_fn(IxDyn(&[17, 17, 17, 6]), |ix| m[ix[3]]);
    write_npy(&t, &field).unwrap();
    let (u, _) = distance_ok(
        &[
            "distance",
            "--tensor",
            s(&t),
            "--source",
            "8,8,8",
            "--out",
            s(&out),
            "--labels",
            s(&labels),
        ],
        &out,
        &labels,
    );
    assert_eq!(u.shape(), &[17, 17, 17]);
    let mut worst: f64 = 0.0;
    for (ix, v) in u.indexed_iter() {
        let (a, b, c) = (ix[0] as f64 - 8.0, ix[1] as f64 - 8.0, ix[2] as f64 - 8.0);
        let exact = (a * a + 4.0 * b * b + 9.0 * c * c).sqrt();
        if exact >= 4.0 {
            worst = worst.max((v - exact).abs() / exact);
        }
    }
    assert!(worst < 0.05, "relative max error {worst}");
}

#[test]
fn bad_tensor_files_exit_non_zero_naming_the_first_bad_cell() {
    let dir = TempDir::new().unwrap();
    let out = path(&dir, "u.npy");
    let write = |name: &str, a: ArrayD<f64>| {
        let p = path(&dir, name);
        write_npy(&p, &a).unwrap();
        p
    };
    let unit = |shape: &[usize]| {
        let last = shape.len() - 1;
        ArrayD::from_shape_fn(IxDyn(shape), |ix| if ix[last] == 1 { 0.0 } else { 1.0 })
    };
    let four = write("four.npy", ArrayD::from_elem(IxDyn(&[8, 8, 4]), 1.0));
    let mut indefinite = unit(&[8, 8, 3]);
    indefinite[[2, 3, 1]] = 2.0;
    indefinite[[6, 6, 1]] = 2.0;
    let indefinite = write("indef.npy", indefinite);
    let mut nan = unit(&[8, 8, 3]);
    nan[[4, 1, 2]] = f64::NAN;
    let nan = write("nan.npy", nan);
    let good = write("good.npy", unit(&[8, 8, 3]));
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (
            vec!["--tensor", s(&four), "--source", "1,1"],
            &["--tensor", "trailing axis of 3"],
        ),
        (
            vec!["--tensor", s(&indefinite), "--source", "1,1"],
            &["--tensor", "cell [2, 3]", "positive definite"],
        ),
        (
            vec!["--tensor", s(&nan), "--source", "1,1"],
            &["--tensor", "cell [4, 1]", "not finite"],
        ),
        (
            vec![
                "--tensor",
                s(&good),
                "--source",
                "1,1",
                "--method",
                "dijkstra",
            ],
            &["--method"],
        ),
        (
            vec!["--tensor", s(&good), "--source", "9,1"],
            &["--source 1"],
        ),
    ];
    for (extra, wanted) in cases {
        let mut args = vec!["distance", "--out", s(&out)];
        args.extend(extra.iter().copied());
        let line = one_error_line(&args);
        for w in wanted {
            assert!(line.contains(w), "{args:?}: {line:?} lacks {w:?}");
        }
    }
}

/// `phi = |x - c|² - r²` on a 96 x 80 grid (not a distance).
fn circle_phi() -> ArrayD<f64> {
    ArrayD::from_shape_fn(IxDyn(&[96, 80]), |ix| {
        (ix[0] as f64 - 47.3).powi(2) + (ix[1] as f64 - 40.6).powi(2) - 25.2f64.powi(2)
    })
}

#[test]
fn phi_signed_is_the_redistancing_and_a_source_mask_is_zero() {
    let dir = TempDir::new().unwrap();
    let (phi_path, out) = (path(&dir, "phi.npy"), path(&dir, "d.npy"));
    write_npy(&phi_path, &circle_phi()).unwrap();
    let o = geodex(&[
        "distance",
        "--phi",
        s(&phi_path),
        "--signed",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let d: ArrayD<f64> = read_npy(&out).unwrap();
    assert_eq!(d.shape(), &[96, 80]);
    for (ix, &v) in d.indexed_iter() {
        let exact = (ix[0] as f64 - 47.3).hypot(ix[1] as f64 - 40.6) - 25.2;
        if exact.abs() <= 8.0 {
            assert!((v - exact).abs() <= 0.05, "{ix:?}: {v} vs {exact}");
        }
        assert_eq!(v < 0.0, exact < 0.0, "{ix:?}");
    }

    // A mask with a cost: 0 on the mask, 2 × the gap beside it.
    let mask = ArrayD::from_shape_fn(IxDyn(&[20, 30]), |ix| {
        u8::from((5..9).contains(&ix[0]) && (10..14).contains(&ix[1]))
    });
    let mask_path = path(&dir, "mask.npy");
    write_npy(&mask_path, &mask).unwrap();
    let cost_path = path(&dir, "cost.npy");
    write_npy(&cost_path, &ArrayD::from_elem(IxDyn(&[20, 30]), 2.0f64)).unwrap();
    let o = geodex(&[
        "distance",
        "--source-mask",
        s(&mask_path),
        "--cost",
        s(&cost_path),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let u: ArrayD<f64> = read_npy(&out).unwrap();
    for (ix, &m) in mask.indexed_iter() {
        if m != 0 {
            assert_eq!(u[&ix], 0.0);
        }
    }
    assert!((u[[6, 20]] - 2.0 * 7.0).abs() < 1e-9, "{}", u[[6, 20]]);

    // Errors name the flags.
    let flat = path(&dir, "flat.npy");
    write_npy(&flat, &ArrayD::from_elem(IxDyn(&[8, 8]), 1.0f64)).unwrap();
    let line = one_error_line(&["distance", "--phi", s(&flat), "--out", s(&out)]);
    assert!(
        line.starts_with("geodex: --phi: ") && line.contains("no zero level set"),
        "{line}"
    );
    let line = one_error_line(&[
        "distance",
        "--shape",
        "8,8",
        "--source",
        "1,1",
        "--signed",
        "--out",
        s(&out),
    ]);
    assert!(
        line.contains("--phi") || line.contains("--signed"),
        "{line}"
    );
}

#[test]
fn cost_gradient_writes_the_library_adjoint_and_names_bad_targets() {
    use geodex::numerics::eikonal::{cost_gradient, Probe};
    let dir = TempDir::new().unwrap();
    let shape = [30, 26];
    let cost = cost_field(&shape);
    let cost_path = path(&dir, "w.npy");
    write_npy(&cost_path, &cost).unwrap();
    let targets = ndarray::arr2(&[[25.0, 20.0], [12.5, 22.25]]);
    let targets_path = path(&dir, "y.npy");
    write_npy(&targets_path, &targets).unwrap();
    let observed_path = path(&dir, "t.npy");
    write_npy(&observed_path, &ndarray::arr1(&[10.0, 40.0])).unwrap();
    let out = path(&dir, "g.npy");
    let json = path(&dir, "r.json");
    let run = || {
        geodex(&[
            "cost-gradient",
            "--cost",
            s(&cost_path),
            "--source",
            "2,3",
            "--target",
            "5,20:0.5",
            "--targets",
            s(&targets_path),
            "--observed",
            s(&observed_path),
            "--misfit",
            "--order",
            "1",
            "--out",
            s(&out),
            "--json",
            s(&json),
        ])
    };
    let o = run();
    // Three targets but two observed values: refused, naming the flag.
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--observed") && err.contains("2 observed values for 3 targets"),
        "{err}"
    );

    write_npy(&observed_path, &ndarray::arr1(&[10.0, 40.0, 3.0])).unwrap();
    let o = run();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got: ArrayD<f64> = read_npy(&out).unwrap();

    // The same adjoint from the library: weights w (U − T).
    let grid = Grid::new(&shape, &[1.0, 1.0]).unwrap();
    let values: Vec<f64> = cost.iter().copied().collect();
    let problem = EikonalProblem {
        grid,
        cost: IsotropicCost::new(
            &Grid::new(&shape, &[1.0, 1.0]).unwrap(),
            CostValues::F64(Cow::Borrowed(&values)),
            Interpretation::Cost,
            None,
        )
        .unwrap(),
        sources: vec![Source::Point(vec![2.0, 3.0])],
    };
    let mut options = EikonalOptions::DEFAULT
        .with_method(Method::FastMarching)
        .with_order(Order::First)
        .with_factoring(false);
    options.record_order = true;
    let solved = solve(&problem, &options, &Control::new()).unwrap();
    let points = [vec![5.0, 20.0], vec![25.0, 20.0], vec![12.5, 22.25]];
    let probes: Vec<Probe> = points.iter().map(|p| Probe::Point(p.clone())).collect();
    let u = geodex::numerics::eikonal::probe_values(&problem.grid, &solved, &probes).unwrap();
    let weights: Vec<(Probe, f64)> = probes
        .into_iter()
        .zip([0.5 * (u[0] - 10.0), u[1] - 40.0, u[2] - 3.0])
        .collect();
    let expected = cost_gradient(&problem, &options, &solved, &weights, &Control::new()).unwrap();
    assert_same(&got, &expected);
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(doc["objective"]["kind"], "misfit");
    assert!((doc["targets"][1]["residual"].as_f64().unwrap() - (u[1] - 40.0)).abs() < 1e-12);

    // A target outside the grid names its flag.
    let line = one_error_line(&[
        "cost-gradient",
        "--cost",
        s(&cost_path),
        "--source",
        "2,3",
        "--target",
        "5,20",
        "--target",
        "5,26",
        "--out",
        s(&out),
    ]);
    assert!(line.contains("--target 2"), "{line}");
}

#[test]
fn tomography_reads_the_api_shaped_survey_and_names_bad_points() {
    let dir = TempDir::new().unwrap();
    // Slowness 2 everywhere: the best constant is close to 2.
    let sources: [[f64; 2]; 2] = [[0.0, 2.0], [0.0, 13.0]];
    let receivers: [[f64; 2]; 3] = [[15.0, 1.0], [15.0, 8.0], [15.0, 14.0]];
    let times: Vec<Vec<f64>> = sources
        .iter()
        .map(|s| {
            receivers
                .iter()
                .map(|r| 2.0 * ((r[0] - s[0]).powi(2) + (r[1] - s[1]).powi(2)).sqrt())
                .collect()
        })
        .collect();
    let points = |p: &[[f64; 2]]| {
        p.iter()
            .map(|p| serde_json::json!({"point": p}))
            .collect::<Vec<_>>()
    };
    let data = path(&dir, "survey.json");
    std::fs::write(
        &data,
        serde_json::json!({"sources": points(&sources), "receivers": points(&receivers), "times": times})
            .to_string(),
    )
    .unwrap();
    let out = path(&dir, "w.npy");
    let report = path(&dir, "r.json");
    let o = geodex(&[
        "tomography",
        "--data",
        s(&data),
        "--shape",
        "16,16",
        "--max-iterations",
        "3",
        "--out",
        s(&out),
        "--report",
        s(&report),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let w: ArrayD<f64> = read_npy(&out).unwrap();
    assert_eq!(w.shape(), &[16, 16]);
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let c = doc["constant_cost"].as_f64().unwrap();
    assert!((c - 2.0).abs() < 0.15, "{doc}");

    // A receiver outside the grid names the flag of the file it came from.
    std::fs::write(
        &data,
        serde_json::json!({"sources": points(&sources), "receivers": points(&[[15.0, 1.0], [15.0, 16.5], [15.0, 14.0]]), "times": times})
            .to_string(),
    )
    .unwrap();
    let line = one_error_line(&[
        "tomography",
        "--data",
        s(&data),
        "--shape",
        "16,16",
        "--out",
        s(&out),
    ]);
    assert!(
        line.contains("--data") && line.contains("outside the grid"),
        "{line}"
    );
}

#[test]
fn cost_gradient_takes_a_tensor_metric_and_returns_one_value_per_component() {
    let dir = TempDir::new().unwrap();
    let (n0, n1) = (18, 15);
    let m = ArrayD::from_shape_fn(IxDyn(&[n0, n1, 3]), |ix| {
        let a = ix[0] as f64 / n0 as f64;
        [2.0 + a.sin(), 0.4 * (ix[1] as f64 / 5.0).cos(), 1.5][ix[2]]
    });
    let tensor = path(&dir, "m.npy");
    write_npy(&tensor, &m).unwrap();
    let out = path(&dir, "g.npy");
    let json = path(&dir, "r.json");
    let o = geodex(&[
        "cost-gradient",
        "--tensor",
        s(&tensor),
        "--source",
        "1,2",
        "--target",
        "16,12",
        "--out",
        s(&out),
        "--json",
        s(&json),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let g: ArrayD<f64> = read_npy(&out).unwrap();
    assert_eq!(g.shape(), &[n0, n1, 3]);
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(doc["with_respect_to"], "metric");
    // U is homogeneous of degree 1/2 in M: Σ m ∂U/∂m = U/2.
    let j = doc["objective"]["value"].as_f64().unwrap();
    let euler: f64 = g.iter().zip(m.iter()).map(|(g, m)| g * m).sum();
    assert!((euler - 0.5 * j).abs() < 1e-9 * j, "{euler} vs {j}/2");
}

// ---- issue 21: output formats by extension, --design, `geodex metric`,
// ---- errors in the flags' names, a progress bar only on a terminal.

/// An image with a bright diagonal band on a darker ramp, values in [1, 2].
fn band_image(shape: [usize; 2]) -> ArrayD<f64> {
    ArrayD::from_shape_fn(IxDyn(&shape), |ix| {
        let (i, j) = (ix[0] as f64, ix[1] as f64);
        let band = (-((i - j) / 2.0).powi(2)).exp();
        1.0 + 0.2 * j / shape[1] as f64 + 0.8 * band
    })
}

#[test]
fn out_extension_chooses_npy_tiff_png_or_png16_and_unknown_ones_are_refused() {
    let dir = TempDir::new().unwrap();
    let base = ["distance", "--shape", "20,30", "--source", "4,5"];
    let run = |out: &Path, labels: Option<&Path>| {
        let mut args: Vec<&str> = base.to_vec();
        args.extend(["--out", s(out)]);
        if let Some(l) = labels {
            args.extend(["--labels", s(l)]);
        }
        let o = geodex(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    let npy = path(&dir, "u.npy");
    run(&npy, None);
    let u: ArrayD<f64> = read_npy(&npy).unwrap();

    // .png: the colour-mapped picture (with its colour bar: wider than the grid).
    let (png, labels_png) = (path(&dir, "U.png"), path(&dir, "L.png"));
    run(&png, Some(&labels_png));
    for p in [&png, &labels_png] {
        let bytes = std::fs::read(p).unwrap();
        assert!(
            bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{p:?} is not a PNG"
        );
        let picture = image::load_from_memory(&bytes).unwrap();
        assert!(picture.height() >= 20, "{p:?}: {}", picture.height());
        assert!(picture.width() >= 30, "{p:?}: {}", picture.width());
    }
    let picture = image::load_from_memory(&std::fs::read(&png).unwrap()).unwrap();
    assert!(picture.width() > 30, "no colour bar: {}", picture.width());

    // .tiff: f32 values.
    let tiff = path(&dir, "u.tiff");
    run(&tiff, None);
    let bytes = std::fs::read(&tiff).unwrap();
    let back = geodex::io::decode(&bytes, None, &geodex::io::Limits::default()).unwrap();
    assert_eq!(back.format, geodex::io::Format::Tiff);
    assert_eq!(back.array.shape(), u.shape());
    for (i, &v) in u.iter().enumerate() {
        let t = back.array.get_f64(i).unwrap();
        assert!((t - v).abs() <= 1e-6 * v.abs().max(1.0), "{t} vs {v}");
    }

    // .png16: 16-bit grey over the finite min..max.
    let png16 = path(&dir, "u.png16");
    run(&png16, None);
    let bytes = std::fs::read(&png16).unwrap();
    assert!(bytes.starts_with(b"\x89PNG"));
    let grey = image::load_from_memory(&bytes).unwrap().into_luma16();
    assert_eq!((grey.width(), grey.height()), (30, 20));
    let lo = u.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = u.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let step = (hi - lo) / 65535.0;
    for (ix, &v) in u.indexed_iter() {
        let q = f64::from(grey.get_pixel(ix[1] as u32, ix[0] as u32)[0]);
        assert!((lo + q * step - v).abs() <= step, "{v} vs {q}");
    }

    // Unknown extensions name the flag, before any work.
    for (flag, bad) in [("--out", "u.xyz"), ("--labels", "l.jpg")] {
        let out = path(&dir, bad);
        let mut args: Vec<&str> = base.to_vec();
        if flag == "--out" {
            args.extend(["--out", s(&out)]);
        } else {
            args.extend(["--out", s(&npy), "--labels", s(&out)]);
        }
        let line = one_error_line(&args);
        let ext = &bad[bad.rfind('.').unwrap()..];
        assert_eq!(
            line,
            format!("geodex: {flag}: unknown extension '{ext}'; use .npy, .tiff, .png or .png16")
        );
        assert!(!out.exists());
    }
    // A volume cannot be a 16-bit PNG: the error names --out.
    let line = one_error_line(&[
        "distance",
        "--shape",
        "4,5,6",
        "--source",
        "1,1,1",
        "--out",
        s(&path(&dir, "v.png16")),
    ]);
    assert!(line.starts_with("geodex: --out: cannot write"), "{line}");
}

#[test]
fn design_is_taken_wherever_a_cost_is_read() {
    let dir = TempDir::new().unwrap();
    let img = path(&dir, "img.npy");
    write_npy(&img, &band_image([24, 24])).unwrap();
    let run = |args: &[&str]| {
        let o = geodex(args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    let differs = |a: &Path, b: &Path| {
        let (a, b): (ArrayD<f64>, ArrayD<f64>) = (read_npy(a).unwrap(), read_npy(b).unwrap());
        assert_eq!(a.shape(), b.shape());
        a.iter().zip(b.iter()).any(|(x, y)| (x - y).abs() > 1e-6)
    };
    let (plain, designed, json) = (
        path(&dir, "plain.npy"),
        path(&dir, "designed.npy"),
        path(&dir, "json.npy"),
    );
    let distance = |out: &Path, design: Option<&str>| {
        let mut args = vec![
            "distance",
            "--cost",
            s(&img),
            "--source",
            "2,2",
            "--out",
            s(out),
        ];
        if let Some(d) = design {
            args.extend(["--design", d]);
        }
        run(&args);
    };
    distance(&plain, None);
    distance(&designed, Some("edges:mode=barrier,sigma=1.5"));
    distance(
        &json,
        Some(r#"{"kind": "edges", "mode": "barrier", "sigma": 1.5}"#),
    );
    assert!(differs(&plain, &designed), "--design changed nothing");
    assert!(
        !differs(&designed, &json),
        "the short form and the JSON differ"
    );

    let segment = |out: &Path, design: Option<&str>| {
        let labels = path(&dir, "l.npy");
        let mut args = vec![
            "segment",
            "--cost",
            s(&img),
            "--seed",
            "1:2,20",
            "--seed",
            "2:20,2",
            "--out",
            s(&labels),
            "--distance",
            s(out),
        ];
        if let Some(d) = design {
            args.extend(["--design", d]);
        }
        run(&args);
    };
    segment(&plain, None);
    segment(&designed, Some("intensity:value=2,power=2"));
    assert!(
        differs(&plain, &designed),
        "segment: --design changed nothing"
    );

    for command in ["sample", "cost-gradient", "group", "offset"] {
        let mut args = vec![command, "--design", "edges"];
        let keys = path(&dir, "k.json");
        std::fs::write(&keys, "[[2, 2], [20, 20]]").unwrap();
        match command {
            "sample" => args.extend(["--cost", s(&img), "--count", "3"]),
            "cost-gradient" => {
                args.extend(["--cost", s(&img), "--source", "2,2", "--target", "20,20"])
            }
            "group" => args.extend(["--cost", s(&img), "--key-points", s(&keys)]),
            _ => args.extend([
                "--mask",
                s(&img),
                "--radius",
                "2",
                "--geodesic",
                "--cost",
                s(&img),
            ]),
        }
        let out = path(
            &dir,
            if command == "group" {
                "g.json"
            } else {
                "o.npy"
            },
        );
        args.extend(["--out", s(&out)]);
        run(&args);
    }
    // A design without an image, and a design that is none, name --design.
    let line = one_error_line(&[
        "segment",
        "--shape",
        "8,8",
        "--seed",
        "1:1,1",
        "--design",
        "edges",
        "--out",
        s(&plain),
    ]);
    assert!(line.starts_with("geodex: --design: "), "{line}");
    let line = one_error_line(&[
        "distance",
        "--cost",
        s(&img),
        "--source",
        "1,1",
        "--design",
        "blur",
        "--out",
        s(&plain),
    ]);
    assert!(
        line.starts_with("geodex: --design: ") && line.contains("blur"),
        "{line}"
    );
    let line = one_error_line(&[
        "distance",
        "--cost",
        s(&img),
        "--source",
        "1,1",
        "--design",
        "edges:sigma=-1",
        "--out",
        s(&plain),
    ]);
    assert!(line.starts_with("geodex: --design: "), "{line}");
}

#[test]
fn metric_writes_what_the_grid_metric_operation_gives() {
    use geodex::numerics::Control;
    use geodex::ops::grid_metric::GridMetricRequest;
    use geodex::ops::{InputArray, OpLimits, Operation};
    use std::collections::HashMap;
    use std::sync::Arc;

    let dir = TempDir::new().unwrap();
    let img = path(&dir, "img.npy");
    let picture = band_image([20, 26]);
    write_npy(&img, &picture).unwrap();
    let design = "vesselness:scales=1;2,polarity=bright";
    let (out, png) = (path(&dir, "w.npy"), path(&dir, "w.png"));
    for o in [&out, &png] {
        let r = geodex(&[
            "metric",
            "--image",
            s(&img),
            "--design",
            design,
            "--spacing",
            "1,1",
            "--out",
            s(o),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        assert!(
            r.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&r.stderr)
        );
    }
    let w: ArrayD<f64> = read_npy(&out).unwrap();
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));

    let request: GridMetricRequest = serde_json::from_value(serde_json::json!({
        "cost": {"dataset": "img", "design": {"kind": "vesselness", "scales": [1, 2], "polarity": "bright"}},
        "spacing": [1, 1]
    }))
    .unwrap();
    let mut inputs = HashMap::new();
    inputs.insert(
        "img".to_string(),
        InputArray {
            array: Arc::new(geodex::io::ArrayData::F64(picture)),
            spacing: None,
        },
    );
    let expected = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let expected = match expected.array("metric").unwrap() {
        geodex::io::ArrayData::F64(a) => a.clone(),
        other => panic!("{other:?}"),
    };
    assert_same(&w, &expected);

    // Without --design the file's values are W; a bad --image names it.
    let line = one_error_line(&[
        "metric",
        "--image",
        s(&path(&dir, "none.npy")),
        "--out",
        s(&out),
    ]);
    assert!(line.starts_with("geodex: --image: cannot read"), "{line}");
    let line = one_error_line(&[
        "metric",
        "--image",
        s(&img),
        "--design",
        "edges",
        "--out",
        s(&path(&dir, "w.bmp")),
    ]);
    assert!(line.contains("--out: unknown extension '.bmp'"), "{line}");
}

#[test]
fn errors_name_the_command_line_flags_not_the_request_fields() {
    let dir = TempDir::new().unwrap();
    let out = path(&dir, "u.npy");
    let o = s(&out);
    let paths_json = path(&dir, "p.json");
    let no_field = |line: &str| {
        for field in [
            "sources[",
            "seeds[",
            "seed_image",
            "`seeds`",
            "ends[",
            "targets[",
            "cost.dataset",
        ] {
            assert!(
                !line.contains(field),
                "{line:?} names the request field {field}"
            );
        }
    };
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (
            vec![
                "distance", "--shape", "16,16", "--source", "40,1", "--out", o,
            ],
            &["geodex: --source 1: "],
        ),
        (
            vec!["segment", "--shape", "16,16", "--out", o],
            &["geodex: --seed: ", "--seed-image"],
        ),
        (
            vec![
                "segment", "--shape", "16,16", "--seed", "1:2,2", "--seed", "2:99,2", "--out", o,
            ],
            &["geodex: --seed 2: "],
        ),
        (
            vec!["segment", "--shape", "16,16", "--seed", "0:2,2", "--out", o],
            &["geodex: --seed 1: "],
        ),
        (
            vec![
                "cost-gradient",
                "--shape",
                "16,16",
                "--source",
                "2,2",
                "--target",
                "3,3",
                "--target",
                "3,99",
                "--out",
                o,
            ],
            &["geodex: --target 2: "],
        ),
        (
            vec![
                "cost-gradient",
                "--shape",
                "16,16",
                "--source",
                "99,2",
                "--target",
                "3,3",
                "--out",
                o,
            ],
            &["geodex: --source 1: "],
        ),
        (
            vec!["sample", "--shape", "16,16", "--out", o],
            &["geodex: --count: ", "`--radius`"],
        ),
        (
            vec![
                "path",
                "--shape",
                "16,16",
                "--source",
                "1,1",
                "--to",
                "30,1",
                "--out",
                s(&paths_json),
            ],
            &["geodex: --to 1: "],
        ),
        (
            vec![
                "distance",
                "--shape",
                "16,16",
                "--source",
                "1,1",
                "--spacing",
                "1,-1",
                "--out",
                o,
            ],
            &["geodex: --spacing value 2: "],
        ),
    ];
    for (args, needles) in cases {
        let line = one_error_line(&args);
        for n in needles {
            assert!(line.contains(n), "{args:?}: {line:?} lacks {n:?}");
        }
        no_field(&line);
        eprintln!("{line}");
    }
}

#[test]
fn no_progress_is_drawn_when_stderr_is_not_a_terminal() {
    let dir = TempDir::new().unwrap();
    let out = path(&dir, "u.npy");
    // Large enough to run past the one second after which a terminal would
    // get a bar (about 1.5 s in the test profile).
    let o = geodex(&[
        "distance",
        "--shape",
        "2500,2500",
        "--source",
        "3,3",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        o.stderr.is_empty(),
        "stderr: {:?}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.starts_with("geodex: wrote"), "{stdout}");
    assert!(
        !stdout.contains('\r') && !stdout.contains('\u{1b}'),
        "{stdout:?}"
    );
}

/// `geodex shape-embed` on a rectangle mask (convex: the inner distance is
/// Euclidean) gives the cells back up to a rigid motion, and its mesh; a
/// mask in two pieces is one stderr line naming `--mask`. `geodex isomap`
/// unrolls a swiss roll.
#[test]
fn shape_embed_and_isomap_write_their_outputs() {
    let dir = TempDir::new().unwrap();
    let mask = ArrayD::from_shape_fn(IxDyn(&[14, 30]), |ix| {
        u8::from((2..12).contains(&ix[0]) && (3..27).contains(&ix[1]))
    });
    let m = path(&dir, "m.npy");
    write_npy(&m, &mask).unwrap();
    let (x, c, mesh) = (
        path(&dir, "x.npy"),
        path(&dir, "c.npy"),
        path(&dir, "f.ply"),
    );
    let o = geodex(&[
        "shape-embed",
        "--mask",
        s(&m),
        "--landmarks",
        "12",
        "--out",
        s(&x),
        "--cells",
        s(&c),
        "--mesh",
        s(&mesh),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let xs: ndarray::Array2<f64> = read_npy(&x).unwrap();
    let c: ndarray::Array2<i64> = read_npy(&c).unwrap();
    assert_eq!(xs.dim(), (240, 2));
    assert_eq!(c.dim(), (240, 2));
    // Pairwise distances of the embedding are those of the cells.
    let mut worst = 0.0f64;
    for p in (0..240).step_by(7) {
        for q in (0..240).step_by(11) {
            let e = (xs[[p, 0]] - xs[[q, 0]]).hypot(xs[[p, 1]] - xs[[q, 1]]);
            let g = ((c[[p, 0]] - c[[q, 0]]) as f64).hypot((c[[p, 1]] - c[[q, 1]]) as f64);
            worst = worst.max((e - g).abs());
        }
    }
    assert!(worst < 0.6, "{worst}");
    assert!(std::fs::metadata(&mesh).unwrap().len() > 0);
    // Two pieces.
    let two = ArrayD::from_shape_fn(IxDyn(&[10, 10]), |ix| u8::from(ix[0] < 3 || ix[0] > 6));
    write_npy(&m, &two).unwrap();
    let o = geodex(&[
        "shape-embed",
        "--mask",
        s(&m),
        "--landmarks",
        "5",
        "--out",
        s(&x),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--mask") && err.contains("piece"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // Isomap of a swiss roll.
    let (roll, _) = geodex::numerics::shape::isomap::swiss_roll(500, 3);
    let p = path(&dir, "roll.npy");
    write_npy(&p, &roll).unwrap();
    let y = path(&dir, "y.npy");
    let o = geodex(&["isomap", "--points", s(&p), "--k", "10", "--out", s(&y)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let y: ndarray::Array2<f64> = read_npy(&y).unwrap();
    assert_eq!(y.dim(), (500, 2));
    let o = geodex(&[
        "isomap",
        "--points",
        s(&p),
        "--k",
        "1",
        "--out",
        s(&path(&dir, "z.npy")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--k"), "{err}");
}

#[test]
fn sample_takes_the_sampling_method() {
    let dir = TempDir::new().unwrap();
    let out = path(&dir, "u.npy");
    let stats = path(&dir, "s.json");
    for (method, block) in [("clustered", Some(3u64)), ("exact", None)] {
        let o = geodex(&[
            "sample",
            "--shape",
            "90,96",
            "--count",
            "100",
            "--sampling",
            method,
            "--out",
            s(&out),
            "--samples",
            s(&stats),
        ]);
        assert!(o.status.success(), "{o:?}");
        let doc: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        let sampling = &doc["stats"]["sampling"];
        assert_eq!(sampling["method"], method, "{doc}");
        assert_eq!(sampling["block"].as_u64(), block, "{doc}");
        assert_eq!(doc["samples"].as_array().map(Vec::len), Some(100));
        let u: ArrayD<f64> = read_npy(&out).unwrap();
        assert_eq!(u.shape(), &[90, 96]);
        assert!(u.iter().all(|v| v.is_finite()));
    }
    // An unknown method names the flag.
    let o = geodex(&[
        "sample",
        "--shape",
        "9,9",
        "--count",
        "3",
        "--sampling",
        "fast",
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--sampling"));
}
