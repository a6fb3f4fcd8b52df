//! `/v1/datasets`: the paged listing, multipart uploads, a mesh result's
//! values as NPY and PLY, and the check of the bytes against the format named.

use geodex::io::mesh::write::write_obj;
use geodex::io::mesh::{ply::vertex_values, read_mesh, MeshFormat, MeshLimits};
use geodex::io::{self, ArrayData};
use geodex::numerics::mesh::shapes::{great_circle, icosphere};
use ndarray::{ArrayD, IxDyn};
use serde_json::{json, Value};

use crate::common::{problem, spawn, TestApp};

async fn list(app: &TestApp, query: &str) -> (Value, Option<String>) {
    let res = app.get(&format!("/v1/datasets{query}")).await;
    assert_eq!(res.status(), 200);
    let link = res
        .headers()
        .get("link")
        .map(|v| v.to_str().expect("link").to_string());
    (res.json().await.expect("json"), link)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_listing_pages_newest_first_with_a_stable_cursor() {
    let app = spawn(|_| {}).await;
    // Seven arrays of seven shapes, so that each item tells which it is.
    let mut ids = Vec::new();
    for k in 0..7usize {
        let a = ArrayData::F32(ArrayD::zeros(IxDyn(&[2 + k, 3])));
        ids.push(app.upload(&a).await);
    }
    let mut seen: Vec<Value> = Vec::new();
    let mut cursor: Option<String> = None;
    let mut pages = 0;
    loop {
        let query = match &cursor {
            None => "?limit=3".to_string(),
            Some(c) => format!("?limit=3&cursor={c}"),
        };
        let (page, link) = list(&app, &query).await;
        pages += 1;
        let items = page["items"].as_array().expect("items").clone();
        assert!(items.len() <= 3);
        seen.extend(items);
        match page["next_cursor"].as_str() {
            Some(c) => {
                assert_eq!(
                    link.as_deref(),
                    Some(format!("</v1/datasets?limit=3&cursor={c}>; rel=\"next\"").as_str())
                );
                cursor = Some(c.to_string());
                // A dataset added mid-walk sorts before the cursor: the walk
                // neither repeats nor loses an item.
                if pages == 1 {
                    app.upload(&ArrayData::F32(ArrayD::zeros(IxDyn(&[20, 20]))))
                        .await;
                }
            }
            None => {
                assert!(link.is_none());
                break;
            }
        }
    }
    assert_eq!(pages, 3);
    let got: Vec<&str> = seen.iter().map(|m| m["id"].as_str().expect("id")).collect();
    let newest_first: Vec<&str> = ids.iter().rev().map(String::as_str).collect();
    assert_eq!(got, newest_first);
    // Item 0 is the last upload: shape [8, 3], f32, 8 * 3 * 4 bytes + header.
    let first = &seen[0];
    assert_eq!(first["kind"], "image");
    assert_eq!(first["shape"], json!([8, 3]));
    assert_eq!(first["dtype"], "f32");
    assert_eq!(first["byte_size"], 224);
    assert!(first["created_at"].is_string());
    // The added one is on a fresh walk's first page; with the default limit all 8 are.
    let (all, _) = list(&app, "").await;
    assert_eq!(all["items"].as_array().expect("items").len(), 8);
    assert_eq!(all["items"][0]["shape"], json!([20, 20]));
    assert_eq!(all["next_cursor"], Value::Null);

    for (query, field) in [
        ("?limit=0", "limit"),
        ("?limit=1001", "limit"),
        ("?cursor=nope", "cursor"),
    ] {
        let v = problem(app.get(&format!("/v1/datasets{query}")).await, 422).await;
        assert_eq!(v["field"], field, "{query}: {v}");
    }
}

async fn post_form(app: &TestApp, form: reqwest::multipart::Form) -> reqwest::Response {
    app.client
        .post(app.url("/v1/datasets"))
        .multipart(form)
        .send()
        .await
        .expect("post")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn multipart_uploads_store_the_file_part() {
    let app = spawn(|_| {}).await;
    let a = ArrayD::from_shape_fn(IxDyn(&[4, 5]), |ix| (ix[0] * 10 + ix[1]) as f64 * 0.5);
    let npy = io::encode_npy(&ArrayData::F64(a.clone())).expect("npy");
    let part = reqwest::multipart::Part::bytes(npy.clone())
        .file_name("a.npy")
        .mime_str("application/x-npy")
        .expect("mime");
    let res = post_form(&app, reqwest::multipart::Form::new().part("file", part)).await;
    assert_eq!(res.status(), 201);
    let location = res.headers()["location"]
        .to_str()
        .expect("location")
        .to_string();
    let meta: Value = res.json().await.expect("json");
    assert_eq!(meta["shape"], json!([4, 5]));
    assert_eq!(meta["source_format"], "npy");
    let back = app
        .get(&format!("{location}/data"))
        .await
        .bytes()
        .await
        .expect("bytes");
    let decoded = io::decode(&back, None, &io::Limits::default()).expect("decode");
    assert_eq!(decoded.array, ArrayData::F64(a));

    // No Content-Type on the part, the format in a `format` part.
    let part = reqwest::multipart::Part::bytes(npy.clone());
    let form = reqwest::multipart::Form::new()
        .part("file", part)
        .text("format", "npy");
    let res = post_form(&app, form).await;
    assert_eq!(res.status(), 201);

    // A mesh through a form.
    let sphere = icosphere(1, 1.0);
    let part = reqwest::multipart::Part::bytes(write_obj(&sphere));
    let form = reqwest::multipart::Form::new()
        .part("file", part)
        .text("format", "obj");
    let res = post_form(&app, form).await;
    assert_eq!(res.status(), 201);
    let meta: Value = res.json().await.expect("json");
    assert_eq!(meta["kind"], "mesh");
    assert_eq!(meta["mesh"]["vertices"], 42);

    // Mistakes name the part.
    let form = reqwest::multipart::Form::new().text("format", "npy");
    let v = problem(post_form(&app, form).await, 422).await;
    assert_eq!(v["field"], "file");
    let form = reqwest::multipart::Form::new()
        .part("file", reqwest::multipart::Part::bytes(npy.clone()))
        .text("format", "bmp");
    let v = problem(post_form(&app, form).await, 422).await;
    assert_eq!(v["field"], "format");
    let form = reqwest::multipart::Form::new()
        .part("file", reqwest::multipart::Part::bytes(npy))
        .text("colour", "red");
    let v = problem(post_form(&app, form).await, 422).await;
    assert_eq!(v["field"], "colour");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mesh_result_downloads_as_npy_values_and_as_ply_with_them() {
    let app = spawn(|_| {}).await;
    let sphere = icosphere(3, 1.0);
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "model/obj")
        .body(write_obj(&sphere))
        .send()
        .await
        .expect("upload");
    assert_eq!(res.status(), 201);
    let mesh: Value = res.json().await.expect("json");
    let mesh_id = mesh["id"].as_str().expect("id").to_string();
    let body: Value = app
        .client
        .post(app.url("/v1/mesh/distance"))
        .json(&json!({"mesh": mesh_id, "sources": [{"vertex": 0}], "method": "exact"}))
        .send()
        .await
        .expect("post")
        .json()
        .await
        .expect("json");
    let url = body["result"]["data_url"]
        .as_str()
        .expect("url")
        .to_string();

    // NPY: one f64 per vertex, 0 at the source, about pi at the antipode.
    let res = app.get(&format!("{url}?format=npy")).await;
    assert_eq!(res.status(), 200);
    assert_eq!(res.headers()["content-type"], "application/x-npy");
    let npy = res.bytes().await.expect("bytes");
    let limits = io::Limits::default();
    let decoded = io::decode(&npy, Some(io::Format::Npy), &limits).expect("npy");
    let ArrayData::F64(d) = decoded.array else {
        panic!("not f64: {:?}", decoded.array.dtype())
    };
    assert_eq!(d.shape(), [642]);
    assert_eq!(d[0], 0.0);
    let p0 = sphere.position(0);
    let far = (0..642u32)
        .max_by(|&a, &b| {
            great_circle(p0, sphere.position(a), 1.0).total_cmp(&great_circle(
                p0,
                sphere.position(b),
                1.0,
            ))
        })
        .expect("far");
    let err = (d[far as usize] - std::f64::consts::PI).abs();
    assert!(
        err < 0.05 * std::f64::consts::PI,
        "antipode {}",
        d[far as usize]
    );

    // The same values in the PLY, as the `distance` vertex property; by
    // `Accept`, NPY too; the labels by `?property=`.
    let ply = app
        .get(&format!("{url}?format=ply"))
        .await
        .bytes()
        .await
        .expect("ply");
    let back = read_mesh(&ply, Some(MeshFormat::Ply), &MeshLimits::default()).expect("ply");
    assert_eq!(back.mesh.num_vertices(), 642);
    let in_ply = vertex_values(&ply).expect("values");
    assert_eq!(in_ply.distance.as_deref(), d.as_slice());
    let by_accept = app
        .client
        .get(app.url(&url))
        .header("accept", "application/x-npy")
        .send()
        .await
        .expect("get");
    assert_eq!(by_accept.headers()["content-type"], "application/x-npy");
    assert_eq!(by_accept.bytes().await.expect("bytes"), npy);
    let labels = app.get(&format!("{url}?format=npy&property=label")).await;
    assert_eq!(labels.status(), 200);
    let labels = io::decode(&labels.bytes().await.expect("b"), None, &limits).expect("npy");
    assert_eq!(labels.array.dtype(), io::DType::I32);
    assert_eq!(labels.array.shape(), [642]);
    let v = problem(
        app.get(&format!("{url}?format=npy&property=value")).await,
        422,
    )
    .await;
    assert_eq!(v["field"], "property");

    // OBJ cannot hold the distances: refused with the way out.
    let v = problem(app.get(&format!("{url}?format=obj")).await, 406).await;
    let detail = v["detail"].as_str().expect("detail");
    assert!(
        detail.contains("distance") && detail.contains("ply"),
        "{detail}"
    );
    // An uploaded mesh has no values: OBJ is fine, NPY is not.
    let plain = format!("/v1/datasets/{mesh_id}/data");
    assert_eq!(app.get(&format!("{plain}?format=obj")).await.status(), 200);
    problem(app.get(&format!("{plain}?format=npy")).await, 406).await;
}

fn jpeg_bytes() -> Vec<u8> {
    let img = image::GrayImage::from_fn(16, 8, |x, y| image::Luma([(x * 8 + y * 4) as u8]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Jpeg)
        .expect("jpeg");
    out.into_inner()
}

async fn upload_as(
    app: &TestApp,
    content_type: &str,
    query: &str,
    body: Vec<u8>,
) -> reqwest::Response {
    let mut req = app
        .client
        .post(app.url(&format!("/v1/datasets{query}")))
        .body(body);
    if !content_type.is_empty() {
        req = req.header("content-type", content_type);
    }
    req.send().await.expect("post")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bytes_that_contradict_their_content_type_are_named() {
    let app = spawn(|_| {}).await;
    let jpeg = jpeg_bytes();
    let v = problem(upload_as(&app, "image/png", "", jpeg.clone()).await, 415).await;
    let detail = v["detail"].as_str().expect("detail");
    assert!(
        detail.contains("this is a JPEG, not a PNG") && detail.contains("image/jpeg"),
        "{detail}"
    );
    assert_eq!(v["field"], "Content-Type");
    // `?format=` that contradicts the bytes names `format`.
    let v = problem(upload_as(&app, "", "?format=png", jpeg.clone()).await, 422).await;
    assert_eq!(v["field"], "format");
    assert!(
        v["detail"].as_str().expect("d").contains("format=jpeg"),
        "{v}"
    );
    // NPY bytes sent as a TIFF.
    let npy = io::encode_npy(&ArrayData::F64(ArrayD::zeros(IxDyn(&[3, 3])))).expect("npy");
    let v = problem(upload_as(&app, "image/tiff", "", npy).await, 415).await;
    assert!(
        v["detail"]
            .as_str()
            .expect("d")
            .contains("this is an NPY file, not a TIFF"),
        "{v}"
    );
    // The way out works: the right type, or none.
    for ct in ["image/jpeg", "", "application/octet-stream"] {
        let res = upload_as(&app, ct, "", jpeg.clone()).await;
        assert_eq!(res.status(), 201, "{ct}");
        let meta: Value = res.json().await.expect("json");
        assert_eq!(meta["source_format"], "jpeg");
        assert_eq!(meta["shape"], json!([8, 16]));
    }
    // The same check on the cost part of a distance form.
    let part = reqwest::multipart::Part::bytes(jpeg)
        .mime_str("image/png")
        .expect("mime");
    let form = reqwest::multipart::Form::new()
        .part("file", part)
        .text("params", "{\"sources\": [{\"point\": [1, 1]}]}");
    let res = app
        .client
        .post(app.url("/v1/grid/distance"))
        .multipart(form)
        .send()
        .await
        .expect("post");
    let v = problem(res, 415).await;
    assert!(
        v["detail"].as_str().expect("d").contains("this is a JPEG"),
        "{v}"
    );
}

/// `?dtype=f32` sends a float array in single precision (what the
/// playground downloads: half the bytes), rounded to nearest; `f64` widens
/// an f32 array; integer arrays, pictures and meshes refuse it with a 400
/// that names `dtype`.
#[tokio::test]
async fn a_float_array_downloads_in_single_precision() {
    let app = spawn(|_| {}).await;
    let values = ArrayD::from_shape_fn(IxDyn(&[70, 90]), |ix| {
        std::f64::consts::PI * (ix[0] as f64 + 1.0) / (ix[1] as f64 + 3.0)
    });
    let id = app.upload(&ArrayData::F64(values.clone())).await;
    let limits = io::Limits::default();
    let get = |q: &'static str| {
        let app = &app;
        let id = id.clone();
        async move { app.get(&format!("/v1/datasets/{id}/data?{q}")).await }
    };
    let full = get("format=npy").await.bytes().await.expect("bytes");
    let res = get("format=npy&dtype=f32").await;
    assert_eq!(res.status(), 200);
    let half = res.bytes().await.expect("bytes");
    let decoded = io::decode(&half, Some(io::Format::Npy), &limits).expect("npy");
    let ArrayData::F32(single) = decoded.array else {
        panic!("not f32: {:?}", decoded.array.dtype())
    };
    assert_eq!(single.shape(), values.shape());
    for (s, d) in single.iter().zip(values.iter()) {
        assert_eq!(*s, *d as f32, "rounded to nearest");
        assert!((f64::from(*s) - d).abs() <= 6e-8 * d.abs());
    }
    assert!(
        half.len() < full.len() * 3 / 5,
        "{} vs {} bytes",
        half.len(),
        full.len()
    );
    // As stored: the same bytes as without dtype.
    let same = get("format=npy&dtype=f64").await.bytes().await.expect("b");
    assert_eq!(same, full);
    let json: Value = get("format=json&dtype=f32")
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(json["dtype"], "f32");
    assert_eq!(json["data"][1], f64::from(single[[0, 1]]));

    // An f32 array widens to f64 exactly.
    let narrow = app.upload(&ArrayData::F32(single.clone())).await;
    let res = app
        .get(&format!("/v1/datasets/{narrow}/data?format=npy&dtype=f64"))
        .await;
    let wide = io::decode(&res.bytes().await.expect("b"), None, &limits).expect("npy");
    let ArrayData::F64(wide) = wide.array else {
        panic!("not f64")
    };
    assert!(wide
        .iter()
        .zip(single.iter())
        .all(|(w, s)| *w == f64::from(*s)));

    for (q, fragment) in [
        ("format=npy&dtype=f16", "use f32 or f64"),
        ("format=png&dtype=f32", "npy and json"),
        ("format=tiff&dtype=f32", "npy and json"),
    ] {
        let v = problem(get(q).await, 400).await;
        assert_eq!(v["field"], "dtype", "{q}: {v}");
        assert!(
            v["detail"].as_str().expect("detail").contains(fragment),
            "{q}: {v}"
        );
    }
    let labels = app
        .upload(&ArrayData::U8(ArrayD::zeros(IxDyn(&[4, 4]))))
        .await;
    let v = problem(
        app.get(&format!("/v1/datasets/{labels}/data?format=npy&dtype=f32"))
            .await,
        400,
    )
    .await;
    assert_eq!(v["field"], "dtype");
    assert!(v["detail"].as_str().expect("detail").contains("u8"), "{v}");
}
