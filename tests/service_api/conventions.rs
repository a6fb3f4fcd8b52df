//! The API's conventions, one test per output kind (see the OpenAPI
//! `info.description` and README "Conventions"): points in array index
//! order (`[row, column]`) except GeoJSON (`[x, y] = [column, row]`), every
//! path from its source to its end, one name per concept, and the old
//! spellings refused with 422 naming the new one.
//!
//! The grids are 20 × 64 with points such as (row 5, column 40): read with
//! the axes swapped, a point falls outside the grid or far from where it
//! should be.

use geodex::io::ArrayData;
use ndarray::{ArrayD, IxDyn};
use serde_json::{json, Value};

use crate::common::{problem, spawn, TestApp};

const SHAPE: [usize; 2] = [20, 64];
const SOURCE: [f64; 2] = [5.0, 40.0];
const END: [f64; 2] = [15.0, 3.0];

async fn post(app: &TestApp, path: &str, body: &Value) -> reqwest::Response {
    app.client
        .post(app.url(path))
        .json(body)
        .send()
        .await
        .expect("post")
}

async fn ok(app: &TestApp, path: &str, body: &Value) -> Value {
    let res = post(app, path, body).await;
    let status = res.status();
    let text = res.text().await.expect("body");
    assert_eq!(status, 200, "{path}: {text}");
    serde_json::from_str(&text).expect("json")
}

fn xy(v: &Value) -> [f64; 2] {
    [v[0].as_f64().expect("x"), v[1].as_f64().expect("y")]
}

fn near(p: [f64; 2], q: [f64; 2], tol: f64) -> bool {
    (p[0] - q[0]).abs() <= tol && (p[1] - q[1]).abs() <= tol
}

/// Index points `[row, column]` inside the 20 × 64 grid.
fn inside(p: [f64; 2]) -> bool {
    (-0.5..=19.5).contains(&p[0]) && (-0.5..=63.5).contains(&p[1])
}

/// Twice the signed area of a closed ring in its own `(x, y)` plane.
fn twice_area(ring: &[[f64; 2]]) -> f64 {
    ring.windows(2)
        .map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1])
        .sum()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grid_path_points_are_row_column_from_source_to_end_and_geojson_is_x_y() {
    let app = spawn(|_| {}).await;
    // Spacing 2 along the columns: world = index × spacing, GeoJSON = [column × 2, row × 1].
    let body = json!({
        "cost": {"constant": 1.0, "shape": SHAPE}, "spacing": [1.0, 2.0],
        "sources": [{"point": SOURCE}], "ends": [END]
    });
    let v = ok(&app, "/v1/grid/paths", &body).await;
    let p = &v["paths"][0];
    let points = p["points"].as_array().expect("points");
    assert!(near(xy(&points[0]), SOURCE, 0.5), "first {}", points[0]);
    assert!(near(xy(points.last().unwrap()), END, 1e-9), "last {p}");
    assert!(points.iter().all(|q| inside(xy(q))));
    let world = p["world"].as_array().expect("world");
    assert!(near(xy(&world[0]), [5.0, 80.0], 1.0), "{}", world[0]);
    assert_eq!(p["end"], json!(END));
    assert_eq!(p["source"], 0);
    assert!(p["geodesic_length"].as_f64().unwrap() > 0.0 && p["euclidean_length"].is_number());

    let mut geo = body.clone();
    geo["format"] = json!("geojson");
    let g: Value = post(&app, "/v1/grid/paths", &geo)
        .await
        .json()
        .await
        .unwrap();
    let c = g["features"][0]["geometry"]["coordinates"]
        .as_array()
        .expect("coordinates");
    assert!(near(xy(&c[0]), [80.0, 5.0], 1.0), "first {}", c[0]);
    assert!(near(xy(c.last().unwrap()), [6.0, 15.0], 1e-9), "last");
    assert!(g["features"][0]["properties"]["geodesic_length"].is_number());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_contours_are_geojson_x_y_counter_clockwise() {
    let app = spawn(|_| {}).await;
    let v = ok(
        &app,
        "/v1/grid/segment",
        &json!({
            "cost": {"constant": 1.0, "shape": SHAPE},
            "seeds": [{"label": 1, "point": [5.0, 10.0]}, {"label": 2, "point": [5.0, 50.0]}]
        }),
    )
    .await;
    let features = v["contours"]["features"].as_array().expect("features");
    assert_eq!(features.len(), 2);
    for f in features {
        let label = f["properties"]["label"].as_i64().unwrap();
        let polygons = f["geometry"]["coordinates"].as_array().unwrap();
        let mut xs = Vec::new();
        for poly in polygons {
            let rings = poly.as_array().unwrap();
            for (k, ring) in rings.iter().enumerate() {
                let ring: Vec<[f64; 2]> = ring.as_array().unwrap().iter().map(xy).collect();
                // [x, y] = [column, row]: y stays within the 20 rows.
                for p in &ring {
                    assert!((-0.5..=63.5).contains(&p[0]) && (-0.5..=19.5).contains(&p[1]));
                    xs.push(p[0]);
                }
                // RFC 7946: outer rings counter-clockwise.
                if k == 0 {
                    assert!(
                        twice_area(&ring) > 0.0,
                        "label {label}: clockwise outer ring"
                    );
                }
            }
        }
        let (lo, hi) = xs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        // Label 1 holds the left columns (up to the bisector at column 30), label 2 the right ones.
        match label {
            1 => assert!(lo == -0.5 && (29.0..=31.0).contains(&hi), "{lo} {hi}"),
            2 => assert!((29.0..=31.0).contains(&lo) && hi == 63.5, "{lo} {hi}"),
            _ => panic!("label {label}"),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tensor_paths_run_from_source_to_end_with_the_grid_names() {
    let app = spawn(|_| {}).await;
    let v = ok(
        &app,
        "/v1/grid/tensor-distance",
        &json!({
            "metric": {"kind": "eigen", "shape": SHAPE, "eigenvalues": [1.0, 1.0], "direction": [1.0, 0.0]},
            "sources": [{"point": SOURCE}], "ends": [END]
        }),
    )
    .await;
    let p = &v["paths"][0];
    let points = p["points"].as_array().expect("points");
    assert!(near(xy(&points[0]), SOURCE, 0.5), "first {}", points[0]);
    assert!(near(xy(points.last().unwrap()), END, 1e-6), "last");
    assert!(points.iter().all(|q| inside(xy(q))));
    assert_eq!(p["end"], json!(END));
    let exact = (10.0f64 * 10.0 + 37.0 * 37.0).sqrt();
    for name in ["geodesic_length", "euclidean_length"] {
        let l = p[name].as_f64().expect(name);
        assert!((l - exact).abs() < 0.05 * exact, "{name} {l} vs {exact}");
    }
    for old in ["length", "distance", "reached_source"] {
        assert!(p.get(old).is_none(), "{old} is gone");
    }
}

/// A planar 8 × 5 grid of vertices (vertex `i * 8 + j` at `(x, y) = (j, i)`), two triangles per square.
fn plane_obj() -> String {
    let mut s = String::new();
    for i in 0..5 {
        for j in 0..8 {
            s += &format!("v {j} {i} 0\n");
        }
    }
    for i in 0..4 {
        for j in 0..7 {
            let a = i * 8 + j + 1;
            s += &format!("f {a} {} {}\nf {a} {} {}\n", a + 1, a + 9, a + 9, a + 8);
        }
    }
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mesh_paths_run_from_source_to_end_with_the_grid_names() {
    let app = spawn(|_| {}).await;
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "model/obj")
        .body(plane_obj())
        .send()
        .await
        .expect("upload");
    assert_eq!(res.status(), 201);
    let id = res.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let exact = (7.0f64 * 7.0 + 4.0 * 4.0).sqrt();
    for method in ["exact", "fast_marching"] {
        let v = ok(
            &app,
            "/v1/mesh/paths",
            &json!({"mesh": id, "sources": [{"vertex": 0}], "ends": [{"vertex": 39}], "method": method}),
        )
        .await;
        let p = &v["paths"][0];
        assert_eq!(p["index"], 0);
        assert_eq!(p["source"], 0);
        let points = p["points"].as_array().expect("points");
        let first = &points[0]["position"];
        let last = &points.last().unwrap()["position"];
        assert_eq!(points[0]["vertex"], 0, "{method}: {}", points[0]);
        assert!(near(xy(first), [0.0, 0.0], 1e-9), "{method}");
        assert_eq!(points.last().unwrap()["vertex"], 39, "{method}");
        assert!(near(xy(last), [7.0, 4.0], 1e-9), "{method}");
        let g = p["geodesic_length"].as_f64().unwrap();
        let e = p["euclidean_length"].as_f64().unwrap();
        let tol = if method == "exact" { 1e-9 } else { 0.05 };
        assert!((g - exact).abs() <= tol * exact, "{method}: {g} vs {exact}");
        assert!((e - exact).abs() <= tol * exact, "{method}: {e} vs {exact}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn skeleton_edges_and_plans_are_row_column_and_run_in_order() {
    let app = spawn(|_| {}).await;
    // A bar over rows 8..=12 and columns 5..=58.
    let mask = ArrayD::from_shape_fn(IxDyn(&SHAPE), |ix| {
        u8::from((8..=12).contains(&ix[0]) && (5..=58).contains(&ix[1]))
    });
    let id = app.upload(&ArrayData::U8(mask)).await;
    let v = ok(&app, "/v1/grid/skeleton", &json!({"mask": id})).await;
    let nodes = v["graph"]["nodes"].as_array().expect("nodes");
    let edges = v["graph"]["edges"].as_array().expect("edges");
    assert!(!edges.is_empty());
    let mut widest = 0.0f64;
    for e in edges {
        let pts: Vec<[f64; 2]> = e["points"].as_array().unwrap().iter().map(xy).collect();
        let node = |k: &str| {
            let n = e[k].as_u64().unwrap() as usize;
            xy(&nodes.iter().find(|m| m["id"] == n).expect("node")["point"])
        };
        assert!(near(pts[0], node("source"), 1.5), "{e}");
        assert!(near(*pts.last().unwrap(), node("target"), 1.5), "{e}");
        for p in &pts {
            assert!(inside(*p) && (7.0..=13.0).contains(&p[0]), "{p:?}");
            widest = widest.max(p[1]);
        }
        assert!(e["euclidean_length"].is_number() && e.get("length").is_none());
    }
    assert!(widest > 40.0, "the bar's axis runs along the columns");

    // A disc robot's plan in free space: from start to goal, [row, column].
    let free = app
        .upload(&ArrayData::U8(ArrayD::zeros(IxDyn(&SHAPE))))
        .await;
    let v = ok(
        &app,
        "/v1/grid/plan",
        &json!({"obstacles": free, "radius": 1.0, "start": SOURCE, "goal": END}),
    )
    .await;
    let path: Vec<[f64; 2]> = v["path"].as_array().unwrap().iter().map(xy).collect();
    assert!(near(path[0], SOURCE, 0.5), "{:?}", path[0]);
    assert!(near(*path.last().unwrap(), END, 0.5));
    assert!(path.iter().all(|p| inside(*p)));
    let exact = (10.0f64 * 10.0 + 37.0 * 37.0).sqrt();
    let l = v["euclidean_length"].as_f64().expect("euclidean_length");
    assert!(l >= exact - 1e-9 && l < 1.1 * exact, "{l} vs {exact}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn samples_are_row_column_and_group_links_and_geojson_follow_the_rules() {
    let app = spawn(|_| {}).await;
    let v = ok(
        &app,
        "/v1/grid/sample",
        &json!({"cost": {"constant": 1.0, "shape": SHAPE}, "count": 6, "seeds": [[5, 40]]}),
    )
    .await;
    let samples: Vec<[f64; 2]> = v["samples"].as_array().unwrap().iter().map(xy).collect();
    assert_eq!(samples[0], [5.0, 40.0], "seeds first, [row, column]");
    assert!(samples.iter().all(|p| inside(*p)));
    // The farthest cell from (5, 40) is the corner (19, 0).
    assert_eq!(samples[1], [19.0, 0.0]);

    // Four key points along row 5: one open chain, links from pair[0] to pair[1].
    let keys = [[5.0, 10.0], [5.0, 25.0], [5.0, 40.0], [5.0, 55.0]];
    let v = ok(
        &app,
        "/v1/grid/group",
        &json!({"cost": {"constant": 1.0, "shape": SHAPE}, "key_points": keys}),
    )
    .await;
    let kept: Vec<&Value> = v["links"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|l| l["kept"] == true)
        .collect();
    assert_eq!(kept.len(), 3, "{}", v["links"]);
    for l in kept {
        let (a, b) = (
            l["pair"][0].as_u64().unwrap(),
            l["pair"][1].as_u64().unwrap(),
        );
        let path = l["path"].as_array().unwrap();
        assert!(near(xy(&path[0]), keys[a as usize], 0.5), "{l}");
        assert!(near(xy(path.last().unwrap()), keys[b as usize], 0.5), "{l}");
        assert!(
            (l["geodesic_length"].as_f64().unwrap() - 15.0).abs() < 0.5,
            "{l}"
        );
        assert!(
            (l["euclidean_length"].as_f64().unwrap() - 15.0).abs() < 0.5,
            "{l}"
        );
    }
    let c = v["geojson"]["features"][0]["geometry"]["coordinates"]
        .as_array()
        .expect("a contour");
    for p in c {
        let [x, y] = xy(p);
        assert!(
            (9.5..=55.5).contains(&x) && (y - 5.0).abs() < 0.5,
            "[x, y] = [column, row]: {p}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn grid_metric_takes_the_cost_and_metric_sections() {
    let app = spawn(|_| {}).await;
    let image = ArrayD::from_shape_fn(IxDyn(&SHAPE), |ix| (ix[1] * 4) as u8);
    let id = app.upload(&ArrayData::U8(image)).await;
    let v = ok(
        &app,
        "/v1/grid/metric",
        &json!({"cost": {"dataset": id, "design": {"kind": "intensity", "value": 0}}}),
    )
    .await;
    assert_eq!(v["metric"]["shape"], json!(SHAPE));
    // f mapped to [0, 1] over columns 0..63: W = |f - 0|^2 + 0.01 from 0.01 to 1.01.
    assert!(
        (v["stats"]["min"].as_f64().unwrap() - 0.01).abs() < 1e-12,
        "{v}"
    );
    assert!(
        (v["stats"]["max"].as_f64().unwrap() - 1.01).abs() < 1e-12,
        "{v}"
    );
    let v = ok(
        &app,
        "/v1/grid/metric",
        &json!({"metric": {"kind": "eigen", "shape": SHAPE, "eigenvalues": [1.0, 4.0], "direction": [1.0, 0.0]}}),
    )
    .await;
    assert_eq!(v["metric"]["shape"], json!([20, 64, 3]));
    assert!((v["stats"]["max_anisotropy"].as_f64().unwrap() - 2.0).abs() < 1e-9);
    let p = problem(
        post(
            &app,
            "/v1/grid/metric",
            &json!({"cost": {"constant": 1.0, "shape": SHAPE}, "metric": {"kind": "eigen", "shape": SHAPE, "eigenvalues": [1.0, 4.0], "direction": [1.0, 0.0]}}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(p["field"], "metric");
}

/// Every old spelling, sent to its endpoint: 422 on the old field, the detail naming the new one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn old_spellings_answer_422_naming_the_new_one() {
    let app = spawn(|_| {}).await;
    let cost = json!({"constant": 1.0, "shape": SHAPE});
    let eigen = json!({"kind": "eigen", "shape": SHAPE, "eigenvalues": [1.0, 4.0], "direction": [1.0, 0.0]});
    let cases = [
        (
            "/v1/mesh/paths",
            json!({"mesh": "ds_x", "sources": [{"vertex": 0}], "targets": [{"vertex": 5}]}),
            "targets",
            "`ends`",
        ),
        (
            "/v1/mesh/distance",
            json!({"mesh": "ds_x", "sources": [{"vertex": 0}], "method": "fast-marching"}),
            "method",
            "`fast_marching`",
        ),
        (
            "/v1/mesh/sample",
            json!({"mesh": "ds_x", "count": 3, "method": "fast-marching"}),
            "method",
            "`fast_marching`",
        ),
        (
            "/v1/grid/distance",
            json!({"cost": cost, "sources": [{"point": SOURCE}], "method": "fast-marching"}),
            "method",
            "`fast_marching`",
        ),
        (
            "/v1/grid/metric",
            json!({"dataset": "ds_x", "design": {"kind": "edges"}}),
            "dataset",
            "`cost.dataset`",
        ),
        (
            "/v1/grid/metric",
            json!({"design": {"kind": "edges"}}),
            "design",
            "`cost.design`",
        ),
        (
            "/v1/grid/tensor-distance",
            json!({"tensor": eigen, "sources": [{"point": SOURCE}]}),
            "tensor",
            "`metric`",
        ),
        (
            "/v1/grid/tensor-distance",
            json!({"metric": eigen, "sources": [{"point": SOURCE}], "paths": [END]}),
            "paths",
            "`ends`",
        ),
        (
            "/v1/grid/tensor-distance",
            json!({"metric": eigen, "sources": [{"point": SOURCE}], "ends": [END], "path_step": 0.5}),
            "path_step",
            "`step`",
        ),
        (
            "/v1/grid/tensor-metric",
            json!({"tensor": eigen}),
            "tensor",
            "`metric`",
        ),
    ];
    for (path, body, field, new) in cases {
        let p = problem(post(&app, path, &body).await, 422).await;
        assert_eq!(p["field"], field, "{path}: {p}");
        let detail = p["detail"].as_str().unwrap();
        assert!(
            detail.contains("was renamed") && detail.contains(new),
            "{path}: {detail}"
        );
    }
    // The job queue parses the same request types: the same answer, under `params`.
    let res = post(
        &app,
        "/v1/jobs",
        &json!({"operation": "mesh.paths", "params": {"mesh": "ds_x", "sources": [{"vertex": 0}], "targets": [{"vertex": 5}]}}),
    )
    .await;
    let p = problem(res, 422).await;
    assert_eq!(p["field"], "params.targets", "{p}");
    assert!(p["detail"].as_str().unwrap().contains("`ends`"), "{p}");
}
