//! The accept loop's limits (issue 20): a declared oversized body is
//! refused before a byte of it is read, a stalled body gets 408, slow
//! headers time out, and at the connection cap the oldest idle connection
//! makes room (or, when every connection is busy, the newcomer gets 503);
//! over HTTP/2 too, idle connections close and stalled bodies get 408.

use std::time::{Duration, Instant};

use futures::StreamExt;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::common::spawn;

fn addr(base: &str) -> String {
    base.trim_start_matches("http://").to_string()
}

/// Reads until the peer closes or `limit` passes; returns what came.
async fn read_all(s: &mut TcpStream, limit: Duration) -> (Vec<u8>, bool) {
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    let deadline = tokio::time::Instant::now() + limit;
    loop {
        match tokio::time::timeout_at(deadline, s.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => return (out, true),
            Ok(Ok(n)) => out.extend_from_slice(&buf[..n]),
            Err(_) => return (out, false),
        }
    }
}

fn status_of(bytes: &[u8]) -> Option<u16> {
    let text = String::from_utf8_lossy(bytes);
    text.lines().next()?.split_whitespace().nth(1)?.parse().ok()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_declared_oversized_body_is_refused_before_it_is_read() {
    let app = spawn(|s| s.max_body_bytes = 1 << 20).await;
    let mut s = TcpStream::connect(addr(&app.base)).await.expect("connect");
    s.write_all(
        b"POST /v1/datasets HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-npy\r\n\
          Content-Length: 300000000\r\n\r\n",
    )
    .await
    .expect("send");
    // Not one body byte is sent: the answer must come anyway.
    let (bytes, _) = read_all(&mut s, Duration::from_secs(5)).await;
    let text = String::from_utf8_lossy(&bytes);
    assert_eq!(status_of(&bytes), Some(413), "{text}");
    assert!(text.contains("application/problem+json"), "{text}");
    assert!(
        text.contains("300000000") && text.contains("max-body-bytes"),
        "{text}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_body_gets_408() {
    let app = spawn(|s| s.body_timeout_secs = 0.5).await;
    let mut s = TcpStream::connect(addr(&app.base)).await.expect("connect");
    let started = Instant::now();
    s.write_all(
        b"POST /v1/datasets HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-npy\r\n\
          Content-Length: 1000\r\n\r\n0123456789",
    )
    .await
    .expect("send");
    let (bytes, _) = read_all(&mut s, Duration::from_secs(10)).await;
    let text = String::from_utf8_lossy(&bytes);
    assert_eq!(status_of(&bytes), Some(408), "{text}");
    assert!(
        text.contains("request-timeout") && text.contains("body-timeout-secs"),
        "{text}"
    );
    // Answered after the pause, not before it.
    assert!(
        started.elapsed() >= Duration::from_millis(450),
        "{:?}",
        started.elapsed()
    );
}

/// A client that trickles its body (10 bytes every 0.2 s, never pausing as
/// long as the body timeout) is cut off once it falls below the minimum
/// rate after the grace period, instead of holding its slot for the hours
/// its 100 KB would take.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trickled_body_gets_408() {
    let app = spawn(|s| {
        s.body_timeout_secs = 0.5;
        s.min_body_rate = 1000;
    })
    .await;
    let mut s = TcpStream::connect(addr(&app.base)).await.expect("connect");
    let started = Instant::now();
    s.write_all(
        b"POST /v1/datasets HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-npy\r\n\
          Content-Length: 100000\r\n\r\n",
    )
    .await
    .expect("send");
    let trickle = async {
        loop {
            if s.write_all(b"0123456789").await.is_err() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
            if started.elapsed() > Duration::from_secs(10) {
                break;
            }
        }
    };
    let _ = tokio::time::timeout(Duration::from_millis(1500), trickle).await;
    let (bytes, _) = read_all(&mut s, Duration::from_secs(10)).await;
    let text = String::from_utf8_lossy(&bytes);
    assert_eq!(status_of(&bytes), Some(408), "{text}");
    assert!(text.contains("min-body-rate"), "{text}");
    // Cut off within a second of the grace period's end.
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_headers_and_silent_connections_are_closed() {
    let app = spawn(|s| s.header_timeout_secs = 0.5).await;
    // Half a request line, then nothing.
    let mut half = TcpStream::connect(addr(&app.base)).await.expect("connect");
    half.write_all(b"GET /healthz HTTP/1.1\r\nHo")
        .await
        .expect("send");
    // Nothing at all.
    let mut silent = TcpStream::connect(addr(&app.base)).await.expect("connect");
    for s in [&mut half, &mut silent] {
        let (_, closed) = read_all(s, Duration::from_secs(5)).await;
        assert!(
            closed,
            "the server kept a slow connection open past its header timeout"
        );
    }
    // A prompt client is served as before.
    assert_eq!(app.get("/healthz").await.status(), 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn at_the_cap_the_oldest_idle_connection_makes_room() {
    let app = spawn(|s| {
        s.max_connections = 4;
        s.header_timeout_secs = 60.0;
    })
    .await;
    let mut slow = Vec::new();
    for _ in 0..4 {
        let mut s = TcpStream::connect(addr(&app.base)).await.expect("connect");
        s.write_all(b"GET /healthz HTTP/1.1\r\n")
            .await
            .expect("send");
        slow.push(s);
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // Four slow clients hold every slot; a fresh client still gets in.
    for _ in 0..3 {
        let res = reqwest::Client::new()
            .get(app.url("/healthz"))
            .send()
            .await
            .expect("a new connection at the cap is served");
        assert_eq!(res.status(), 200);
    }
    // The oldest slow connection was the one closed to make room.
    let (_, closed) = read_all(&mut slow[0], Duration::from_secs(2)).await;
    assert!(closed, "the oldest idle connection was not evicted");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn at_the_cap_with_every_connection_busy_a_newcomer_gets_503() {
    let app = spawn(|s| {
        s.max_connections = 2;
        s.body_timeout_secs = 30.0;
    })
    .await;
    // Two uploads in progress (headers sent, body still arriving): busy.
    let mut busy = Vec::new();
    for _ in 0..2 {
        let mut s = TcpStream::connect(addr(&app.base)).await.expect("connect");
        s.write_all(
            b"POST /v1/datasets HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-npy\r\n\
              Content-Length: 1000\r\n\r\n01234",
        )
        .await
        .expect("send");
        busy.push(s);
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    let mut third = TcpStream::connect(addr(&app.base)).await.expect("connect");
    third
        .write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .expect("send");
    let (bytes, closed) = read_all(&mut third, Duration::from_secs(5)).await;
    let text = String::from_utf8_lossy(&bytes);
    assert_eq!(status_of(&bytes), Some(503), "{text}");
    assert!(
        text.to_ascii_lowercase().contains("retry-after: 1"),
        "{text}"
    );
    assert!(text.contains("max-connections"), "{text}");
    assert!(closed);
    drop(busy);
    // Once the uploads go away, the service answers again.
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(app.get("/healthz").await.status(), 200);
}

/// The client connection preface of HTTP/2 with prior knowledge, then an
/// empty SETTINGS frame (length 0, type 4, no flags, stream 0).
const H2_PREFACE: &[u8] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n\0\0\0\x04\0\0\0\0\0";

/// HTTP/2 has no header timer in hyper: a connection that opens no stream
/// is shut down by the accept loop's idle check (GOAWAY, then close) within
/// two header timeouts, and so is one idle after its requests.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_http2_connections_are_closed() {
    let app = spawn(|s| s.header_timeout_secs = 0.5).await;
    let mut s = TcpStream::connect(addr(&app.base)).await.expect("connect");
    let started = Instant::now();
    s.write_all(H2_PREFACE).await.expect("send");
    let (bytes, closed) = read_all(&mut s, Duration::from_secs(5)).await;
    assert!(closed, "an HTTP/2 connection with no stream stayed open");
    // The server spoke HTTP/2 (its SETTINGS frame, type 4, comes first) and
    // said goodbye with a GOAWAY frame (type 7).
    let mut types = Vec::new();
    let mut at = 0;
    while at + 9 <= bytes.len() {
        let len = usize::from(bytes[at]) << 16
            | usize::from(bytes[at + 1]) << 8
            | usize::from(bytes[at + 2]);
        types.push(bytes[at + 3]);
        at += 9 + len;
    }
    assert_eq!(types.first(), Some(&4), "frames {types:?}");
    assert!(types.contains(&7), "no GOAWAY among frames {types:?}");
    let after = started.elapsed();
    assert!(
        after >= Duration::from_millis(450) && after < Duration::from_millis(2500),
        "closed after {after:?}"
    );
    // A real HTTP/2 client is served, on one connection, request after request.
    let h2 = reqwest::Client::builder()
        .http2_prior_knowledge()
        .build()
        .expect("client");
    for _ in 0..3 {
        let res = h2.get(app.url("/healthz")).send().await.expect("h2 get");
        assert_eq!(res.version(), reqwest::Version::HTTP_2);
        assert_eq!(res.status(), 200);
    }
}

/// The body timeout covers HTTP/2 request bodies too: a stream that sends a
/// few bytes and stalls gets 408 on its stream.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_http2_body_gets_408() {
    let app = spawn(|s| s.body_timeout_secs = 0.5).await;
    let h2 = reqwest::Client::builder()
        .http2_prior_knowledge()
        .build()
        .expect("client");
    let first = futures::stream::once(async {
        Ok::<_, std::io::Error>(bytes::Bytes::from_static(b"0123456789"))
    });
    let stalled = first.chain(futures::stream::pending());
    let started = Instant::now();
    let res = tokio::time::timeout(
        Duration::from_secs(10),
        h2.post(app.url("/v1/datasets"))
            .header("content-type", "application/x-npy")
            .header("content-length", "1000")
            .body(reqwest::Body::wrap_stream(stalled))
            .send(),
    )
    .await
    .expect("answered within 10 s")
    .expect("h2 post");
    assert_eq!(res.version(), reqwest::Version::HTTP_2);
    assert_eq!(res.status(), 408);
    let text = res.text().await.expect("body");
    assert!(text.contains("body-timeout-secs"), "{text}");
    assert!(
        started.elapsed() >= Duration::from_millis(450),
        "{:?}",
        started.elapsed()
    );
}

/// Uploads are decoded on the solver pool and admitted like solves: while a
/// long solve holds the only slot, an upload is refused with 503 and
/// `Retry-After` instead of decoding beside it (issue 20: concurrent
/// compressed volumes used to be decoded all at once, 4.6 GB for three).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_are_admitted_by_the_pool() {
    let app = spawn(|s| {
        s.pool_threads = Some(1);
        s.queue_capacity = Some(1);
        s.request_timeout_secs = 30.0;
    })
    .await;
    let small = geodex::io::ArrayData::F64(ndarray::ArrayD::zeros(ndarray::IxDyn(&[4, 4])));
    let npy = geodex::io::encode_npy(&small).expect("npy");
    // Admitted when the pool is free.
    let id = app.upload(&small).await;
    assert!(id.starts_with("ds_"));
    // The upload's pool slot is given back just after its answer is sent:
    // wait for it, so that the full pool seen below is the solve's.
    let t = Instant::now();
    while app.get("/readyz").await.status() != 200 {
        assert!(t.elapsed() < Duration::from_secs(10), "the upload's slot");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    // A segmentation, not a distance: `load.rs` reads the process-wide
    // metrics of cancelled grid.distance solves.
    let slow = serde_json::json!({"cost": {"constant": 1.0, "shape": [3000, 3000]},
        "seeds": [{"label": 1, "point": [1.0, 1.0]}, {"label": 2, "point": [2990.0, 2990.0]}]});
    let client = app.client.clone();
    let url = app.url("/v1/grid/segment");
    let solve = tokio::spawn(async move { client.post(url).json(&slow).send().await });
    let t = Instant::now();
    while app.get("/readyz").await.status() == 200 {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the solve never started"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let res = app
        .client
        .post(app.url("/v1/datasets"))
        .header("content-type", "application/x-npy")
        .body(npy)
        .send()
        .await
        .expect("upload");
    let retry = res.headers().get("retry-after").cloned();
    let v = crate::common::problem(res, 503).await;
    assert_eq!(v["type"], "https://geodex.dev/problems/busy", "{v}");
    assert!(retry.is_some());
    solve.abort();
}
