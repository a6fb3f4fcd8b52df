#!/usr/bin/env python3
"""Level-set redistancing: geodex against scikit-fmm on the same phi.

    python3 -m venv /tmp/venv-skfmm && /tmp/venv-skfmm/bin/pip install numpy scikit-fmm
    cargo build --release --bin geodex
    /tmp/venv-skfmm/bin/python tests/bench/compare_skfmm_levelset.py [--sizes 512,1024] [--repeat 3]

For each grid size n (n x n, unit spacing) and two phis with the same zero
level set, a circle of radius 0.293 n around (0.4986 n, 0.5012 n) (off the
grid points):

* `dist`:    phi = |x - c| - r (already a signed distance),
* `squared`: phi = |x - c|^2 - r^2 (not a distance: |grad phi| = 2|x - c|),

both `skfmm.distance(phi, dx=1, order=k)` and
`geodex distance --phi phi.npy --signed --order k` run, for k = 1 and 2,
in the same run, alternately. The table gives the max error in cells over
every cell against the exact signed distance |x - c| - r, the max over the
cells 10 or more cells from the centre (`off-c`: the centre is the medial
point, a cone where the converging fronts give every upwind scheme an error
of its own, whatever the interface), the mean error over every cell, and the
time: scikit-fmm's call (best of --repeat), geodex's solve as it reports it
(`solve X s`: interface location and march, no file IO; best of --repeat),
and geodex's whole process (reading and writing the NPY files included).
"""

import argparse
import os
import re
import subprocess
import tempfile
import time

import numpy as np
import skfmm

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GEODEX = os.environ.get("GEODEX_BIN", os.path.join(ROOT, "target", "release", "geodex"))


def phis(n):
    c = np.array([0.4986 * n, 0.5012 * n])
    r = 0.293 * n
    i, j = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    rho = np.hypot(i - c[0], j - c[1])
    exact = rho - r
    return exact, rho, {"dist": rho - r, "squared": rho**2 - r**2}


def geodex_once(phi_path, out_path, order):
    s = time.perf_counter()
    r = subprocess.run(
        [GEODEX, "distance", "--phi", phi_path, "--signed", "--order", str(order), "--out", out_path],
        capture_output=True, text=True, check=True,
    )
    wall = time.perf_counter() - s
    solve = float(re.search(r"solve ([0-9.]+) s", r.stdout).group(1))
    return solve, wall


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="512,1024")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"scikit-fmm {skfmm.__version__}, numpy {np.__version__}, geodex {GEODEX}")
    print(f"{'n':>5} {'phi':>8} {'order':>5} | {'skfmm max':>9} {'off-c':>7} {'mean':>7} {'time s':>7} | "
          f"{'geodex max':>10} {'off-c':>7} {'mean':>7} {'solve s':>7} {'process s':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in [int(x) for x in args.sizes.split(",")]:
            exact, rho, cases = phis(n)
            off = rho >= 10.0
            for name, phi in cases.items():
                phi_path = os.path.join(tmp, f"phi_{n}_{name}.npy")
                np.save(phi_path, phi)
                out_path = os.path.join(tmp, "u.npy")
                for order in (1, 2):
                    ts, tg, tw = [], [], []
                    d_sk = u = None
                    for _ in range(args.repeat):
                        s = time.perf_counter()
                        d_sk = np.asarray(skfmm.distance(phi, dx=1.0, order=order))
                        ts.append(time.perf_counter() - s)
                        solve, wall = geodex_once(phi_path, out_path, order)
                        tg.append(solve)
                        tw.append(wall)
                    u = np.load(out_path)
                    e_sk = np.abs(d_sk - exact)
                    e_g = np.abs(u - exact)
                    print(f"{n:>5} {name:>8} {order:>5} | {e_sk.max():9.4f} {e_sk[off].max():7.4f} "
                          f"{e_sk.mean():7.4f} {min(ts):7.3f} | {e_g.max():10.4f} {e_g[off].max():7.4f} "
                          f"{e_g.mean():7.4f} {min(tg):7.3f} {min(tw):9.3f}", flush=True)
    print(os.getloadavg())


if __name__ == "__main__":
    main()
