// Sample data made in code (nothing to license): grey images drawn from
// closed-form shapes with a fixed-seed noise, and triangle meshes (a torus,
// a bumpy sphere, a rolled sheet) written as OBJ text.
"use strict";
window.GX = window.GX || {};

(function () {
  function rng(seed) {
    // mulberry32: a small deterministic PRNG, so that samples are reproducible.
    return function () {
      seed |= 0; seed = (seed + 0x6d2b79f5) | 0;
      let t = Math.imul(seed ^ (seed >>> 15), 1 | seed);
      t = (t + Math.imul(t ^ (t >>> 7), 61 | t)) ^ t;
      return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
    };
  }

  /** Distance from (x, y) to the segment a-b. */
  function segDist(x, y, ax, ay, bx, by) {
    const dx = bx - ax, dy = by - ay;
    const t = Math.max(0, Math.min(1, ((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy || 1)));
    return Math.hypot(x - ax - t * dx, y - ay - t * dy);
  }

  // Each sample: (n) -> Uint8Array of n*n grey values, row-major (axis 0 = rows).
  const IMAGES = {
    // Dark winding tubes on a bright background: vesselness (dark) or intensity at a tube.
    vessels(n) {
      const r = rng(7), g = new Uint8Array(n * n);
      const curves = [];
      for (let k = 0; k < 5; k++) {
        curves.push({ y0: (0.15 + 0.17 * k) * n, a: (0.04 + 0.05 * r()) * n, f: 1 + 2 * r(), p: 6.3 * r(), w: (0.006 + 0.008 * r()) * n });
      }
      for (let i = 0; i < n; i++) for (let j = 0; j < n; j++) {
        let v = 200 + 20 * Math.sin(j / n * 3 + i / n * 2);
        for (const c of curves) {
          const yc = c.y0 + c.a * Math.sin(c.f * 6.283 * j / n + c.p);
          const d = (i - yc) / c.w;
          v -= 140 * Math.exp(-0.5 * d * d);
        }
        // a vertical tube joining the others
        const xc = 0.55 * n + 0.05 * n * Math.sin(6.283 * i / n * 1.5);
        const dv = (j - xc) / (0.008 * n);
        v -= 120 * Math.exp(-0.5 * dv * dv);
        g[i * n + j] = Math.max(0, Math.min(255, v + 18 * (r() - 0.5)));
      }
      return g;
    },
    // Bright discs on a dark background: edges, segmentation by seeds.
    cells(n) {
      const r = rng(11), g = new Uint8Array(n * n);
      const discs = [];
      for (let k = 0; k < 14; k++) discs.push({ x: (0.1 + 0.8 * r()) * n, y: (0.1 + 0.8 * r()) * n, rad: (0.05 + 0.07 * r()) * n, v: 140 + 100 * r() });
      for (let i = 0; i < n; i++) for (let j = 0; j < n; j++) {
        let v = 30;
        for (const d of discs) {
          const e = Math.hypot(i - d.y, j - d.x) - d.rad;
          v = Math.max(v, 30 + (d.v - 30) / (1 + Math.exp(e / (0.004 * n + 0.5))));
        }
        g[i * n + j] = Math.max(0, Math.min(255, v + 20 * (r() - 0.5)));
      }
      return g;
    },
    // Bright rooms with dark walls and doors: minimal paths go through the doors.
    rooms(n) {
      const r = rng(5), g = new Uint8Array(n * n);
      const walls = [
        [0.33, 0.0, 0.33, 0.42], [0.33, 0.52, 0.33, 1.0],
        [0.66, 0.0, 0.66, 0.72], [0.66, 0.82, 0.66, 1.0],
        [0.0, 0.5, 0.14, 0.5], [0.22, 0.5, 0.33, 0.5],
        [0.66, 0.3, 0.84, 0.3], [0.92, 0.3, 1.0, 0.3],
      ];
      const w = Math.max(2, 0.012 * n);
      for (let i = 0; i < n; i++) for (let j = 0; j < n; j++) {
        let v = 215 + 15 * Math.sin(i / n * 9) * Math.cos(j / n * 7);
        for (const s of walls) {
          if (segDist(j, i, s[0] * n, s[1] * n, s[2] * n, s[3] * n) < w) v = 25;
        }
        g[i * n + j] = Math.max(0, Math.min(255, v + 14 * (r() - 0.5)));
      }
      return g;
    },
    // A binary shape (a disc, a bar and a ring): for EDT, skeleton and offset.
    shape(n) {
      const g = new Uint8Array(n * n);
      for (let i = 0; i < n; i++) for (let j = 0; j < n; j++) {
        const y = i / n, x = j / n;
        const disc = Math.hypot(x - 0.3, y - 0.35) < 0.2;
        const bar = Math.abs(y - 0.7) < 0.07 && x > 0.15 && x < 0.85;
        const ring = Math.abs(Math.hypot(x - 0.7, y - 0.3) - 0.15) < 0.05;
        g[i * n + j] = disc || bar || ring ? 255 : 0;
      }
      return g;
    },
  };

  /** Grey values → a PNG Blob (through a canvas). */
  function greyToPng(grey, h, w) {
    const c = document.createElement("canvas");
    c.width = w; c.height = h;
    const ctx = c.getContext("2d");
    const img = ctx.createImageData(w, h);
    for (let k = 0; k < w * h; k++) {
      img.data[4 * k] = img.data[4 * k + 1] = img.data[4 * k + 2] = grey[k];
      img.data[4 * k + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
    return new Promise((ok) => c.toBlob(ok, "image/png"));
  }

  function torus(R, r, nu, nv) {
    const v = [], f = [];
    for (let i = 0; i < nu; i++) for (let j = 0; j < nv; j++) {
      const u = 2 * Math.PI * i / nu, w = 2 * Math.PI * j / nv;
      v.push([(R + r * Math.cos(w)) * Math.cos(u), (R + r * Math.cos(w)) * Math.sin(u), r * Math.sin(w)]);
    }
    const id = (i, j) => (i % nu) * nv + (j % nv);
    for (let i = 0; i < nu; i++) for (let j = 0; j < nv; j++) {
      f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
      f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
    }
    return { v, f };
  }

  /** An icosphere subdivided `level` times, with radial bumps of height `bump`. */
  function sphere(level, bump) {
    const t = (1 + Math.sqrt(5)) / 2;
    let v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]];
    let f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]];
    const norm = (p) => { const l = Math.hypot(p[0], p[1], p[2]); return [p[0] / l, p[1] / l, p[2] / l]; };
    v = v.map(norm);
    for (let s = 0; s < level; s++) {
      const mid = new Map(), nf = [];
      const m = (a, b) => {
        const k = a < b ? a + "," + b : b + "," + a;
        if (!mid.has(k)) { v.push(norm([(v[a][0] + v[b][0]) / 2, (v[a][1] + v[b][1]) / 2, (v[a][2] + v[b][2]) / 2])); mid.set(k, v.length - 1); }
        return mid.get(k);
      };
      for (const [a, b, c] of f) {
        const ab = m(a, b), bc = m(b, c), ca = m(c, a);
        nf.push([a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]);
      }
      f = nf;
    }
    v = v.map(([x, y, z]) => {
      const h = 1 + bump * Math.sin(3 * x) * Math.sin(3 * y) * Math.sin(3 * z + 1);
      return [x * h, y * h, z * h];
    });
    return { v, f };
  }

  /**
   * A flat rectangular sheet rolled up along the Archimedean spiral
   * r = a θ (θ from 1.5π to 4.5π: one and a half turns), `nu` vertices
   * along the roll spaced evenly in arc length and `nv` across, so that the
   * triangles are nearly right isosceles. Rolling bends without stretching:
   * its geodesic distances are those of the flat rectangle, so its canonical
   * form (mesh.embed) is the sheet unrolled.
   */
  function rolledSheet(nu, nv) {
    const a = 0.08, t0 = 1.5 * Math.PI, t1 = 4.5 * Math.PI, K = 4000;
    const th = [t0], s = [0];
    for (let k = 1; k <= K; k++) {
      const t = t0 + (t1 - t0) * k / K, tm = t - (t1 - t0) / (2 * K);
      th.push(t);
      s.push(s[k - 1] + a * Math.sqrt(1 + tm * tm) * (t1 - t0) / K);
    }
    const L = s[K], H = L * (nv - 1) / (nu - 1);
    const v = [], f = [];
    let j = 0;
    for (let i = 0; i < nu; i++) {
      const target = L * i / (nu - 1);
      while (j < K - 1 && s[j + 1] < target) j++;
      const t = th[j] + (target - s[j]) / (s[j + 1] - s[j]) * (th[j + 1] - th[j]);
      for (let k = 0; k < nv; k++) v.push([a * t * Math.cos(t), H * k / (nv - 1), a * t * Math.sin(t)]);
    }
    for (let i = 0; i + 1 < nu; i++) for (let k = 0; k + 1 < nv; k++) {
      const p = i * nv + k;
      f.push([p, p + nv, p + nv + 1], [p, p + nv + 1, p + 1]);
    }
    return { v, f };
  }

  function toObj(m) {
    const lines = m.v.map((p) => "v " + p.map((c) => c.toFixed(6)).join(" "));
    for (const t of m.f) lines.push("f " + (t[0] + 1) + " " + (t[1] + 1) + " " + (t[2] + 1));
    return lines.join("\n") + "\n";
  }

  const MESHES = {
    torus: () => toObj(torus(1, 0.4, 96, 40)),
    "bumpy sphere": () => toObj(sphere(4, 0.25)),
    "rolled sheet": () => toObj(rolledSheet(72, 18)),
    "big sphere (jobs)": () => toObj(sphere(6, 0.25)),
  };

  GX.samples = { IMAGES, MESHES, greyToPng };
})();
