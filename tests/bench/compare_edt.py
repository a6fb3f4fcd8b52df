#!/usr/bin/env python3
"""Exact EDT: geodex against the `edt` package and scipy on the same masks.

    python3 -m venv /tmp/edtvenv && /tmp/edtvenv/bin/pip install edt scipy numpy
    cargo build --release --bin geodex
    /tmp/edtvenv/bin/python tests/bench/compare_edt.py [--sizes 512x512,4096x4096,256x256x256,512x512x512]

Masks: uniform random cells with probability 1 % (the features), seed 0.
geodex computes the distance of every cell to the nearest feature cell (f64);
`edt` and scipy compute the distance of non-zero cells to the nearest zero
cell, so they get `mask == 0`, the same problem. Multi-label: 16 labels in
random boxes on a background of label 0 (geodex `--multilabel`; scipy has
none). `edt.edt(labels)` takes label 0 as background: it writes 0 there and
computes nothing for those cells (70 % of the cells at 256³), while geodex
computes the distance to the nearest other label for every cell, label 0
included. So `edt` gets `labels + 1` (no background), the same problem, and
its output is checked against geodex's (max abs difference, f32); the time of
`edt.edt(labels)` (the easier problem) is printed as `edt-bg`.
The geodex figure is the transform alone (`transform X s`, no file IO), the
best of `--repeat` runs, like the Python ones; geodex and edt run
alternately on each input so that both see the same load (the last column
is the 1-minute load average after the row). Results are compared with
scipy (max abs difference) as a check.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

try:
    import edt as edt_pkg
except ImportError:  # pragma: no cover
    edt_pkg = None
from scipy import ndimage

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GEODEX = os.environ.get("GEODEX_BIN", os.path.join(ROOT, "target", "release", "geodex"))


def best(f, repeat):
    t = []
    out = None
    for _ in range(repeat):
        s = time.perf_counter()
        out = f()
        t.append(time.perf_counter() - s)
    return min(t), out


def labels_image(shape, rng):
    lab = np.zeros(shape, dtype=np.uint32)
    for k in range(1, 17):
        lo = [rng.integers(0, n // 2) for n in shape]
        hi = [l + rng.integers(n // 8, n // 2) for l, n in zip(lo, shape)]
        lab[tuple(slice(a, b) for a, b in zip(lo, hi))] = k
    return lab


def geodex_once(mask_path, out_path, threads, extra=()):
    r = subprocess.run(
        [GEODEX, "edt", "--mask", mask_path, "--out", out_path, "--threads", str(threads), *extra],
        capture_output=True, text=True, check=True,
    )
    return float(re.search(r"transform ([0-9.]+) s", r.stdout).group(1))


def interleaved(mask_path, out_path, threads, repeat, arr, extra=()):
    """geodex and edt alternately on the same input, best of `repeat` each, so
    that both see the same load."""
    g, e = [], []
    for _ in range(repeat):
        g.append(geodex_once(mask_path, out_path, threads, extra))
        if edt_pkg is not None:
            s = time.perf_counter()
            edt_pkg.edt(arr, parallel=threads)
            e.append(time.perf_counter() - s)
    return min(g), (min(e) if e else None)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="512x512,4096x4096,256x256x256,512x512x512")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--no-scipy-above", type=int, default=80_000_000,
                    help="skip scipy above this many cells (it is slow)")
    args = ap.parse_args()
    threads = [int(t) for t in args.threads.split(",")]
    rng = np.random.default_rng(0)
    tmp = tempfile.mkdtemp(prefix="edtbench")
    rows = []
    load0 = os.getloadavg()[0]
    for size in args.sizes.split(","):
        shape = tuple(int(s) for s in size.split("x"))
        mask = rng.random(shape) < 0.01
        mpath = os.path.join(tmp, "m.npy")
        dpath = os.path.join(tmp, "d.npy")
        np.save(mpath, mask)
        inv = (~mask).astype(np.uint8)
        scipy_s = None
        for t in threads:
            g, e = interleaved(mpath, dpath, t, args.repeat, inv)
            if t == 1 and mask.size <= args.no_scipy_above:
                scipy_s, ref = best(lambda: ndimage.distance_transform_edt(inv), max(1, args.repeat - 1))
                ours = np.load(dpath)
                diff = float(np.max(np.abs(ours - ref)))
                print(f"{size}: max |geodex - scipy| = {diff:.3e}", file=sys.stderr)
                assert diff < 1e-9
                del ours, ref
            rows.append((size, "binary", t, g, e, scipy_s if t == 1 else None, os.getloadavg()[0]))
        lab = labels_image(shape, rng)
        lpath = os.path.join(tmp, "l.npy")
        np.save(lpath, lab)
        lab1 = lab + 1
        for t in threads:
            g, e = interleaved(lpath, dpath, t, args.repeat, lab1, extra=("--multilabel",))
            if edt_pkg is not None and t == 1:
                diff = float(np.max(np.abs(np.load(dpath) - edt_pkg.edt(lab1, parallel=1))))
                print(f"{size}: multi-label max |geodex - edt(labels + 1)| = {diff:.3e}", file=sys.stderr)
                assert diff < 1e-3
            bg = None
            if edt_pkg is not None:
                bg, _ = best(lambda: edt_pkg.edt(lab, parallel=t), args.repeat)
            print(f"{size}: multi-label {t} thread(s): edt-bg {bg}", file=sys.stderr)
            rows.append((size, "multi-label", t, g, e, None, os.getloadavg()[0]))
    fmt = lambda v: "" if v is None else "%.3f" % v
    print("load average (1 min) at start: %.2f" % load0)
    print("| grid | form | threads | geodex | edt | scipy | edt / geodex | load |")
    print("|---|---|---|---|---|---|---|---|")
    for size, form, t, g, e, sc, load in rows:
        ratio = "" if e is None else "%.2f" % (e / g)
        print("| %s | %s | %d | %s | %s | %s | %s | %.1f |" % (size, form, t, fmt(g), fmt(e), fmt(sc), ratio, load))


if __name__ == "__main__":
    main()
