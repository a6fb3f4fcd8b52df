//! Level-set and mask sources of `grid.distance` through the real server:
//! the signed distance to a circle's zero level set (the redistancing of
//! phi), a mask source, and the 422s of the bad cases, each naming its field.

use geodex::io::{self, ArrayData, Format, Limits};
use ndarray::ArrayD;
use serde_json::json;

use crate::common::{problem, spawn, TestApp};

const N: usize = 64;
const C: [f64; 2] = [31.4, 32.7];
const R: f64 = 17.3;

fn radius(i: usize, j: usize) -> f64 {
    (i as f64 - C[0]).hypot(j as f64 - C[1])
}

/// `phi = |x - c|² - r²`: the circle's zero level set, not a distance.
fn circle_phi() -> ArrayData {
    ArrayData::F64(ArrayD::from_shape_fn(ndarray::IxDyn(&[N, N]), |ix| {
        radius(ix[0], ix[1]).powi(2) - R * R
    }))
}

async fn distance(app: &TestApp, req: serde_json::Value) -> ArrayD<f64> {
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .header("accept", "application/x-npy")
        .json(&req)
        .send()
        .await
        .expect("post");
    assert_eq!(res.status(), 200, "{:?}", res.text().await);
    let bytes = res.bytes().await.expect("bytes");
    match io::decode(&bytes, Some(Format::Npy), &Limits::default())
        .expect("decode")
        .array
    {
        ArrayData::F64(a) => a,
        other => panic!("distance is f64, got {:?}", other.dtype()),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_level_set_source_gives_the_signed_distance_to_the_circle() {
    let app = spawn(|_| {}).await;
    let phi = app.upload(&circle_phi()).await;
    for (signed, order, bound) in [(true, 2, 0.05), (false, 2, 0.05), (true, 1, 0.3)] {
        let u = distance(
            &app,
            json!({
                "cost": {"constant": 1.0, "shape": [N, N]},
                "sources": [{"level_set": phi}],
                "order": order,
                "signed": signed
            }),
        )
        .await;
        let mut max = 0.0f64;
        for ((i, j), &v) in u
            .view()
            .into_dimensionality::<ndarray::Ix2>()
            .expect("2D")
            .indexed_iter()
        {
            // Within 8 cells of the interface (the centre, where fronts
            // converge, has an error of the scheme's own: tests/level_set.rs).
            let exact = radius(i, j) - R;
            if exact.abs() > 8.0 {
                continue;
            }
            let exact = if signed { exact } else { exact.abs() };
            max = max.max((v - exact).abs());
        }
        assert!(
            max <= bound,
            "signed {signed} order {order}: max error {max} > {bound} cell"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mask_source_is_zero_on_its_cells() {
    let app = spawn(|_| {}).await;
    // A 6 x 4 block of source cells.
    let mask = ArrayD::from_shape_fn(ndarray::IxDyn(&[32, 40]), |ix| {
        u8::from((10..16).contains(&ix[0]) && (20..24).contains(&ix[1]))
    });
    let id = app.upload(&ArrayData::U8(mask.clone())).await;
    let u = distance(
        &app,
        json!({
            "cost": {"constant": 2.0, "shape": [32, 40]},
            "sources": [{"mask": id}, {"point": [30.0, 2.0]}]
        }),
    )
    .await;
    for (ix, &m) in mask.indexed_iter() {
        if m != 0 {
            assert_eq!(u[&ix], 0.0, "{ix:?}");
        }
    }
    // Along row 13, right of the block: the distance is 2 (cost) times the gap.
    assert!((u[[13, 30]] - 2.0 * 7.0).abs() < 1e-9, "{}", u[[13, 30]]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_level_set_and_mask_sources_are_422_naming_the_field() {
    let app = spawn(|_| {}).await;
    let phi = app.upload(&circle_phi()).await;
    let positive = app
        .upload(&ArrayData::F64(ArrayD::from_elem(
            ndarray::IxDyn(&[N, N]),
            1.0,
        )))
        .await;
    let empty = app
        .upload(&ArrayData::U8(ArrayD::zeros(ndarray::IxDyn(&[N, N]))))
        .await;
    let small = app
        .upload(&ArrayData::F64(ArrayD::from_elem(
            ndarray::IxDyn(&[8, 8]),
            -1.0,
        )))
        .await;
    let grid = json!({"constant": 1.0, "shape": [N, N]});
    let cases = [
        (
            json!({"cost": grid, "sources": [{"level_set": positive}]}),
            "sources[0].level_set",
            "no zero level set",
        ),
        (
            json!({"cost": grid, "sources": [{"mask": empty}]}),
            "sources[0].mask",
            "no non-zero cell",
        ),
        (
            json!({"cost": grid, "sources": [{"level_set": small}]}),
            "sources[0].level_set",
            "shape",
        ),
        (
            json!({"cost": grid, "sources": [{"mask": small}]}),
            "sources[0].mask",
            "shape",
        ),
        (
            json!({"cost": grid, "sources": [{"level_set": phi}, {"point": [1.0, 1.0]}]}),
            "sources",
            "only source",
        ),
        (
            json!({"cost": grid, "sources": [{"level_set": phi, "point": [1.0, 1.0]}]}),
            "sources[0]",
            "exactly one of",
        ),
        (
            json!({"cost": grid, "sources": [{"point": [1.0, 1.0]}], "signed": true}),
            "signed",
            "level_set",
        ),
        (
            json!({"cost": grid, "sources": [{"level_set": "nope"}]}),
            "sources[0].level_set",
            "does not exist",
        ),
    ];
    for (req, field, words) in cases {
        let res = app
            .client
            .post(app.url("/v1/grid/distance"))
            .json(&req)
            .send()
            .await
            .expect("post");
        let status = if words == "does not exist" { 404 } else { 422 };
        let body = problem(res, status).await;
        assert_eq!(body["field"], field, "{req}: {body}");
        let detail = body["detail"].as_str().unwrap_or_default();
        assert!(detail.contains(words), "{req}: {detail}");
    }
    // grid.paths refuses them, saying where to go instead.
    let res = app
        .client
        .post(app.url("/v1/grid/paths"))
        .json(&json!({
            "cost": grid,
            "sources": [{"mask": empty}],
            "ends": [[1.0, 1.0]]
        }))
        .send()
        .await
        .expect("post");
    let body = problem(res, 422).await;
    assert_eq!(body["field"], "sources[0].mask", "{body}");
    assert!(
        body["detail"]
            .as_str()
            .is_some_and(|d| d.contains("grid.distance")),
        "{body}"
    );
}
