// The one way the page talks to geodex: every request goes through `GX.api`,
// which records it as a curl command (shown in the "Requests" panel), times it,
// and turns a problem+json answer into an Error carrying its `detail`.
"use strict";
window.GX = window.GX || {};

(function () {
  const log = []; // newest first: {method, path, curl, status, ms}
  const listeners = [];
  GX.requestLog = log;

  function shellQuote(s) {
    return "'" + String(s).replace(/'/g, "'\\''") + "'";
  }

  /** The curl command of a request (`body` a JSON value, or a file description). */
  function curlOf(method, path, opts) {
    const url = location.origin + path;
    const parts = ["curl -s"];
    if (method !== "GET") parts.push("-X " + method);
    // The key itself is never shown: the command reads it from the shell.
    if (GX.key) parts.push("-H \"authorization: Bearer $GEODEX_KEY\"");
    if (opts.json !== undefined) {
      parts.push("-H 'content-type: application/json'");
      parts.push("-d " + shellQuote(JSON.stringify(opts.json)));
    } else if (opts.file) {
      parts.push("-H " + shellQuote("content-type: " + opts.file.type));
      parts.push("--data-binary @" + opts.file.name);
    }
    if (opts.accept) parts.push("-H " + shellQuote("accept: " + opts.accept));
    if (opts.out) parts.push("-o " + opts.out);
    parts.push(shellQuote(url));
    return parts.join(" ");
  }

  function record(entry) {
    if (entry.key) {
      const i = log.findIndex((e) => e.key === entry.key);
      if (i >= 0) log.splice(i, 1);
    }
    log.unshift(entry);
    if (log.length > 60) log.pop();
    listeners.forEach((f) => f(entry));
  }

  /**
   * Sends a request. `opts.json`: a JSON body; `opts.file`: {blob, name, type}
   * sent as the raw body; `opts.as`: "json" (default), "blob", "arraybuffer";
   * `opts.key`: the listed request replaces the last one with the same key
   * (the pointer-move paths are listed once, not once per move).
   */
  async function api(method, path, opts) {
    opts = opts || {};
    const init = { method, headers: {} };
    if (GX.key) init.headers["authorization"] = "Bearer " + GX.key;
    if (opts.json !== undefined) {
      init.headers["content-type"] = "application/json";
      init.body = JSON.stringify(opts.json);
    } else if (opts.file) {
      init.headers["content-type"] = opts.file.type;
      init.body = opts.file.blob;
    }
    if (opts.accept) init.headers["accept"] = opts.accept;
    const entry = { method, path, curl: curlOf(method, path, opts), status: 0, ms: 0, key: opts.key };
    const t0 = performance.now();
    let res;
    try {
      res = await fetch(path, init);
    } catch (e) {
      entry.status = "network error";
      record(entry);
      throw e;
    }
    entry.status = res.status;
    if (res.status === 401 && !opts.retried && askKey()) {
      record(entry);
      return api(method, path, { ...opts, retried: true });
    }
    let body;
    if (!res.ok) {
      const text = await res.text();
      entry.ms = performance.now() - t0;
      record(entry);
      let detail = text;
      try {
        const p = JSON.parse(text);
        detail = (p.title || "") + ": " + (p.detail || text);
      } catch (_) { /* not JSON */ }
      throw new Error(method + " " + path + " → " + res.status + " " + detail);
    }
    const as = opts.as || "json";
    if (as === "json") body = await res.json();
    else if (as === "blob") body = await res.blob();
    else body = await res.arrayBuffer();
    entry.ms = performance.now() - t0;
    record(entry);
    return body;
  }

  /**
   * Asks for an API key once (a service with auth answered 401) and keeps it
   * in this browser's localStorage; true if one was given.
   */
  let asked = false;
  function askKey() {
    if (asked) return false;
    asked = true;
    const key = window.prompt("This geodex needs an API key (the operator creates one with `geodex keys create --tenant NAME`):", "");
    if (!key) return false;
    GX.key = key.trim();
    try { localStorage.setItem("geodex.key", GX.key); } catch (_) { /* private mode */ }
    return true;
  }
  try { GX.key = localStorage.getItem("geodex.key") || ""; } catch (_) { GX.key = ""; }

  /**
   * A URL an <img> can show: the URL itself, or, when the page sends an API
   * key (an <img> cannot), an object URL of the picture fetched with it.
   */
  async function src(url) {
    if (!GX.key || !url.startsWith("/")) return url;
    const blob = await api("GET", url, { as: "blob" });
    return URL.createObjectURL(blob);
  }

  /** Uploads a Blob as a dataset; answers its metadata ({id, shape, ...}). */
  function upload(blob, name, type) {
    return api("POST", "/v1/datasets", { file: { blob, name, type: type || blob.type || "application/octet-stream" } });
  }

  /**
   * Parses an NPY file (v1/v2, little-endian f8/f4/i4/u1/b1, C order) into
   * {shape, data} with `data` a typed array.
   */
  function parseNpy(buf) {
    const bytes = new Uint8Array(buf);
    const major = bytes[6];
    const dv = new DataView(buf);
    const hlen = major === 1 ? dv.getUint16(8, true) : dv.getUint32(8, true);
    const start = major === 1 ? 10 : 12;
    const header = new TextDecoder().decode(bytes.subarray(start, start + hlen));
    const descr = /'descr':\s*'([^']+)'/.exec(header)[1];
    const shape = /'shape':\s*\(([^)]*)\)/.exec(header)[1].split(",").map((s) => s.trim()).filter((s) => s).map(Number);
    const off = start + hlen;
    const n = shape.reduce((a, b) => a * b, 1);
    const types = { "<f8": Float64Array, "<f4": Float32Array, "<i4": Int32Array, "<i8": BigInt64Array, "|u1": Uint8Array, "|b1": Uint8Array, "<u2": Uint16Array };
    const T = types[descr];
    if (!T) throw new Error("unsupported npy dtype " + descr);
    // NPY pads its header to 64 bytes, so the values are aligned in place
    // (no copy); a misaligned file is copied out.
    const data = off % T.BYTES_PER_ELEMENT === 0 ? new T(buf, off, n) : new T(buf.slice(off), 0, n);
    return { shape, data, dtype: descr };
  }

  /** Shows an error in the status line (and the console as a warning, not an error). */
  GX.errors = [];
  function fail(e) {
    GX.errors.push(String(e.message || e));
    console.warn(e);
    status(String(e.message || e), true);
  }

  function status(text, bad) {
    const el = document.getElementById("status");
    if (!el) return;
    el.textContent = text;
    el.className = bad ? "bad" : "";
  }

  GX.api = api;
  GX.src = src;
  GX.upload = upload;
  GX.parseNpy = parseNpy;
  GX.fail = fail;
  GX.status = status;
  GX.curlOf = curlOf;
  GX.record = record;
  GX.onRequest = (f) => listeners.push(f);

  // Viridis, the 17 control points of the server's `?format=png` (io::render), for colour bars and meshes.
  const VIRIDIS = [
    [71, 1, 85], [72, 24, 106], [71, 45, 123], [67, 64, 134], [61, 82, 140], [52, 99, 142],
    [43, 114, 142], [35, 129, 141], [31, 144, 139], [33, 159, 135], [42, 174, 128],
    [61, 188, 116], [90, 200, 97], [128, 211, 73], [172, 220, 48], [216, 226, 29], [252, 231, 33],
  ];
  GX.viridis = function (t) {
    t = Math.min(1, Math.max(0, t)) * (VIRIDIS.length - 1);
    const i = Math.min(VIRIDIS.length - 2, Math.floor(t));
    const f = t - i;
    const a = VIRIDIS[i], b = VIRIDIS[i + 1];
    return [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f];
  };
  GX.VIRIDIS = VIRIDIS;
})();
