#!/usr/bin/env python3
"""The exact method on mesh files, end to end, side by side with pygeodesic.

geodex runs through its CLI (`geodex mesh-distance --method exact`: process
start, read, topology, solve, write an NPY), one process per run;
pygeodesic (MMP, single-threaded) is timed in memory (its algorithm object
built from the arrays, then `geodesicDistances` from vertex 0), in a child
process so that a crash of the peer (it segfaults on some scans) is a
result rather than the end of the run. Runs alternate between the tools,
best of `--repeat`. Several geodex binaries (comma-separated `--bin`) run
side by side, e.g. the commit before a change and after it.

    python3 -m venv /tmp/venv-mesh
    /tmp/venv-mesh/bin/pip install numpy potpourri3d pygeodesic pymeshlab
    sh tests/bench/mesh_fetch_scanned.sh /tmp/scanned
    /tmp/venv-mesh/bin/python tests/bench/compare_robust_heat.py --slivers 6 /tmp/slivers6.obj
    /tmp/venv-mesh/bin/python tests/bench/compare_exact_files.py --decimate /tmp/scanned/dragon.ply 100000 /tmp/dragon50k.obj
    /tmp/venv-mesh/bin/python tests/bench/compare_exact_files.py --bin target/release/geodex \\
        /tmp/slivers6.obj /tmp/dragon50k.obj /tmp/scanned/bunny.obj

`--decimate IN FACES OUT` writes IN decimated to FACES faces by MeshLab's
quadric edge collapse (pymeshlab, topology preserved): a 50k-vertex scan
from the 437k-vertex dragon. One JSON line per mesh and tool; the geodex
lines carry the largest relative difference to pygeodesic's map where
pygeodesic finished.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def geodex_run(binary, mesh, out):
    t = time.perf_counter()
    r = subprocess.run([binary, "mesh-distance", "--mesh", mesh, "--method", "exact",
                        "--source-vertex", "0", "--out", out], capture_output=True, text=True)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(r.stderr)
    return wall


PEER = r"""
import sys, time, numpy as np, potpourri3d as pp3d, pygeodesic.geodesic as geodesic
V, F = pp3d.read_mesh(sys.argv[1])
t = time.perf_counter()
alg = geodesic.PyGeodesicAlgorithmExact(V, F)
d, _ = alg.geodesicDistances(np.array([0]), None)
s = time.perf_counter() - t
np.save(sys.argv[2], d)
print(s)
"""


def peer_run(mesh, out, timeout):
    try:
        r = subprocess.run([sys.executable, "-c", PEER, mesh, out], capture_output=True, text=True,
                           timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout} s"
    if r.returncode != 0:
        return None, f"exit status {r.returncode} {r.stderr.strip()[-200:]}"
    return float(r.stdout.strip().splitlines()[-1]), None


def decimate(src, faces, dst):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(src)
    ms.meshing_remove_unreferenced_vertices()
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=faces, preservetopology=True)
    ms.save_current_mesh(dst, save_vertex_color=False, save_vertex_normal=False)
    m = ms.current_mesh()
    print(json.dumps({"decimated": dst, "vertices": m.vertex_number(), "faces": m.face_number()}))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/geodex")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--peer-timeout", type=float, default=600)
    ap.add_argument("--decimate", nargs=3, metavar=("IN", "FACES", "OUT"))
    ap.add_argument("meshes", nargs="*")
    a = ap.parse_args()
    if a.decimate:
        decimate(a.decimate[0], int(a.decimate[1]), a.decimate[2])
        return
    bins = a.bin.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        for mesh in a.meshes:
            name = os.path.basename(mesh)
            best = {b: float("inf") for b in bins}
            peer_best, peer_error = float("inf"), None
            for _ in range(a.repeat):
                for i, b in enumerate(bins):
                    best[b] = min(best[b], geodex_run(b, mesh, os.path.join(tmp, f"g{i}.npy")))
                if peer_error is None:
                    s, peer_error = peer_run(mesh, os.path.join(tmp, "p.npy"), a.peer_timeout)
                    if s is not None:
                        peer_best = min(peer_best, s)
            ref = np.load(os.path.join(tmp, "p.npy")) if peer_error is None else None
            peer = {"mesh": name, "tool": "pygeodesic"}
            if peer_error is None:
                peer["in_memory_s"] = round(peer_best, 3)
            else:
                peer["failed"] = peer_error
            print(json.dumps(peer), flush=True)
            for i, b in enumerate(bins):
                d = np.load(os.path.join(tmp, f"g{i}.npy"))
                row = {"mesh": name, "vertices": len(d), "tool": "geodex", "bin": b,
                       "end_to_end_s": round(best[b], 3)}
                if ref is not None and len(ref) == len(d):
                    m = np.isfinite(ref) & (ref > 0)
                    row["max_rel_diff_to_pygeodesic"] = float(np.max(np.abs(d[m] - ref[m]) / ref[m]))
                    row["speedup"] = round(peer_best / best[b], 2)
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())
