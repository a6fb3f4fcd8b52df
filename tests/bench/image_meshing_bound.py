#!/usr/bin/env python3
"""How far below a uniform mesh's L2 error can a 2,000-vertex mesh of
scikit-image's `camera` go? A reference for issue 18's image-meshing target
(adaptive error at most half the uniform one), independent of geodex.

Two meshes with the same vertex count (`--count`, 2,000 by default), both
Delaunay triangulations of pixel centres in index coordinates, the image
scaled to [0, 1]:

- **uniform**: a hexagonal lattice plus points along the border;
- **greedy**: error-driven insertion (Garland and Heckbert's greedy
  insertion with the L2 measure): starting from the corners and border
  points every 32 pixels, each round takes the triangles with the largest
  sum of squared interpolation error (a tenth of the vertex count per
  round) and inserts, in each, its pixel of largest error. It uses the
  image itself, not a metric, so it is what a metric-driven sampling can
  hope to approach, not a bound it must stay above.

For each: the L2 error (root mean square over the 512² pixels) of the
piecewise-linear *interpolation* (vertex values = pixel values, what the
issue measures), and of the *least-squares* fit (the best vertex values
for that triangulation, by LSQR).

    python3 -m venv /tmp/venv-skimage
    /tmp/venv-skimage/bin/pip install scikit-image scipy
    /tmp/venv-skimage/bin/python tests/bench/image_meshing_bound.py
"""

import argparse
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from scipy.spatial import Delaunay
from skimage import data

IMG = data.camera().astype(float) / 255.0
N0, N1 = IMG.shape
PIX = np.column_stack([a.ravel() for a in np.mgrid[0:N0, 0:N1]]).astype(float)
FLAT = IMG.ravel()


def barycentric(points):
    tri = Delaunay(points)
    s = tri.find_simplex(PIX)
    t = tri.transform[s]
    b = np.einsum("ijk,ik->ij", t[:, :2], PIX - t[:, 2])
    return tri, s, np.column_stack([b, 1.0 - b.sum(axis=1)])


def errors(points):
    """(L2 of interpolation, L2 of the least-squares fit, per-pixel error, triangle ids)."""
    tri, s, bc = barycentric(points)
    corners = tri.simplices[s]
    values = IMG[points[:, 0].astype(int), points[:, 1].astype(int)]
    interpolated = (values[corners] * bc).sum(axis=1)
    rows = np.repeat(np.arange(len(PIX)), 3)
    a = sp.csr_matrix((bc.ravel(), (rows, corners.ravel())), shape=(len(PIX), len(points)))
    fit = sla.lsqr(a, FLAT, atol=1e-10, btol=1e-10, iter_lim=5000)[0]
    l2 = lambda r: float(np.sqrt(np.mean(r**2)))
    return l2(interpolated - FLAT), l2(a @ fit - FLAT), interpolated - FLAT, s


def uniform(count):
    h = np.sqrt(2 * N0 * N1 / (np.sqrt(3) * count))
    pts, r, x = [], 0, 0.0
    while x <= N0 - 1:
        y = (h / 2) * (r % 2)
        while y <= N1 - 1:
            pts.append((x, y))
            y += h
        r, x = r + 1, x + h * np.sqrt(3) / 2
    for t in np.linspace(0, N1 - 1, int(N1 / h) + 1):
        pts += [(0, t), (N0 - 1, t), (t, 0), (t, N1 - 1)]
    return np.unique(np.round(np.array(pts)), axis=0)


def greedy(count):
    pts = [(0, 0), (0, N1 - 1), (N0 - 1, 0), (N0 - 1, N1 - 1)]
    for t in range(32, 512, 32):
        pts += [(0, t), (N0 - 1, t), (t, 0), (t, N1 - 1)]
    pts = np.array(pts, float)
    taken = np.zeros(len(PIX), bool)
    while len(pts) < count:
        tri, s, bc = barycentric(pts)
        values = IMG[pts[:, 0].astype(int), pts[:, 1].astype(int)]
        r = ((values[tri.simplices[s]] * bc).sum(axis=1) - FLAT) ** 2
        per_triangle = np.bincount(s, weights=r, minlength=len(tri.simplices))
        batch = max(1, min(count - len(pts), len(pts) // 10))
        worst = np.argsort(per_triangle)[::-1][:batch]
        rr = np.where(taken, -1.0, r)
        order = np.lexsort((-rr, s))  # by triangle, largest error first
        first = np.ones(len(order), bool)
        first[1:] = s[order][1:] != s[order][:-1]
        best = dict(zip(s[order][first], order[first]))
        new = [best[w] for w in worst if w in best]
        taken[new] = True
        pts = np.vstack([pts, PIX[new]])
    return pts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=2000)
    args = ap.parse_args()
    t = time.perf_counter()
    # The lattice count that lands nearest the asked vertex count.
    u = min((uniform(int(args.count * f)) for f in np.linspace(0.85, 1.0, 16)),
            key=lambda m: abs(len(m) - args.count))
    g = greedy(len(u))
    ui, ul, _, _ = errors(u)
    gi, gl, _, _ = errors(g)
    print("| mesh | vertices | L2, interpolation | / uniform | L2, least squares | / uniform interpolation |")
    print("|---|---|---|---|---|---|")
    print(f"| uniform | {len(u)} | {ui:.5f} | 1.000 | {ul:.5f} | {ul / ui:.3f} |")
    print(f"| greedy L2 insertion | {len(g)} | {gi:.5f} | {gi / ui:.3f} | {gl:.5f} | {gl / ui:.3f} |")
    print(f"({time.perf_counter() - t:.1f} s)")


if __name__ == "__main__":
    main()
