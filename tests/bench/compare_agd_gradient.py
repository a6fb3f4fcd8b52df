#!/usr/bin/env python3
"""The cost gradient of geodex (`geodex cost-gradient`, the discrete adjoint of
fast marching) against HFM/agd's reverse-mode sensitivity
(`inspectSensitivity`, PyPI `agd` driving HFM's `FileHFM_Isotropic2`), on the
same isotropic problem, in the same run.

The problem: an n x n grid, spacing 1, a smooth cost
W = 1 + 0.5 sin(6 pi i / n) cos(4 pi j / n), one point source at the centre,
m targets on cells drawn at random (seeded), J = sum of U over the targets.
HFM's grid is placed so that its cell centres are geodex's index points
(origin -0.5, gridScale 1, row-major), and both snap the targets to cells.

Printed per order (1, 2):
- wall time of each tool, end to end (files in, files out), best of --repeat;
- geodex's own solve and adjoint times (from its stderr) and HFM's FMCPUTime
  (the forward march it reports), plus HFM's wall time without the
  sensitivity request (so the cost of its backward pass can be read off);
- accuracy: each tool's directional derivative sum(g * delta) against a
  centred finite difference of its own J (two more solves each), and the
  relative L1 gap between the two gradients; and U at the targets on a unit
  cost against the Euclidean distance (the forward accuracy of each scheme).

Usage (the venv needs numpy, scipy and agd: agd 0.2.16 imports scipy without declaring it; HFM's FileHFM_Isotropic2 built from
its sources, see tests/bench/README.md):
    python3 tests/bench/compare_agd_gradient.py --geodex target/release/geodex \
        --hfm-dir /tmp/hfm --n 1024 --targets 1000 --repeat 3
"""

import argparse
import os
import re
import subprocess
import tempfile
import time

import numpy as np


def run_geodex(binary, work, cost, source, targets, order):
    np.save(os.path.join(work, "w.npy"), cost)
    np.save(os.path.join(work, "y.npy"), targets.astype(np.float64))
    out = os.path.join(work, "g.npy")
    cmd = [
        binary, "cost-gradient", "--cost", os.path.join(work, "w.npy"),
        "--source", f"{source[0]},{source[1]}",
        "--targets", os.path.join(work, "y.npy"),
        "--order", str(order), "--threads", "1",
        "--out", out, "--json", os.path.join(work, "r.json"),
    ]
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"geodex failed: {p.stderr}")
    m = re.search(r"J = ([^ ]+) .*forward solve ([0-9.]+) s, adjoint ([0-9.]+) s", p.stderr)
    if not m:
        raise SystemExit(f"unexpected geodex output: {p.stderr}")
    return {
        "wall": wall,
        "J": float(m.group(1)),
        "solve": float(m.group(2)),
        "adjoint": float(m.group(3)),
        "g": np.load(out),
    }


def run_hfm(cost, source, targets, order, sensitivity=True):
    from agd import Eikonal

    n0, n1 = cost.shape
    params = {
        "model": "Isotropic2",
        "cost": cost,
        "seeds": [list(map(float, source))],
        "arrayOrdering": "RowMajor",
        "order": order,
        "exportValues": 1,
        "verbosity": 0,
    }
    if sensitivity:
        params["inspectSensitivity"] = targets.astype(np.float64)
        params["inspectSensitivityWeights"] = np.ones(len(targets))
        params["inspectSensitivityLengths"] = [len(targets)]
    hfm_in = Eikonal.dictIn(params)
    hfm_in.SetRect(sides=[[-0.5, n0 - 0.5], [-0.5, n1 - 0.5]], dims=[n0, n1])
    t = time.perf_counter()
    out = hfm_in.Run()
    wall = time.perf_counter() - t
    u = out["values"]
    r = {
        "wall": wall,
        "fm": float(out["FMCPUTime"]),
        "J": float(sum(u[int(a), int(b)] for a, b in targets)),
        "u": u,
    }
    if sensitivity:
        r["g"] = out["costSensitivity_0"]
    return r


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--geodex", default="target/release/geodex")
    ap.add_argument("--hfm-dir", default="/tmp/hfm", help="folder of FileHFM_Isotropic2")
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--targets", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--orders", default="1,2")
    ap.add_argument("--eps", type=float, default=1e-4)
    args = ap.parse_args()

    from agd.Eikonal import LibraryCall

    LibraryCall.binary_dir["FileHFM"] = args.hfm_dir

    n = args.n
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    cost = 1.0 + 0.5 * np.sin(6 * np.pi * i / n) * np.cos(4 * np.pi * j / n)
    delta = np.cos(2 * np.pi * i / n) * np.sin(3 * np.pi * j / n) + 0.5
    rng = np.random.default_rng(7)
    source = (n // 2, n // 2)
    targets = rng.integers(0, n, size=(args.targets, 2))
    targets = targets[np.any(targets != np.array(source), axis=1)]
    unit = np.ones((n, n))
    exact = np.hypot(targets[:, 0] - source[0], targets[:, 1] - source[1])

    print(f"grid {n}x{n}, {len(targets)} targets, one source at the centre; best of {args.repeat}")
    with tempfile.TemporaryDirectory() as work:
        for order in [int(o) for o in args.orders.split(",")]:
            geo = min((run_geodex(args.geodex, work, cost, source, targets, order)
                       for _ in range(args.repeat)), key=lambda r: r["wall"])
            hfm = min((run_hfm(cost, source, targets, order)
                       for _ in range(args.repeat)), key=lambda r: r["wall"])
            hfm_fwd = min((run_hfm(cost, source, targets, order, sensitivity=False)
                           for _ in range(args.repeat)), key=lambda r: r["wall"])
            # Accuracy of each against its own finite difference.
            e = args.eps
            fd_geo = (run_geodex(args.geodex, work, cost + e * delta, source, targets, order)["J"]
                      - run_geodex(args.geodex, work, cost - e * delta, source, targets, order)["J"]) / (2 * e)
            fd_hfm = (run_hfm(cost + e * delta, source, targets, order, False)["J"]
                      - run_hfm(cost - e * delta, source, targets, order, False)["J"]) / (2 * e)
            dir_geo = float(np.sum(geo["g"] * delta))
            dir_hfm = float(np.sum(hfm["g"] * delta))
            gap = float(np.abs(geo["g"] - hfm["g"]).sum() / np.abs(hfm["g"]).sum())
            # Forward accuracy on a unit cost.
            u_geo = run_geodex(args.geodex, work, unit, source, targets, order)
            u_hfm = run_hfm(unit, source, targets, order, False)
            err_geo = abs(u_geo["J"] - exact.sum()) / exact.sum()
            err_hfm = abs(u_hfm["J"] - exact.sum()) / exact.sum()
            print(f"\norder {order}")
            print(f"  geodex: wall {geo['wall']:.3f} s (solve {geo['solve']:.3f} s, adjoint "
                  f"{geo['adjoint']:.3f} s = {geo['adjoint'] / geo['solve']:.2f}x the solve)")
            print(f"  HFM:    wall {hfm['wall']:.3f} s (FMCPUTime {hfm['fm']:.3f} s; "
                  f"without the sensitivity: wall {hfm_fwd['wall']:.3f} s)")
            print(f"  end to end, HFM / geodex: {hfm['wall'] / geo['wall']:.2f}x; "
                  f"backward pass alone, HFM (wall difference) {hfm['wall'] - hfm_fwd['wall']:.3f} s"
                  f" vs geodex {geo['adjoint']:.3f} s")
            print(f"  directional derivative vs own finite difference: geodex rel "
                  f"{abs(dir_geo - fd_geo) / abs(fd_geo):.2e}, HFM rel {abs(dir_hfm - fd_hfm) / abs(fd_hfm):.2e}")
            print(f"  relative L1 gap between the two gradients: {gap:.3e}; J geodex {geo['J']:.6f}, HFM {hfm['J']:.6f}")
            print(f"  unit cost, sum of U at the targets vs Euclidean: geodex rel {err_geo:.2e}, HFM rel {err_hfm:.2e}")


if __name__ == "__main__":
    main()
