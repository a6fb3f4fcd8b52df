#!/usr/bin/env python3
"""Exact EDT: geodex against the `edt` package and scipy on the same masks.

    python3 -m venv /tmp/edtvenv && /tmp/edtvenv/bin/pip install edt scipy numpy
    cargo build --release --bin geodex
    /tmp/edtvenv/bin/python tests/bench/compare_edt.py [--sizes 512x512,4096x4096,256x256x256,512x512x512]

Masks: uniform random cells with probability 1 % (the features), seed 0.
geodex computes the distance of every cell to the nearest feature cell (f64);
`edt` and scipy compute the distance of non-zero cells to the nearest zero
cell, so they get `mask == 0`, the same problem. Multi-label: 16 labels in
random boxes (geodex `--multilabel`, `edt.edt(labels)`; scipy has none).
The geodex figure is the transform alone (`transform X s`, no file IO), the
best of `--repeat` runs, like the Python ones. Results are compared with
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


def geodex(mask_path, out_path, threads, repeat, extra=()):
    times = []
    for _ in range(repeat):
        r = subprocess.run(
            [GEODEX, "edt", "--mask", mask_path, "--out", out_path, "--threads", str(threads), *extra],
            capture_output=True, text=True, check=True,
        )
        m = re.search(r"transform ([0-9.]+) s", r.stdout)
        times.append(float(m.group(1)))
    return min(times)


def labels_image(shape, rng):
    lab = np.zeros(shape, dtype=np.uint32)
    for k in range(1, 17):
        lo = [rng.integers(0, n // 2) for n in shape]
        hi = [l + rng.integers(n // 8, n // 2) for l, n in zip(lo, shape)]
        lab[tuple(slice(a, b) for a, b in zip(lo, hi))] = k
    return lab


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
    for size in args.sizes.split(","):
        shape = tuple(int(s) for s in size.split("x"))
        mask = rng.random(shape) < 0.01
        mpath = os.path.join(tmp, "m.npy")
        dpath = os.path.join(tmp, "d.npy")
        np.save(mpath, mask)
        inv = (~mask).astype(np.uint8)
        for t in threads:
            g = geodex(mpath, dpath, t, args.repeat)
            rows.append((size, "binary", t, "geodex", g))
            if edt_pkg is not None:
                e, _ = best(lambda: edt_pkg.edt(inv, parallel=t), args.repeat)
                rows.append((size, "binary", t, "edt", e))
        ours = np.load(dpath)
        if mask.size <= args.no_scipy_above:
            s, ref = best(lambda: ndimage.distance_transform_edt(inv), max(1, args.repeat - 1))
            rows.append((size, "binary", 1, "scipy", s))
            diff = float(np.max(np.abs(ours - ref)))
            print(f"{size}: max |geodex - scipy| = {diff:.3e}", file=sys.stderr)
            assert diff < 1e-9
        del ours
        lab = labels_image(shape, rng)
        lpath = os.path.join(tmp, "l.npy")
        np.save(lpath, lab)
        for t in threads:
            g = geodex(lpath, dpath, t, args.repeat, extra=("--multilabel",))
            rows.append((size, "multilabel", t, "geodex", g))
            if edt_pkg is not None:
                e, _ = best(lambda: edt_pkg.edt(lab, parallel=t), args.repeat)
                rows.append((size, "multilabel", t, "edt", e))
    print("| grid | form | threads | tool | seconds (best of %d) |" % args.repeat)
    print("|---|---|---|---|---|")
    for r in rows:
        print("| %s | %s | %d | %s | %.3f |" % r)


if __name__ == "__main__":
    main()
