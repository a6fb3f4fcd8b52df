// A minimal WebGL2 mesh viewer written for the playground (no library): a
// lit triangle mesh coloured by a per-vertex scalar (viridis, with iso-lines
// drawn in the fragment shader where fract(value / spacing) crosses 0),
// its edges optionally (to see a remeshing's triangles), polylines and
// points over it, orbit by dragging, zoom with the wheel, and
// picking by casting the pointer's ray against every triangle
// (Möller–Trumbore), which answers a face and barycentric coordinates.
"use strict";
window.GX = window.GX || {};

(function () {
  const VS = `#version 300 es
  in vec3 pos; in vec3 nrm; in float val;
  uniform mat4 mvp; uniform mat4 model;
  out vec3 vn; out float vv;
  void main() { gl_Position = mvp * vec4(pos, 1.0); vn = mat3(model) * nrm; vv = val; }`;
  const FS = `#version 300 es
  precision highp float;
  in vec3 vn; in float vv;
  uniform float vmax; uniform float spacing; uniform vec3 ramp[17];
  out vec4 colour;
  void main() {
    vec3 n = normalize(vn);
    float light = 0.35 + 0.65 * abs(dot(n, normalize(vec3(0.3, 0.5, 1.0))));
    vec3 c = vec3(0.72);
    if (vv >= 0.0 && vmax > 0.0) {
      float t = clamp(vv / vmax, 0.0, 1.0) * 16.0;
      int i = int(min(floor(t), 15.0));
      c = mix(ramp[i], ramp[i + 1], t - float(i));
      if (spacing > 0.0) {
        float f = vv / spacing;
        float w = fwidth(f);
        float line = 1.0 - smoothstep(0.0, 1.5 * w, abs(f - round(f)));
        c = mix(c, vec3(1.0), 0.8 * line);
      }
    } else if (vv < -1.5) {
      c = vec3(0.5); // unreached
    }
    colour = vec4(c * light, 1.0);
  }`;
  const LVS = `#version 300 es
  in vec3 pos; uniform mat4 mvp; uniform float size;
  void main() { gl_Position = mvp * vec4(pos, 1.0); gl_Position.z -= 0.002 * gl_Position.w; gl_PointSize = size; }`;
  const LFS = `#version 300 es
  precision highp float; uniform vec3 tint; out vec4 colour;
  void main() { colour = vec4(tint, 1.0); }`;

  function compile(gl, vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }

  // Column-major 4×4 matrices.
  function mul(a, b) {
    const r = new Float32Array(16);
    for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + j] * b[i * 4 + k];
      r[i * 4 + j] = s;
    }
    return r;
  }
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
  }
  function rotation(yaw, pitch) {
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    // R = Rx(pitch) · Ry(yaw)
    return new Float32Array([cy, sp * sy, -cp * sy, 0, 0, cp, sp, 0, sy, -sp * cy, cp * cy, 0, 0, 0, 0, 1]);
  }
  function invert(m) {
    // General 4×4 inverse (cofactors).
    const inv = new Float32Array(16);
    const a = m;
    inv[0] = a[5] * a[10] * a[15] - a[5] * a[11] * a[14] - a[9] * a[6] * a[15] + a[9] * a[7] * a[14] + a[13] * a[6] * a[11] - a[13] * a[7] * a[10];
    inv[4] = -a[4] * a[10] * a[15] + a[4] * a[11] * a[14] + a[8] * a[6] * a[15] - a[8] * a[7] * a[14] - a[12] * a[6] * a[11] + a[12] * a[7] * a[10];
    inv[8] = a[4] * a[9] * a[15] - a[4] * a[11] * a[13] - a[8] * a[5] * a[15] + a[8] * a[7] * a[13] + a[12] * a[5] * a[11] - a[12] * a[7] * a[9];
    inv[12] = -a[4] * a[9] * a[14] + a[4] * a[10] * a[13] + a[8] * a[5] * a[14] - a[8] * a[6] * a[13] - a[12] * a[5] * a[10] + a[12] * a[6] * a[9];
    inv[1] = -a[1] * a[10] * a[15] + a[1] * a[11] * a[14] + a[9] * a[2] * a[15] - a[9] * a[3] * a[14] - a[13] * a[2] * a[11] + a[13] * a[3] * a[10];
    inv[5] = a[0] * a[10] * a[15] - a[0] * a[11] * a[14] - a[8] * a[2] * a[15] + a[8] * a[3] * a[14] + a[12] * a[2] * a[11] - a[12] * a[3] * a[10];
    inv[9] = -a[0] * a[9] * a[15] + a[0] * a[11] * a[13] + a[8] * a[1] * a[15] - a[8] * a[3] * a[13] - a[12] * a[1] * a[11] + a[12] * a[3] * a[9];
    inv[13] = a[0] * a[9] * a[14] - a[0] * a[10] * a[13] - a[8] * a[1] * a[14] + a[8] * a[2] * a[13] + a[12] * a[1] * a[10] - a[12] * a[2] * a[9];
    inv[2] = a[1] * a[6] * a[15] - a[1] * a[7] * a[14] - a[5] * a[2] * a[15] + a[5] * a[3] * a[14] + a[13] * a[2] * a[7] - a[13] * a[3] * a[6];
    inv[6] = -a[0] * a[6] * a[15] + a[0] * a[7] * a[14] + a[4] * a[2] * a[15] - a[4] * a[3] * a[14] - a[12] * a[2] * a[7] + a[12] * a[3] * a[6];
    inv[10] = a[0] * a[5] * a[15] - a[0] * a[7] * a[13] - a[4] * a[1] * a[15] + a[4] * a[3] * a[13] + a[12] * a[1] * a[7] - a[12] * a[3] * a[5];
    inv[14] = -a[0] * a[5] * a[14] + a[0] * a[6] * a[13] + a[4] * a[1] * a[14] - a[4] * a[2] * a[13] - a[12] * a[1] * a[6] + a[12] * a[2] * a[5];
    inv[3] = -a[1] * a[6] * a[11] + a[1] * a[7] * a[10] + a[5] * a[2] * a[11] - a[5] * a[3] * a[10] - a[9] * a[2] * a[7] + a[9] * a[3] * a[6];
    inv[7] = a[0] * a[6] * a[11] - a[0] * a[7] * a[10] - a[4] * a[2] * a[11] + a[4] * a[3] * a[10] + a[8] * a[2] * a[7] - a[8] * a[3] * a[6];
    inv[11] = -a[0] * a[5] * a[11] + a[0] * a[7] * a[9] + a[4] * a[1] * a[11] - a[4] * a[3] * a[9] - a[8] * a[1] * a[7] + a[8] * a[3] * a[5];
    inv[15] = a[0] * a[5] * a[10] - a[0] * a[6] * a[9] - a[4] * a[1] * a[10] + a[4] * a[2] * a[9] + a[8] * a[1] * a[6] - a[8] * a[2] * a[5];
    let det = a[0] * inv[0] + a[1] * inv[4] + a[2] * inv[8] + a[3] * inv[12];
    det = 1 / det;
    for (let i = 0; i < 16; i++) inv[i] *= det;
    return inv;
  }
  function apply(m, v) {
    const r = [0, 0, 0, 0];
    for (let j = 0; j < 4; j++) r[j] = m[j] * v[0] + m[4 + j] * v[1] + m[8 + j] * v[2] + m[12 + j] * v[3];
    return r;
  }

  class Viewer {
    constructor(canvas) {
      this.canvas = canvas;
      const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: true });
      if (!gl) throw new Error("this browser has no WebGL2: the mesh view cannot draw");
      this.gl = gl;
      this.prog = compile(gl, VS, FS);
      this.lprog = compile(gl, LVS, LFS);
      this.yaw = 0.6; this.pitch = 0.5; this.dist = 3;
      this.vmax = 0; this.spacing = 0;
      this.lines = []; this.points = null;
      this.showEdges = false; this.edges = null;
      this.onPick = null;
      this.bindInput();
    }

    setMesh(vertices, faces) {
      const gl = this.gl, n = vertices.length;
      // Centre and scale to the unit ball.
      const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
      for (const v of vertices) for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], v[k]); hi[k] = Math.max(hi[k], v[k]); }
      const c = lo.map((l, k) => (l + hi[k]) / 2);
      let rad = 0;
      for (const v of vertices) rad = Math.max(rad, Math.hypot(v[0] - c[0], v[1] - c[1], v[2] - c[2]));
      this.centre = c; this.scale = 1 / (rad || 1);
      const pos = new Float32Array(3 * n), nrm = new Float32Array(3 * n);
      vertices.forEach((v, i) => { for (let k = 0; k < 3; k++) pos[3 * i + k] = (v[k] - c[k]) * this.scale; });
      for (const [a, b, d] of faces) {
        const e1 = [0, 1, 2].map((k) => pos[3 * b + k] - pos[3 * a + k]);
        const e2 = [0, 1, 2].map((k) => pos[3 * d + k] - pos[3 * a + k]);
        const fn = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        for (const i of [a, b, d]) for (let k = 0; k < 3; k++) nrm[3 * i + k] += fn[k];
      }
      this.pos = pos; this.faces = faces; this.n = n;
      const idx = new Uint32Array(faces.length * 3);
      faces.forEach((f, i) => idx.set(f, 3 * i));
      this.vao = gl.createVertexArray();
      gl.bindVertexArray(this.vao);
      const attr = (prog, name, data, size) => {
        const buf = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, buf);
        gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
        const loc = gl.getAttribLocation(prog, name);
        gl.enableVertexAttribArray(loc);
        gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
        return buf;
      };
      const posBuf = attr(this.prog, "pos", pos, 3);
      attr(this.prog, "nrm", nrm, 3);
      this.valBuf = attr(this.prog, "val", new Float32Array(n).fill(-1), 1);
      const ib = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
      this.count = idx.length;
      gl.bindVertexArray(null);
      // The edges, each once, as line pairs over the same positions.
      const seen = new Set(), edges = [];
      for (const f of faces) for (let k = 0; k < 3; k++) {
        const a = f[k], b = f[(k + 1) % 3];
        const key = a < b ? a * n + b : b * n + a;
        if (!seen.has(key)) { seen.add(key); edges.push(a, b); }
      }
      const evao = gl.createVertexArray();
      gl.bindVertexArray(evao);
      gl.bindBuffer(gl.ARRAY_BUFFER, posBuf);
      const eloc = gl.getAttribLocation(this.lprog, "pos");
      gl.enableVertexAttribArray(eloc);
      gl.vertexAttribPointer(eloc, 3, gl.FLOAT, false, 0, 0);
      const eb = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, eb);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(edges), gl.STATIC_DRAW);
      gl.bindVertexArray(null);
      this.edges = { vao: evao, count: edges.length };
      this.values = null; this.vmax = 0; this.lines = []; this.points = null;
      this.draw();
    }

    /** Draws the mesh's edges (dark lines) or not. */
    setEdges(on) { this.showEdges = !!on; this.draw(); }

    /** Per-vertex values (null: unreached), coloured up to their maximum with `lines` iso-lines. */
    setValues(values, lines) {
      const gl = this.gl, a = new Float32Array(this.n);
      let hi = 0;
      values.forEach((v, i) => { if (v === null || !Number.isFinite(v)) a[i] = -2; else { a[i] = v; hi = Math.max(hi, v); } });
      this.values = a; this.vmax = hi; this.spacing = lines ? hi / (lines + 1) : 0;
      gl.bindBuffer(gl.ARRAY_BUFFER, this.valBuf);
      gl.bufferData(gl.ARRAY_BUFFER, a, gl.STATIC_DRAW);
      this.draw();
    }

    /** A polyline of model positions, drawn over the surface. */
    addLine(points, tint) {
      const gl = this.gl;
      const data = new Float32Array(points.length * 3);
      points.forEach((p, i) => { for (let k = 0; k < 3; k++) data[3 * i + k] = (p[k] - this.centre[k]) * this.scale; });
      const vao = gl.createVertexArray();
      gl.bindVertexArray(vao);
      const buf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
      const loc = gl.getAttribLocation(this.lprog, "pos");
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
      gl.bindVertexArray(null);
      this.lines.push({ vao, count: points.length, tint: tint || [1, 0.23, 0.19] });
      this.draw();
    }
    clearLines() { this.lines = []; this.points = null; this.draw(); }

    /** Marks the vertices `ids` as dots. */
    setPoints(ids, tint) {
      const pts = ids.map((i) => [0, 1, 2].map((k) => this.pos[3 * i + k] / this.scale + this.centre[k]));
      this.addLine(pts, tint || [1, 0.2, 0.6]);
      const l = this.lines.pop();
      this.points = l;
      this.draw();
    }

    matrices() {
      const c = this.canvas;
      const proj = perspective(0.8, c.width / c.height, 0.05, 50);
      const model = rotation(this.yaw, this.pitch);
      const view = new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, -this.dist, 1]);
      return { model, mvp: mul(proj, mul(view, model)) };
    }

    draw() {
      const gl = this.gl, c = this.canvas;
      gl.viewport(0, 0, c.width, c.height);
      gl.clearColor(0.11, 0.12, 0.14, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      if (!this.vao) return;
      gl.enable(gl.DEPTH_TEST);
      const { model, mvp } = this.matrices();
      gl.useProgram(this.prog);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.prog, "mvp"), false, mvp);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.prog, "model"), false, model);
      gl.uniform1f(gl.getUniformLocation(this.prog, "vmax"), this.vmax);
      gl.uniform1f(gl.getUniformLocation(this.prog, "spacing"), this.spacing);
      gl.uniform3fv(gl.getUniformLocation(this.prog, "ramp"), new Float32Array(GX.VIRIDIS.flat().map((v) => v / 255)));
      gl.bindVertexArray(this.vao);
      gl.drawElements(gl.TRIANGLES, this.count, gl.UNSIGNED_INT, 0);
      gl.useProgram(this.lprog);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.lprog, "mvp"), false, mvp);
      if (this.showEdges && this.edges) {
        gl.uniform3fv(gl.getUniformLocation(this.lprog, "tint"), [0.13, 0.14, 0.17]);
        gl.uniform1f(gl.getUniformLocation(this.lprog, "size"), 1);
        gl.bindVertexArray(this.edges.vao);
        gl.drawElements(gl.LINES, this.edges.count, gl.UNSIGNED_INT, 0);
      }
      for (const l of this.lines) {
        // WebGL draws lines one pixel wide: dots of 4 pixels at the vertices make a path visible.
        gl.uniform3fv(gl.getUniformLocation(this.lprog, "tint"), l.tint);
        gl.uniform1f(gl.getUniformLocation(this.lprog, "size"), 4);
        gl.bindVertexArray(l.vao);
        gl.drawArrays(gl.LINE_STRIP, 0, l.count);
        gl.drawArrays(gl.POINTS, 0, l.count);
      }
      if (this.points) {
        gl.uniform3fv(gl.getUniformLocation(this.lprog, "tint"), this.points.tint);
        gl.uniform1f(gl.getUniformLocation(this.lprog, "size"), 7);
        gl.bindVertexArray(this.points.vao);
        gl.drawArrays(gl.POINTS, 0, this.points.count);
      }
      gl.bindVertexArray(null);
    }

    /** The face and barycentric coordinates under canvas pixel (x, y), or null. */
    pick(x, y) {
      if (!this.vao) return null;
      const c = this.canvas;
      const nx = 2 * x / c.clientWidth - 1, ny = 1 - 2 * y / c.clientHeight;
      const inv = invert(this.matrices().mvp);
      const h = (v) => { const r = apply(inv, v); return [r[0] / r[3], r[1] / r[3], r[2] / r[3]]; };
      const o = h([nx, ny, -1, 1]), e = h([nx, ny, 1, 1]);
      const d = [e[0] - o[0], e[1] - o[1], e[2] - o[2]];
      const P = this.pos;
      let best = null;
      for (let f = 0; f < this.faces.length; f++) {
        const [a, b, cc] = this.faces[f];
        const ax = P[3 * a], ay = P[3 * a + 1], az = P[3 * a + 2];
        const e1 = [P[3 * b] - ax, P[3 * b + 1] - ay, P[3 * b + 2] - az];
        const e2 = [P[3 * cc] - ax, P[3 * cc + 1] - ay, P[3 * cc + 2] - az];
        const p = [d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]];
        const det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
        if (Math.abs(det) < 1e-12) continue;
        const t0 = [o[0] - ax, o[1] - ay, o[2] - az];
        const u = (t0[0] * p[0] + t0[1] * p[1] + t0[2] * p[2]) / det;
        if (u < 0 || u > 1) continue;
        const q = [t0[1] * e1[2] - t0[2] * e1[1], t0[2] * e1[0] - t0[0] * e1[2], t0[0] * e1[1] - t0[1] * e1[0]];
        const v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) / det;
        if (v < 0 || u + v > 1) continue;
        const t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) / det;
        if (t > 0 && (!best || t < best.t)) best = { t, face: f, bary: [1 - u - v, u, v] };
      }
      return best;
    }

    bindInput() {
      const c = this.canvas;
      let drag = null;
      c.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, moved: false }; c.setPointerCapture(e.pointerId); });
      c.addEventListener("pointermove", (e) => {
        if (!drag) return;
        const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
        if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
        if (drag.moved) {
          this.yaw += dx * 0.01; this.pitch = Math.max(-1.5, Math.min(1.5, this.pitch + dy * 0.01));
          drag.x = e.clientX; drag.y = e.clientY;
          this.draw();
        }
      });
      c.addEventListener("pointerup", (e) => {
        if (drag && !drag.moved && this.onPick) {
          const r = c.getBoundingClientRect();
          const hit = this.pick(e.clientX - r.left, e.clientY - r.top);
          if (hit) this.onPick(hit, e);
        }
        drag = null;
      });
      c.addEventListener("wheel", (e) => {
        e.preventDefault();
        this.dist = Math.max(1.2, Math.min(10, this.dist * Math.exp(e.deltaY * 0.001)));
        this.draw();
      }, { passive: false });
    }
  }

  GX.Viewer = Viewer;
})();
