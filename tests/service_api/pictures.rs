//! The picture parameters of `GET /v1/datasets/{id}/data?format=png`.

use geodex::io::{ArrayData, Colormap};
use ndarray::ArrayD;

use crate::common::{problem, spawn};

/// Writes a picture to `/tmp/pics/http_<name>.png` when `GEODEX_PICS` is set.
fn keep(name: &str, bytes: &[u8]) {
    if std::env::var_os("GEODEX_PICS").is_some() {
        let _ = std::fs::create_dir_all("/tmp/pics");
        let _ = std::fs::write(format!("/tmp/pics/http_{name}.png"), bytes);
    }
}

fn png(bytes: &[u8]) -> image::RgbImage {
    image::load_from_memory(bytes).expect("a PNG").to_rgb8()
}

#[tokio::test]
async fn png_pictures_take_colour_map_range_levels_slices_overlays_and_markers() {
    let app = spawn(|_| {}).await;
    let u = ArrayData::F64(ArrayD::from_shape_fn(vec![64, 64], |i| {
        (i[0] as f64).hypot(i[1] as f64)
    }));
    let id = app.upload(&u).await;
    // Default: a colour bar beside the 64 × 64 map magnified 6 times.
    let res = app.get(&format!("/v1/datasets/{id}/data?format=png")).await;
    assert_eq!(res.status(), 200);
    let bytes = res.bytes().await.expect("bytes");
    keep("distance_default", &bytes);
    let img = png(&bytes);
    assert_eq!(img.height(), 384);
    assert!(img.width() > 384 + 40, "{:?}", img.dimensions());
    // Without the bar, the map alone; magma over an explicit range.
    let res = app
        .get(&format!(
            "/v1/datasets/{id}/data?format=png&colorbar=false&colormap=magma&vmin=0&vmax=50&levels=0"
        ))
        .await;
    assert_eq!(res.status(), 200);
    let img = png(&res.bytes().await.expect("bytes"));
    assert_eq!(img.dimensions(), (64, 64));
    assert_eq!(img.get_pixel(0, 0).0, Colormap::Magma.at(0.0));
    assert_eq!(img.get_pixel(63, 63).0, Colormap::Magma.at(1.0));
    // A volume: the slice asked for, and a montage.
    let vol = ArrayData::F32(ArrayD::from_shape_fn(vec![8, 16, 16], |i| i[0] as f32));
    let vid = app.upload(&vol).await;
    let res = app
        .get(&format!(
            "/v1/datasets/{vid}/data?format=png&slice=0:7&colorbar=false"
        ))
        .await;
    assert_eq!(res.status(), 200);
    let res = app
        .get(&format!("/v1/datasets/{vid}/data?format=png&montage=4"))
        .await;
    assert_eq!(res.status(), 200);
    keep("montage", &res.bytes().await.expect("bytes"));
    // Labels over an image with markers.
    let labels = ArrayData::I32(ArrayD::from_shape_fn(vec![64, 64], |i| {
        i32::from(i[1] >= 32)
    }));
    let lid = app.upload(&labels).await;
    let res = app
        .get(&format!(
            "/v1/datasets/{lid}/data?format=png&over={id}&alpha=0.4&markers=10,5;50,55"
        ))
        .await;
    assert_eq!(res.status(), 200);
    keep("labels_over", &res.bytes().await.expect("bytes"));
    // Bad parameters: a 400 naming each.
    for (query, field) in [
        ("colormap=rainbow", "colormap"),
        ("vmin=abc", "vmin"),
        ("vmin=5&vmax=1", "vmin"),
        ("levels=-2", "levels"),
        ("levels=3&level_step=2", "level_step"),
        ("colorbar=maybe", "colorbar"),
        ("style=fancy", "style"),
        ("slice=0", "slice"),
        ("slice=0:1", "slice"),
        ("alpha=2", "alpha"),
        ("markers=1,2,3", "markers"),
        ("markers=100,2", "markers"),
    ] {
        let res = app
            .get(&format!("/v1/datasets/{id}/data?format=png&{query}"))
            .await;
        let v = problem(res, 400).await;
        assert_eq!(v["field"], field, "{query}: {v}");
    }
    // A slice past the end of a volume, a montage too large.
    for (query, field) in [("slice=0:8", "slice"), ("montage=0:65", "montage")] {
        let res = app
            .get(&format!("/v1/datasets/{vid}/data?format=png&{query}"))
            .await;
        let v = problem(res, 400).await;
        assert_eq!(v["field"], field, "{query}: {v}");
    }
    // An overlay that does not exist, or of another shape.
    let res = app
        .get(&format!("/v1/datasets/{lid}/data?format=png&over=ds_nope"))
        .await;
    let v = problem(res, 404).await;
    assert_eq!(v["field"], "over", "{v}");
    let res = app
        .get(&format!("/v1/datasets/{lid}/data?format=png&over={vid}"))
        .await;
    let v = problem(res, 400).await;
    assert_eq!(v["field"], "over", "{v}");
}

#[tokio::test]
async fn a_2d_plan_comes_with_its_picture() {
    let app = spawn(|_| {}).await;
    // A 40 × 40 room with a wall across rows 0..30 of column 20.
    let walls = ArrayData::U8(ArrayD::from_shape_fn(vec![40, 40], |i| {
        u8::from(i[1] == 20 && i[0] < 30)
    }));
    let id = app.upload(&walls).await;
    let res = app
        .client
        .post(app.url("/v1/grid/plan"))
        .json(
            &serde_json::json!({"obstacles": id, "radius": 2.0, "start": [5, 5], "goal": [5, 35]}),
        )
        .send()
        .await
        .expect("plan");
    assert_eq!(res.status(), 200);
    let body: serde_json::Value = res.json().await.expect("json");
    let s = geodex::io::mesh_picture::magnification(40, 40);
    assert_eq!(
        body["picture"]["shape"],
        serde_json::json!([40 * s, 40 * s, 3])
    );
    let url = body["picture"]["data_url"].as_str().expect("url");
    let res = app.get(&format!("{url}?format=png")).await;
    let bytes = res.bytes().await.expect("bytes");
    keep("plan", &bytes);
    let img = png(&bytes);
    // The wall is dark grey, the start green.
    let at = |r: usize, c: usize| {
        img.get_pixel((c * s + s / 2) as u32, (r * s + s / 2) as u32)
            .0
    };
    assert_eq!(at(10, 20), geodex::ops::grid_plan::OBSTACLE);
    assert_eq!(at(5, 5), geodex::ops::grid_plan::START);
}
