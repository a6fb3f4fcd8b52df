#!/usr/bin/env python3
"""Hostile-load suite (issue 20): attacks on a real `geodex serve`, loopback only.

Each attack starts a fresh server (its own data directory and port), runs,
checks its bound and prints one line of figures. Exit status 1 if any bound
fails. Standard library only; needs the release (or debug) binary.

    cargo build --release --bin geodex
    python3 tests/hostile/hostile.py [--bin target/release/geodex] [--only NAME] [--slow N]

Attacks and bounds:
  declared-413   a 300 MB Content-Length: 413 before the body is read (the
                 server must answer while the client has sent 0 body bytes).
  stalled-body   a body that stops after 10 of 1000 bytes: 408 within the
                 body timeout (2 s here) + 1 s.
  slowloris      N half-sent requests (default 20,000, lowered to fit the
                 open-file limit) held open and dribbled: /healthz on fresh
                 connections answers 200 to every probe with p99 < 100 ms;
                 RSS comes back within 25 % of its idle value (+ 16 MB) 30 s
                 after the connections close.
  png-bomb       60 concurrent uploads of a 1.1 MB PNG carrying an iCCP chunk
                 that inflates to 1 GiB: every answer 201, 413 or 503, and the
                 server's peak RSS stays under 1 GiB.
  nifti-bomb     200 concurrent uploads of a 16 KB .nii.gz holding 256^3
                 voxels (16.8 MB each), 4 pool threads admitting 400 by count
                 and --solve-memory-bytes 150 MB: every answer 201, 413 or
                 503 with Retry-After, and the peak RSS above idle under the
                 budget + 64 MB. Run again without the budget, for the figure.
  frozen-mesh    a mesh with faces 1e-14 across in a unit mesh (the class of
                 input that froze the exact solver): 422 at upload naming the
                 problem; an exact sampling that would run for minutes: 504
                 within 2 s (deadline 1 s), and the next solve succeeds.
  heat-cache     heat-method solves on one 40,000-vertex mesh with m = 1..8
                 (each its own factorisation, about 50 MB) under --cache-bytes 128 MB: every
                 solve 200, /readyz's cache_bytes within the budget after
                 each, and RSS at the end within idle + budget + 64 MB.
  json-storm     4 JSON bodies of 75 MB (a 12.5M-cell source list, 37.5M
                 values): each refused 413 naming `body` before it is parsed
                 (more than 4M values), peak RSS under idle + 400 MB, and RSS
                 back within 25 % of idle (+ 16 MB) within 30 s.
  overflow       a cost of 1e306 and a spacing of 1e300 (distances beyond
                 f64): 422 naming `cost` and `spacing`, not a map of +inf.
  quota-results  a job whose results exceed the storage quota: the job fails
                 with the 507 problem and no file of it is left on disk.

The bomb storms also check that RSS, less what the cache holds (/readyz
`cache_bytes`: the datasets a storm stored stay decoded there, within
--cache-bytes), comes back within 25 % of its idle value (+ 16 MB) within
30 s after the storm.
"""

import argparse
import http.client
import json
import os
import resource
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib

FAILED = []


def check(name, ok, figures):
    print(f"{'PASS' if ok else 'FAIL'} {name}: {figures}", flush=True)
    if not ok:
        FAILED.append(name)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    def __init__(self, binary, *extra, threads=1):
        self.dir = tempfile.mkdtemp(prefix="geodex-hostile-")
        self.port = free_port()
        self.log = open(os.path.join(self.dir, "serve.log"), "wb")
        self.proc = subprocess.Popen(
            [binary, "serve", "--addr", f"127.0.0.1:{self.port}", "--data-dir",
             os.path.join(self.dir, "data"), "--pool-threads", str(threads), *extra],
            stdout=self.log, stderr=subprocess.STDOUT)
        for _ in range(200):
            try:
                if self.get("/healthz")[0] == 200:
                    break
            except OSError:
                time.sleep(0.05)
        else:
            raise RuntimeError("server did not start")

    def get(self, path, timeout=5.0):
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        try:
            c.request("GET", path)
            r = c.getresponse()
            return r.status, r.read()
        finally:
            c.close()

    def post(self, path, body, ctype, timeout=30.0):
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        try:
            c.request("POST", path, body=body, headers={"content-type": ctype})
            r = c.getresponse()
            return r.status, r.read()
        finally:
            c.close()

    def status_mb(self, field):
        """A memory figure of the server from /proc (VmRSS, VmHWM), in MB."""
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024
        return 0.0

    def rss_mb(self):
        return self.status_mb("VmRSS")

    def hwm_mb(self):
        return self.status_mb("VmHWM")

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()
        shutil.rmtree(self.dir, ignore_errors=True)


def read_status(sock, timeout):
    sock.settimeout(timeout)
    data = b""
    while b"\r\n" not in data:
        chunk = sock.recv(4096)
        if not chunk:
            break
        data += chunk
    line = data.split(b"\r\n", 1)[0].decode(errors="replace")
    parts = line.split()
    return int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else None


def raw_request(server, head, timeout):
    """Sends `head` (request line, headers and any body bytes) on a fresh
    connection; returns the answer's status and the seconds it took."""
    sock = socket.create_connection(("127.0.0.1", server.port))
    try:
        t0 = time.perf_counter()
        sock.sendall(head)
        status = read_status(sock, timeout)
        return status, time.perf_counter() - t0
    finally:
        sock.close()


def declared_413(binary):
    s = Server(binary)
    try:
        status, dt = raw_request(s, b"POST /v1/datasets HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-npy\r\n"
                                    b"Content-Length: 300000000\r\n\r\n", 5)
        dt *= 1000
        check("declared-413", status == 413 and dt < 1000,
              f"status {status} after {dt:.1f} ms with 0 body bytes sent (300 MB declared)")
    finally:
        s.stop()


def stalled_body(binary):
    s = Server(binary, "--body-timeout-secs", "2")
    try:
        status, dt = raw_request(s, b"POST /v1/datasets HTTP/1.1\r\nHost: x\r\nContent-Type: application/x-npy\r\n"
                                    b"Content-Length: 1000\r\n\r\n0123456789", 10)
        check("stalled-body", status == 408 and dt < 3.0,
              f"status {status} after {dt:.2f} s (body timeout 2 s, 10 of 1000 bytes sent)")
    finally:
        s.stop()


def slowloris(binary, n):
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    n = min(n, hard - 200)
    s = Server(binary)
    socks = []
    try:
        time.sleep(0.5)
        idle = s.rss_mb()
        t0 = time.perf_counter()
        for i in range(n):
            try:
                c = socket.socket()
                c.setblocking(False)
                c.connect_ex(("127.0.0.1", s.port))
                socks.append(c)
            except OSError:
                break
        time.sleep(1.0)
        for c in socks:
            try:
                c.send(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
            except OSError:
                pass
        opened = time.perf_counter() - t0
        lat, ok = [], 0
        stop = threading.Event()

        def dribble():
            while not stop.is_set():
                for c in socks:
                    try:
                        c.send(b"X-a: b\r\n")
                    except OSError:
                        pass
                stop.wait(2.0)

        th = threading.Thread(target=dribble, daemon=True)
        th.start()
        for _ in range(200):
            t = time.perf_counter()
            try:
                status, _ = s.get("/healthz", timeout=5)
                ok += status == 200
            except OSError:
                pass
            lat.append((time.perf_counter() - t) * 1000)
            time.sleep(0.01)
        stop.set()
        th.join()
        lat.sort()
        p50, p99 = lat[len(lat) // 2], lat[int(len(lat) * 0.99) - 1]
        peak = s.rss_mb()
        for c in socks:
            c.close()
        socks = []
        time.sleep(30)
        after = s.rss_mb()
        check("slowloris", ok == 200 and p99 < 100 and after <= idle * 1.25 + 16,
              f"{n} slow connections opened in {opened:.1f} s; /healthz {ok}/200, p50 {p50:.1f} ms, "
              f"p99 {p99:.1f} ms; RSS idle {idle:.0f} MB, under load {peak:.0f} MB, 30 s after {after:.0f} MB")
    finally:
        for c in socks:
            c.close()
        s.stop()


def png_chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bomb_bytes():
    w = h = 64
    raw = b"".join(b"\x00" + bytes(range(w)) for _ in range(h))
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    z = zlib.compressobj(9)
    block = b"\x00" * (16 << 20)
    profile = b"".join(z.compress(block) for _ in range(64)) + z.flush()
    return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"iCCP", b"bomb\x00\x00" + profile)
            + png_chunk(b"IDAT", zlib.compress(raw)) + png_chunk(b"IEND", b""))


def storm(server, body, ctype, n):
    """n concurrent uploads of `body`; returns (statuses, seconds). A 503
    without Retry-After is reported as such."""
    statuses = []
    lock = threading.Lock()

    def upload():
        c = http.client.HTTPConnection("127.0.0.1", server.port, timeout=120)
        try:
            c.request("POST", "/v1/datasets", body=body, headers={"content-type": ctype})
            r = c.getresponse()
            r.read()
            st = r.status
            if st == 503 and r.getheader("retry-after") is None:
                st = "503 without Retry-After"
        except OSError as e:
            st = f"error {e}"
        finally:
            c.close()
        with lock:
            statuses.append(st)

    threads = [threading.Thread(target=upload) for _ in range(n)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return statuses, time.perf_counter() - t0


def cache_mb(server):
    """What the server's one cache holds (/readyz `cache_bytes`), in MB: the
    datasets a storm stored legitimately stay decoded there."""
    try:
        return json.loads(server.get("/readyz")[1]).get("cache_bytes", 0) / 2**20
    except (OSError, ValueError):
        return 0.0


def rss_settles(server, idle, within=30.0):
    """Polls RSS for up to `within` s until, less what the cache holds, it is
    back within 25 % of `idle` (+ 16 MB); returns (settled, seconds, MB,
    cache MB)."""
    t0 = time.perf_counter()
    while True:
        now, cached = server.rss_mb(), cache_mb(server)
        dt = time.perf_counter() - t0
        if now - cached <= idle * 1.25 + 16:
            return True, dt, now, cached
        if dt > within:
            return False, dt, now, cached
        time.sleep(0.5)


def png_bomb(binary, n=60):
    bomb = png_bomb_bytes()
    s = Server(binary)
    try:
        time.sleep(0.5)
        idle = s.rss_mb()
        statuses, dt = storm(s, bomb, "image/png", n)
        peak = s.hwm_mb()
        settled, back, after, cached = rss_settles(s, idle)
        counts = {st: statuses.count(st) for st in set(statuses)}
        check("png-bomb", all(st in (201, 413, 503) for st in statuses) and peak < 1024 and settled,
              f"{n} concurrent {len(bomb) / 1e6:.1f} MB PNGs with a 1 GiB iCCP chunk in {dt:.1f} s: "
              f"statuses {counts}, RSS idle {idle:.0f} MB, peak {peak:.0f} MB, "
              f"{after:.0f} MB {back:.1f} s after (cache {cached:.0f} MB)")
    finally:
        s.stop()


def nifti_bomb_bytes(n=256):
    """A gzipped NIfTI-1 volume of n^3 zero bytes: ~20 KB that inflate to n^3."""
    import gzip
    hdr = bytearray(348)
    struct.pack_into("<i", hdr, 0, 348)
    struct.pack_into("<8h", hdr, 40, 3, n, n, n, 1, 1, 1, 1)
    struct.pack_into("<hh", hdr, 70, 2, 8)  # datatype u8, bitpix 8
    struct.pack_into("<8f", hdr, 76, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into("<f", hdr, 108, 352.0)  # vox_offset
    hdr[344:348] = b"n+1\0"
    return gzip.compress(bytes(hdr) + b"\0" * 4 + b"\0" * (n * n * n), 9)


def nifti_bomb(binary, n=200, budget=150_000_000):
    """n concurrent uploads of a gzipped 256^3 NIfTI (16.8 MB decoded each)
    on four pool threads admitting 400 at once by count: only the memory
    budget keeps the decodes from running together. Run once with the budget
    and once without (a budget of 100 GB), for the figure without it."""
    bomb = nifti_bomb_bytes()
    for label, mem in (("budget", budget), ("no budget", 100_000_000_000)):
        s = Server(binary, "--queue-capacity", "400", "--solve-memory-bytes", str(mem),
                   "--storage-quota-bytes", str(4 << 30), threads=4)
        try:
            time.sleep(0.5)
            idle = s.rss_mb()
            statuses, dt = storm(s, bomb, "application/gzip", n)
            peak = s.hwm_mb()
            counts = {st: statuses.count(st) for st in set(statuses)}
            figures = (f"{label}: {n} concurrent {len(bomb) / 1e3:.0f} KB .nii.gz (256^3 inside) "
                       f"in {dt:.1f} s: statuses {counts}, RSS {idle:.0f} MB idle, peak {peak:.0f} MB")
            if label == "budget":
                settled, back, after, cached = rss_settles(s, idle)
                check("nifti-bomb", all(st in (201, 413, 503) for st in statuses)
                      and peak - idle < budget / 1e6 + 64 and settled,
                      f"{figures}, {after:.0f} MB {back:.1f} s after (cache {cached:.0f} MB)")
            else:
                print(f"     {figures}")
        finally:
            s.stop()


def grid_obj(n, jitter=0.3, seed=5):
    """A jittered n x n vertex grid of the unit square, as OBJ text."""
    state = seed
    lines = []
    for i in range(n):
        for j in range(n):
            state = (state * 6364136223846793005 + 1442695040888963407) % (1 << 64)
            dx = ((state >> 11) / (1 << 53) - 0.5) * jitter / n
            state = (state * 6364136223846793005 + 1442695040888963407) % (1 << 64)
            dy = ((state >> 11) / (1 << 53) - 0.5) * jitter / n
            lines.append(f"v {i / n + dx} {j / n + dy} 0")
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j + 1
            lines.append(f"f {a} {a + n} {a + 1}")
            lines.append(f"f {a + 1} {a + n} {a + n + 1}")
    return ("\n".join(lines) + "\n").encode()


def frozen_mesh(binary):
    # Faces 1e-14 across in a unit mesh: their shape is round-off (the class
    # of mesh that froze the exact solver), refused at upload.
    tiny = ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0.00000000000001 0 0\nv 0 0.00000000000001 0\n"
            "f 1 2 3\nf 1 4 5\n").encode()
    s = Server(binary, "--request-timeout-secs", "1")
    try:
        st, body = s.post("/v1/datasets", tiny, "model/obj", timeout=10)
        detail = json.loads(body).get("detail", "") if body else ""
        # An exact sampling that would run for minutes: 504 at the 1 s
        # deadline, and the pool serves the next request.
        st2, body2 = s.post("/v1/datasets", grid_obj(150), "model/obj", timeout=30)
        mesh = json.loads(body2)["id"]
        t0 = time.perf_counter()
        st3, _ = s.post("/v1/mesh/sample", json.dumps({"mesh": mesh, "count": 400, "method": "exact"}).encode(),
                        "application/json", timeout=30)
        dt = time.perf_counter() - t0
        nxt = None
        for _ in range(100):
            nxt, _ = s.post("/v1/grid/distance", json.dumps(
                {"cost": {"constant": 1.0, "shape": [8, 8]}, "sources": [{"point": [1.0, 1.0]}]}).encode(),
                "application/json", timeout=10)
            if nxt != 503:
                break
            time.sleep(0.02)
        nxt_dt = time.perf_counter() - t0
        check("frozen-mesh", st == 422 and "represent" in detail and st2 == 201 and st3 == 504
              and dt < 2.0 and nxt == 200 and nxt_dt < 3.0,
              f"round-off mesh upload {st} ({detail[:70]}...); exact sampling of 22,500 vertices "
              f"{st3} after {dt:.2f} s (deadline 1 s); next solve {nxt} at {nxt_dt:.2f} s")
    finally:
        s.stop()


def post_json(server, path, doc, timeout=120.0):
    st, body = server.post(path, json.dumps(doc).encode(), "application/json", timeout=timeout)
    try:
        return st, json.loads(body) if body else {}
    except ValueError:
        return st, {"raw": body[:200].decode(errors="replace")}


def heat_cache(binary, budget_mb=128):
    s = Server(binary, "--cache-bytes", str(budget_mb << 20), threads=2)
    try:
        st, up = s.post("/v1/datasets", grid_obj(200), "model/obj", timeout=60)
        mesh = json.loads(up)["id"]
        time.sleep(0.5)
        idle = s.rss_mb()
        statuses, cached = [], []
        for m in range(1, 9):
            st, doc = post_json(s, "/v1/mesh/distance", {
                "mesh": mesh, "method": "heat", "heat": {"m": m}, "sources": [{"vertex": 0}]})
            statuses.append(st)
            _, ready = s.get("/readyz")
            cached.append(json.loads(ready).get("cache_bytes", -1) / 2**20)
        end = s.rss_mb()
        peak = s.hwm_mb()
        check("heat-cache", all(st == 200 for st in statuses)
              and all(0 <= c <= budget_mb for c in cached) and end <= idle + budget_mb + 64,
              f"8 heat solves (m = 1..8) on 40,000 vertices, --cache-bytes {budget_mb} MB: statuses "
              f"{sorted(set(statuses))}, cache after each {', '.join(f'{c:.1f}' for c in cached)} MB; "
              f"RSS idle {idle:.0f} MB, "
              f"peak {peak:.0f} MB, after {end:.0f} MB")
    finally:
        s.stop()


def json_storm(binary, n=4, cells=12_500_000):
    # A source list of `cells` cells as JSON: about 8 bytes per cell.
    one = b"[1,2],"
    body = (b'{"cost": {"constant": 1.0, "shape": [64, 64]}, "sources": [{"cells": ['
            + one * (cells - 1) + b'[1,2]]}]}')
    s = Server(binary, threads=2)
    try:
        time.sleep(0.5)
        idle = s.rss_mb()
        statuses, fields = [], []
        t0 = time.perf_counter()
        for _ in range(n):
            st, raw = s.post("/v1/grid/distance", body, "application/json", timeout=120)
            statuses.append(st)
            try:
                fields.append(json.loads(raw).get("field"))
            except ValueError:
                fields.append(None)
        dt = time.perf_counter() - t0
        peak = s.hwm_mb()
        settled, back, after, cached = rss_settles(s, idle)
        check("json-storm", all(st == 413 for st in statuses) and set(fields) == {"body"}
              and peak < idle + 400 and settled,
              f"{n} JSON bodies of {len(body) / 1e6:.0f} MB ({cells:,} source cells) in {dt:.1f} s: "
              f"statuses {statuses}, fields {sorted(set(map(str, fields)))}; RSS idle {idle:.0f} MB, "
              f"peak {peak:.0f} MB, {after:.0f} MB {back:.1f} s after (cache {cached:.0f} MB)")
    finally:
        s.stop()


def overflow(binary):
    s = Server(binary)
    try:
        got = []
        for doc, field in (
                ({"cost": {"constant": 1e306, "shape": [64, 64]}, "sources": [{"point": [1, 1]}]},
                 "cost"),
                ({"cost": {"constant": 1.0, "shape": [64, 64]}, "spacing": [1e300, 1e300],
                  "sources": [{"point": [1, 1]}]}, "spacing")):
            st, p = post_json(s, "/v1/grid/distance", doc)
            got.append((st, p.get("field"), field))
        check("overflow", all(st == 422 and f == want for st, f, want in got),
              "; ".join(f"{want}: {st} naming {f!r}" for st, f, want in got))
    finally:
        s.stop()


def quota_results(binary):
    # 300 KB of quota: the 80 KB cost fits, the job's distance and labels
    # over a 200 x 200 grid (320 KB + 160 KB) do not.
    s = Server(binary, "--storage-quota-bytes", "300000", "--job-poll-ms", "50")
    try:
        st, job = post_json(s, "/v1/jobs", {"operation": "grid.distance", "params": {
            "cost": {"constant": 1.0, "shape": [200, 200]}, "sources": [{"point": [3, 4]}]}})
        jid = job.get("id")
        final = {}
        for _ in range(600):
            _, raw = s.get(f"/v1/jobs/{jid}")
            final = json.loads(raw)
            if final.get("state") in ("succeeded", "failed", "cancelled"):
                break
            time.sleep(0.05)
        results = os.path.join(s.dir, "data", "results", "results", str(jid))
        left = sum(len(f) for _, _, f in os.walk(results))
        err = final.get("error") or {}
        check("quota-results", st == 202 and final.get("state") == "failed"
              and err.get("status") == 507 and left == 0,
              f"job {st}, then {final.get('state')} with {err.get('status')} "
              f"({str(err.get('detail'))[:60]}...); files left: {left}")
    finally:
        s.stop()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=os.environ.get("BIN", "target/release/geodex"))
    ap.add_argument("--only")
    ap.add_argument("--slow", type=int, default=20000, help="slowloris connections")
    a = ap.parse_args()
    attacks = {
        "declared-413": lambda: declared_413(a.bin),
        "stalled-body": lambda: stalled_body(a.bin),
        "frozen-mesh": lambda: frozen_mesh(a.bin),
        "png-bomb": lambda: png_bomb(a.bin),
        "nifti-bomb": lambda: nifti_bomb(a.bin),
        "slowloris": lambda: slowloris(a.bin, a.slow),
        "heat-cache": lambda: heat_cache(a.bin),
        "json-storm": lambda: json_storm(a.bin),
        "overflow": lambda: overflow(a.bin),
        "quota-results": lambda: quota_results(a.bin),
    }
    for name, run in attacks.items():
        if a.only and name != a.only:
            continue
        try:
            run()
        except Exception as e:  # a crash of the harness is a failure too
            check(name, False, f"harness error: {e!r}")
    if FAILED:
        print("failed:", ", ".join(FAILED))
        sys.exit(1)


if __name__ == "__main__":
    main()
