#!/usr/bin/env python3
"""Times scikit-fmm and eikonalfm on the cases of `geodex bench`, printing
lines in the format of `geodex bench --json` (one JSON object per line, with
"tool" telling the implementations apart), or a table with --table.

This script installs nothing. Set up its environment once with:

    python3 -m venv /tmp/geodex-bench
    /tmp/geodex-bench/bin/pip install scikit-fmm eikonalfm numpy

and run it with that interpreter (single-threaded, like the geodex solvers):

    /tmp/geodex-bench/bin/python tests/bench/compare_python.py --repeat 3 --table

Cases (the same grids as `geodex bench`, domain [0, 1]^d, h = 1/(N-1)):

* point2d-2048, point3d-256: scikit-fmm has no point sources, so phi is
  |x - p| - r0 with r0 = 1.5 h (p at the centre) and the exact solution is
  |x - p| - r0 (signed, for `skfmm.distance`) or its absolute value
  (`skfmm.travel_time` with unit speed). `order` 1 and 2.
* poincare2d-1024: W = 1/y on [-0.5, 0.5] x [1, 2] (axis 0 is x), solved by
  eikonalfm's factored fast marching (`eikonalfm.factored_fast_marching`,
  speed c = y, orders 1 and 2); U = tau0 * tau1 with tau0 the distance to the
  source. eikonalfm needs the source on a grid node, so it is the node
  nearest to (0, 1.5), and the exact solution
  arcosh(1 + |x - p|^2 / (2 y y0)) uses that node.

Errors are max and mean |U - exact| over all cells; times are the best of
--repeat runs of the solver call alone (phi and the speed array are built
beforehand).

Side by side with geodex (the JSON lines of both tools in one table):

    cargo run --release -- bench --json > /tmp/geodex.jsonl
    /tmp/geodex-bench/bin/python tests/bench/compare_python.py --json > /tmp/python.jsonl
    python3 tests/bench/compare_python.py --render /tmp/geodex.jsonl /tmp/python.jsonl
"""

import argparse
import json
import sys
import time

try:
    import numpy as np
except ImportError:  # --render needs only the standard library
    np = None


def best_time(fn, repeat):
    best, out = float("inf"), None
    for _ in range(repeat):
        out = None
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def record(tool, case, method, order, seconds, u, exact):
    cells = int(np.prod(u.shape))
    err = np.abs(np.asarray(u, dtype=np.float64) - exact)
    err = err[np.isfinite(err)]
    return {
        "tool": tool,
        "case": case,
        "method": method,
        "order": order,
        "cells": cells,
        "repeat": ARGS.repeat,
        "seconds": seconds,
        "ns_per_cell": seconds * 1e9 / cells,
        "max_error": float(err.max()),
        "mean_error": float(err.mean()),
        "peak_bytes_per_cell": None,
    }


def point_cases(skfmm, n, dims):
    h = 1.0 / (n - 1)
    mid = (n - 1) / 2.0
    axes = np.meshgrid(*([np.arange(n, dtype=np.float64)] * dims), indexing="ij", sparse=True)
    r = h * np.sqrt(sum((a - mid) ** 2 for a in axes))
    r0 = 1.5 * h
    phi = r - r0
    speed = np.ones_like(phi)
    case = f"point{dims}d-{n}"
    out = []
    for order in (1, 2):
        name = f"{case}-fmm-o{order}"
        s, u = best_time(lambda: skfmm.distance(phi, dx=h, order=order), ARGS.repeat)
        out.append(record("scikit-fmm", name, "skfmm.distance", order, s, u, phi))
        s, u = best_time(
            lambda: skfmm.travel_time(phi, speed, dx=h, order=order), ARGS.repeat
        )
        out.append(record("scikit-fmm", name, "skfmm.travel_time", order, s, u, np.abs(phi)))
    return out


def poincare_cases(eikonalfm, n):
    h = 1.0 / (n - 1)
    i0 = int(round(0.5 / h))
    x = -0.5 + h * np.arange(n, dtype=np.float64)[:, None]
    y = 1.0 + h * np.arange(n, dtype=np.float64)[None, :]
    x0, y0 = -0.5 + i0 * h, 1.0 + i0 * h
    exact = np.arccosh(1.0 + ((x - x0) ** 2 + (y - y0) ** 2) / (2.0 * y * y0))
    c = np.ascontiguousarray(np.broadcast_to(y, (n, n)))
    src = (i0, i0)
    dx = (h, h)
    out = []
    for order in (1, 2):

        def solve():
            tau1 = eikonalfm.factored_fast_marching(c, src, dx, order)
            tau0 = eikonalfm.distance(tau1.shape, dx, src, indexing="ij")
            return tau0 * tau1

        s, u = best_time(solve, ARGS.repeat)
        out.append(
            record(
                "eikonalfm",
                f"poincare2d-{n}-fmm-o{order}",
                "eikonalfm.factored_fast_marching",
                order,
                s,
                u,
                exact,
            )
        )
    return out


def print_table(rows):
    print(
        f"{'tool':<11} {'case':<28} {'method':<34} {'cells':>10} {'best_s':>9} "
        f"{'ns/cell':>8} {'max_err':>9} {'mean_err':>9} {'B/cell':>7}"
    )
    for r in rows:
        if "error" in r:
            print(f"{r['tool']:<11} {r['case']:<28} error: {r['error']}")
            continue

        def e(k):
            return "-" if r.get(k) is None else f"{r[k]:.2e}"

        b = r.get("peak_bytes_per_cell")
        print(
            f"{r['tool']:<11} {r['case']:<28} {r['method']:<34} {r['cells']:>10} "
            f"{r['seconds']:>9.4f} {r['ns_per_cell']:>8.1f} {e('max_error'):>9} "
            f"{e('mean_error'):>9} {'-' if b is None else f'{b:.1f}':>7}"
        )


def render(paths):
    """Prints the JSON lines of several files as one table, sorted by case."""
    rows = []
    for path in paths:
        with open(path) as f:
            rows += [json.loads(line) for line in f if line.startswith("{")]
    rows.sort(key=lambda r: (r["case"], r["tool"]))
    print_table(rows)


def main():
    if ARGS.render:
        render(ARGS.render)
        return
    rows = []
    if np is None:
        sys.exit("compare_python: numpy is missing (see the module docstring)")
    try:
        import skfmm
    except ImportError:
        sys.exit("compare_python: scikit-fmm is missing (see the module docstring)")
    try:
        import eikonalfm
    except ImportError:
        sys.exit("compare_python: eikonalfm is missing (see the module docstring)")
    n2, n3, np2 = (256, 48, 256) if ARGS.quick else (2048, 256, 1024)
    for name, batch in (
        ("point2d", lambda: point_cases(skfmm, n2, 2)),
        ("point3d", lambda: point_cases(skfmm, n3, 3)),
        ("poincare2d", lambda: poincare_cases(eikonalfm, np2)),
    ):
        if ARGS.only and name not in ARGS.only:
            continue
        for row in batch():
            rows.append(row)
            if not ARGS.table:
                print(json.dumps(row), flush=True)
    if ARGS.table:
        print_table(rows)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="best of this many runs")
    parser.add_argument("--quick", action="store_true", help="small grids only")
    parser.add_argument(
        "--only",
        action="append",
        choices=["point2d", "point3d", "poincare2d"],
        help="run only this family of cases (repeatable; all by default)",
    )
    parser.add_argument("--table", action="store_true", help="a table instead of JSON lines")
    parser.add_argument("--json", action="store_true", help="JSON lines (the default)")
    parser.add_argument(
        "--render", nargs="+", metavar="JSONL", help="print JSON-lines files as one table and exit"
    )
    ARGS = parser.parse_args()
    main()
