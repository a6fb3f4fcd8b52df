//! A really full disk (issue 20, item 4): the datasets' and the results'
//! directories are 2 MiB tmpfs file systems, mounted in a private mount
//! namespace of the server's process (`unshare --mount`, so nothing is
//! mounted on the machine and nothing is left mounted if the test dies).
//! Well below every quota, a write that does not fit must answer 507 (an
//! upload, a synchronous solve's stored result) or fail its job with the 507
//! problem, leave no partial file, and leave the service usable.
//!
//! Needs `unshare` and the right to mount in a new mount namespace (root, or
//! unprivileged user namespaces); CI runs as root.

mod jobs_support;

use std::path::{Path, PathBuf};
use std::time::Duration;

use geodex::io::ArrayData;
use jobs_support::{wavy_cost, Server};
use serde_json::{json, Value};

/// The 2 MiB tmpfs mounts, then the server (`unshare` runs `sh` in the new
/// namespace, which `exec`s the binary: the child's pid is the server's).
const WRAPPER: &str = "for d in datasets results; do mkdir -p \"$0/$d\" && \
    mount -t tmpfs -o size=2m tmpfs \"$0/$d\" || exit 97; done; exec \"$@\"";

/// The files under `dir` as the server's mount namespace sees them.
fn files_seen_by(server: &Server, dir: &Path) -> Vec<PathBuf> {
    let pid = server.pid().expect("running");
    let inside = PathBuf::from(format!("/proc/{pid}/root")).join(dir.strip_prefix("/").unwrap());
    let mut out = Vec::new();
    let mut todo = vec![inside.clone()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.expect("entry").path();
            if p.is_dir() {
                todo.push(p);
            } else {
                out.push(p.strip_prefix(&inside).expect("inside").to_path_buf());
            }
        }
    }
    out
}

async fn status_of(r: reqwest::Response) -> (u16, Value) {
    let s = r.status().as_u16();
    let body = r.text().await.expect("body");
    (
        s,
        serde_json::from_str(&body).unwrap_or(Value::String(body)),
    )
}

fn is_disk_full_problem(p: &Value) -> bool {
    p["status"] == 507
        && p["type"]
            .as_str()
            .is_some_and(|t| t.ends_with("storage-full"))
        && p["detail"].as_str().is_some_and(|d| d.contains("disk"))
}

#[tokio::test]
async fn a_full_disk_answers_507_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().canonicalize().expect("canonical");
    let data_str = data.to_str().expect("utf-8 path");
    let server = Server::start_under(
        &[
            "unshare",
            "--mount",
            "--propagation",
            "private",
            "sh",
            "-c",
            WRAPPER,
            data_str,
        ],
        &data,
        "disk-full",
        &["--job-poll-ms", "50"],
    )
    .await;
    let datasets = data.join("datasets");
    let results = data.join("results");

    // An upload of 2.9 MB (600 x 600 f64) cannot fit on the 2 MiB disk,
    // though the quota (8 GiB by default) is far away.
    let body = geodex::io::encode_npy(&ArrayData::F64(wavy_cost(600))).expect("npy");
    let r = server
        .client
        .post(server.url("/v1/datasets"))
        .header("content-type", "application/x-npy")
        .body(body)
        .send()
        .await
        .expect("upload");
    let (s, p) = status_of(r).await;
    assert_eq!(s, 507, "{p}");
    assert!(is_disk_full_problem(&p), "{p}");
    let left = files_seen_by(&server, &datasets);
    assert!(left.is_empty(), "partial upload left behind: {left:?}");

    // The disk is usable again: a small upload is stored.
    let small = server.upload(&ArrayData::F64(wavy_cost(40))).await;
    assert!(small.starts_with("ds_"), "{small}");
    let before = files_seen_by(&server, &datasets);

    // A synchronous solve whose stored result does not fit: 507, and only
    // the small dataset's files remain.
    let big = json!({"cost": {"constant": 1.0, "shape": [600, 600]},
        "sources": [{"point": [3, 4]}]});
    let (s, p) = status_of(server.post_json("/v1/grid/distance", &big, &[]).await).await;
    assert_eq!(s, 507, "{p}");
    assert!(is_disk_full_problem(&p), "{p}");
    assert_eq!(
        files_seen_by(&server, &datasets),
        before,
        "partial result left"
    );

    // A job whose result does not fit fails with the 507 problem and leaves
    // no file in the result store.
    let job = json!({"operation": "grid.distance", "params": big});
    let (s, submitted) = status_of(server.post_json("/v1/jobs", &job, &[]).await).await;
    assert_eq!(s, 202, "{submitted}");
    let id = submitted["id"].as_str().expect("job id").to_string();
    let done = server.wait_final(&id, Duration::from_secs(120)).await;
    assert_eq!(done["state"], "failed", "{done}");
    assert!(is_disk_full_problem(&done["error"]), "{done}");
    let left = files_seen_by(&server, &results);
    assert!(left.is_empty(), "files of {id} left behind: {left:?}");

    // And a job that fits still succeeds.
    let fits = json!({"operation": "grid.distance", "params": {
        "cost": {"dataset": small}, "sources": [{"point": [3, 4]}]}});
    let (s, submitted) = status_of(server.post_json("/v1/jobs", &fits, &[]).await).await;
    assert_eq!(s, 202, "{submitted}");
    let id = submitted["id"].as_str().expect("job id").to_string();
    let done = server.wait_final(&id, Duration::from_secs(120)).await;
    assert_eq!(done["state"], "succeeded", "{done}");
}
