//! The segmentation operations end to end through their request structs
//! (`ops::grid_{edt,segment,skeleton,offset,plan}`), with the bounds.

use std::collections::HashMap;
use std::sync::Arc;

use geodex::io::ArrayData;
use geodex::numerics::segmentation::dice;
use geodex::numerics::Control;
use geodex::ops::grid_edt::{EdtMode, GridEdtRequest};
use geodex::ops::grid_offset::{GridOffsetRequest, OffsetMetric, OffsetOperation};
use geodex::ops::grid_plan::GridPlanRequest;
use geodex::ops::grid_segment::{GridSegmentRequest, SeedSpec};
use geodex::ops::grid_skeleton::GridSkeletonRequest;
use geodex::ops::spec::cost::{CostSpec, InterpretationSpec};
use geodex::ops::{InputArray, OpError, OpLimits, OpOutput, Operation};
use ndarray::ArrayD;

fn input(a: ArrayData) -> InputArray {
    InputArray {
        array: Arc::new(a),
        spacing: None,
    }
}

fn arr2<T>(n0: usize, n1: usize, v: Vec<T>) -> ArrayD<T> {
    ArrayD::from_shape_vec(vec![n0, n1], v).unwrap()
}

fn out_f64(out: &OpOutput, name: &str) -> Vec<f64> {
    match &out.arrays.iter().find(|a| a.name == name).unwrap().array {
        ArrayData::F64(a) => a.iter().copied().collect(),
        other => panic!("{name}: {:?}", other.dtype()),
    }
}

fn out_i32(out: &OpOutput, name: &str) -> Vec<i32> {
    match &out.arrays.iter().find(|a| a.name == name).unwrap().array {
        ArrayData::I32(a) => a.iter().copied().collect(),
        other => panic!("{name}: {:?}", other.dtype()),
    }
}

fn out_u8(out: &OpOutput, name: &str) -> Vec<u8> {
    match &out.arrays.iter().find(|a| a.name == name).unwrap().array {
        ArrayData::U8(a) => a.iter().copied().collect(),
        other => panic!("{name}: {:?}", other.dtype()),
    }
}

/// Deterministic standard normal samples (LCG + Box–Muller).
fn normals(n: usize, mut state: u64) -> Vec<f64> {
    let mut uni = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let (a, b) = (uni(), uni());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        })
        .collect()
}

#[test]
fn three_discs_are_segmented_with_dice_at_least_98_percent() {
    let n = 128;
    let discs = [
        ([34.0, 34.0], 20.0, 0.9),
        ([92.0, 40.0], 22.0, 0.2),
        ([64.0, 96.0], 24.0, 0.7),
    ];
    let inside = |k: usize, d: usize| {
        let (i, j) = ((k / n) as f64, (k % n) as f64);
        let (c, r, _) = discs[d];
        ((i - c[0]).powi(2) + (j - c[1]).powi(2)).sqrt() <= r
    };
    let noise = normals(n * n, 7);
    let image: Vec<f64> = (0..n * n)
        .map(|k| {
            let base = (0..3).find(|&d| inside(k, d)).map_or(0.5, |d| discs[d].2);
            base + 0.05 * noise[k]
        })
        .collect();
    // Metric: the edge barrier of `cost.design`, W = eps + g^2 with g the
    // normalised gradient magnitude of the image smoothed at sigma = 1.5:
    // cheap inside regions, expensive across their edges.
    // One seed in each disc, and the background as a scribble along the border.
    let mut scribble = vec![0u8; n * n];
    for k in 0..n {
        for c in [k, (n - 1) * n + k, k * n, k * n + n - 1] {
            scribble[c] = 4;
        }
    }
    let inputs: HashMap<String, InputArray> = HashMap::from([
        ("w".to_string(), input(ArrayData::F64(arr2(n, n, image)))),
        ("s".to_string(), input(ArrayData::U8(arr2(n, n, scribble)))),
    ]);
    let request = GridSegmentRequest {
        metric: None,
        cost: Some(CostSpec {
            dataset: Some("w".into()),
            constant: None,
            shape: None,
            interpretation: InterpretationSpec::Cost,
            design: Some(
                serde_json::from_value(serde_json::json!({
                    "kind": "edges", "mode": "barrier", "sigma": 1.5, "power": 2.0, "epsilon": 1e-3
                }))
                .unwrap(),
            ),
        }),
        spacing: None,
        obstacles: None,
        seeds: discs
            .iter()
            .enumerate()
            .map(|(d, (c, _, _))| SeedSpec {
                label: d as i32 + 1,
                point: Some(c.to_vec()),
                cells: None,
            })
            .collect(),
        seed_image: Some("s".into()),
        max_distance: None,
        order: 2,
        contours: true,
    };
    let out = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let labels = out_i32(&out, "labels");
    for d in 0..3 {
        let truth: Vec<bool> = (0..n * n).map(|k| inside(k, d)).collect();
        let got: Vec<bool> = labels.iter().map(|&l| l == d as i32 + 1).collect();
        let score = dice(&truth, &got);
        assert!(score >= 0.98, "disc {}: Dice {score}", d + 1);
    }
    // Confidence = second - first, 0 on the boundaries, never negative.
    let first = out_f64(&out, "distance");
    let second = out_f64(&out, "second_distance");
    let conf = out_f64(&out, "confidence");
    for k in 0..n * n {
        assert!(second[k] >= first[k]);
        assert!((conf[k] - (second[k] - first[k])).abs() < 1e-12);
    }
    // GeoJSON: one feature per label, the disc polygons cover their areas within 2 %.
    let features = out.document["contours"]["features"].as_array().unwrap();
    assert_eq!(features.len(), 4);
    for f in features {
        let label = f["properties"]["label"].as_i64().unwrap();
        let cells = f["properties"]["cells"].as_u64().unwrap() as f64;
        let polys = f["geometry"]["coordinates"].as_array().unwrap();
        let area: f64 = polys
            .iter()
            .flat_map(|p| p.as_array().unwrap().iter())
            .map(|ring| {
                let pts: Vec<[f64; 2]> = ring
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()])
                    .collect();
                geodex::numerics::contours::ring_area(&pts)
            })
            .sum();
        assert_eq!(
            area, cells,
            "label {label}: polygons cover exactly its cells"
        );
        if label <= 3 {
            let r = discs[label as usize - 1].1;
            assert!((area / (std::f64::consts::PI * r * r) - 1.0).abs() < 0.02);
        }
    }
}

#[test]
fn geodesic_ball_and_seed_errors() {
    let inputs: HashMap<String, InputArray> = HashMap::new();
    let mut request = GridSegmentRequest {
        metric: None,
        cost: Some(CostSpec {
            dataset: None,
            constant: Some(1.0),
            shape: Some(vec![41, 41]),
            interpretation: InterpretationSpec::Cost,
            design: None,
        }),
        spacing: None,
        obstacles: None,
        seeds: vec![SeedSpec {
            label: 3,
            point: Some(vec![20.0, 20.0]),
            cells: None,
        }],
        seed_image: None,
        max_distance: Some(10.0),
        order: 2,
        contours: false,
    };
    let out = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let ball = out_u8(&out, "ball");
    let area = ball.iter().filter(|&&b| b == 1).count() as f64;
    // The ball of radius 10 around a point: pi r^2 = 314 cells, within 3 %.
    assert!(
        (area / (std::f64::consts::PI * 100.0) - 1.0).abs() < 0.03,
        "{area}"
    );
    let labels = out_i32(&out, "labels");
    assert!(labels.iter().all(|&l| l == 3 || l == -1));
    request.seeds[0].point = Some(vec![80.0, 2.0]);
    let err = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap_err();
    assert_eq!(err.field(), Some("seeds[0]"), "{err}");
    request.seeds[0].label = 0;
    let err = request.validate(&OpLimits::default()).unwrap_err();
    assert_eq!(err.field(), Some("seeds[0].label"));
}

fn disc_mask(n: usize, c: f64, r: f64) -> Vec<u8> {
    (0..n * n)
        .map(|k| {
            let (i, j) = ((k / n) as f64, (k % n) as f64);
            u8::from(((i - c).powi(2) + (j - c).powi(2)).sqrt() <= r)
        })
        .collect()
}

#[test]
fn offset_of_a_disc_is_the_larger_disc_and_obstacles_block_it() {
    let n = 160;
    let inputs: HashMap<String, InputArray> = HashMap::from([(
        "m".to_string(),
        input(ArrayData::U8(arr2(n, n, disc_mask(n, 80.0, 25.0)))),
    )]);
    let mut request = GridOffsetRequest {
        mask: "m".into(),
        radius: 15.0,
        operation: OffsetOperation::Dilate,
        metric: OffsetMetric::Euclidean,
        cost: None,
        obstacles: None,
        spacing: None,
    };
    let out = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let area = out_u8(&out, "offset").iter().filter(|&&v| v == 1).count() as f64;
    let exact = std::f64::consts::PI * 40.0 * 40.0;
    assert!((area / exact - 1.0).abs() < 0.01, "{area} vs {exact}");
    // Geodesic (unit cost, fast marching) gives the exact Euclidean dilation
    // of the mask cells (4985 cells, 0.8 % under the continuous disc's
    // area) within 1 %.
    let euclidean = area;
    request.metric = OffsetMetric::Geodesic;
    let out = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let area = out_u8(&out, "offset").iter().filter(|&&v| v == 1).count() as f64;
    assert!(
        (area / euclidean - 1.0).abs() < 0.01,
        "geodesic: {area} vs {euclidean}"
    );
    // A wall right of the disc: nothing beyond it is reached.
    let mut wall = vec![0u8; n * n];
    for i in 0..n {
        wall[i * n + 110] = 1;
    }
    let mut inputs = inputs;
    inputs.insert("o".into(), input(ArrayData::U8(arr2(n, n, wall))));
    request.metric = OffsetMetric::Euclidean;
    request.obstacles = Some("o".into());
    request.radius = 40.0;
    let out = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let off = out_u8(&out, "offset");
    assert!((0..n).all(|i| (110..n).all(|j| off[i * n + j] == 0)));
    assert_eq!(off[80 * n + 109], 1);
    request.cost = Some(CostSpec {
        dataset: None,
        constant: Some(1.0),
        shape: Some(vec![n, n]),
        interpretation: InterpretationSpec::Cost,
        design: None,
    });
    assert_eq!(
        request.validate(&OpLimits::default()).unwrap_err().field(),
        Some("cost")
    );
}

#[test]
fn edt_skeleton_and_plan_through_their_requests() {
    let n = 60;
    let mut inputs: HashMap<String, InputArray> = HashMap::new();
    let mut m = vec![0u8; n * n];
    m[10 * n + 20] = 1;
    inputs.insert("m".into(), input(ArrayData::U8(arr2(n, n, m))));
    let request = GridEdtRequest {
        mask: "m".into(),
        spacing: Some(vec![2.0, 0.5]),
        mode: EdtMode::Binary,
        features: true,
    };
    let out = request
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    let d = out_f64(&out, "distance");
    assert_eq!(d[13 * n + 24], (36.0f64 + 4.0).sqrt());
    match &out.arrays[1].array {
        ArrayData::I64(f) => assert!(f.iter().all(|&v| v == (10 * n + 20) as i64)),
        other => panic!("{:?}", other.dtype()),
    }

    // Skeleton of a disc with pruning: its centre, one node, no branch.
    inputs.insert(
        "disc".into(),
        input(ArrayData::U8(arr2(n, n, disc_mask(n, 30.0, 20.0)))),
    );
    let sk = GridSkeletonRequest {
        mask: "disc".into(),
        spacing: None,
        min_boundary_length: 0.0,
        min_boundary_fraction: 0.08,
    }
    .run(&inputs, &OpLimits::default(), &Control::new())
    .unwrap();
    let cells: Vec<usize> = out_u8(&sk, "skeleton")
        .iter()
        .enumerate()
        .filter(|(_, &v)| v == 1)
        .map(|(k, _)| k)
        .collect();
    // A digital disc's axis is its centre plus a small star of digitisation
    // spokes; pruning keeps every cell within 0.3 R of the centre.
    assert!(!cells.is_empty(), "{cells:?}");
    for k in &cells {
        let (i, j) = ((k / n) as f64, (k % n) as f64);
        assert!(
            ((i - 30.0).powi(2) + (j - 30.0).powi(2)).sqrt() <= 6.0,
            "{k}"
        );
    }
    let radius = out_f64(&sk, "radius");
    assert!(cells
        .iter()
        .all(|&k| radius[k] >= 14.0 && radius[k] <= 21.5));
    assert!(
        cells.iter().any(|&k| radius[k] >= 20.0),
        "the centre cells have radius ~20"
    );

    // Planning: a wall with a 7-cell gap.
    let mut o = vec![0u8; n * n];
    for i in 0..n {
        if !(27..34).contains(&i) {
            o[i * n + 30] = 1;
        }
    }
    inputs.insert("o".into(), input(ArrayData::U8(arr2(n, n, o))));
    let mut plan = GridPlanRequest {
        obstacles: "o".into(),
        radius: 5.0,
        start: vec![30.0, 5.0],
        goal: vec![30.0, 55.0],
        spacing: None,
    };
    let err = plan
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap_err();
    match err {
        OpError::Invalid { field, reason } => {
            assert_eq!(field, "radius");
            assert!(reason.contains("no collision-free path"), "{reason}");
            assert!(reason.contains("radius 4"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    plan.radius = 3.5;
    let out = plan
        .run(&inputs, &OpLimits::default(), &Control::new())
        .unwrap();
    assert_eq!(out.document["widest_radius"], 4.0);
    assert!(out.document["min_clearance"].as_f64().unwrap() >= 3.5);
    let path = out.document["path"].as_array().unwrap();
    assert_eq!(path[0], serde_json::json!([30.0, 5.0]));
    assert_eq!(path[path.len() - 1], serde_json::json!([30.0, 55.0]));
}
