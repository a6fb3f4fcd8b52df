"""geodex's Isomap against scikit-learn's on the same point cloud, in one run.

    cargo bench --bench shape_analysis --no-run            # builds target/release/deps/shape_analysis-*
    BIN=$(ls -t $CARGO_TARGET_DIR/release/deps/shape_analysis-* | grep -v '\\.d$' | head -1)
    $BIN roll 10000 7 /tmp/roll.npy /tmp/roll_flat.npy
    python tests/bench/compare_isomap.py $BIN /tmp/roll.npy /tmp/roll_flat.npy 10 500

Both embed the same cloud with the same k into 2D. Quality: the residual
variance 1 - r^2 between the embedding's distances and the true unrolled
rectangle's, over the same 2,000,000 random pairs for both tools (and each
tool's own figure where it has one). Time: wall clock of the whole fit
(neighbours, shortest paths, eigenproblem). scikit-learn is a peer, not a
dependency.
"""
import json
import subprocess
import sys
import time

import numpy as np
from sklearn.manifold import Isomap


def residual(Y, flat, pairs):
    i, j = pairs
    e = np.linalg.norm(Y[i] - Y[j], axis=1)
    g = np.linalg.norm(flat[i] - flat[j], axis=1)
    r = np.corrcoef(e, g)[0, 1]
    return float(1.0 - r * r)


def main(binary, cloud, flat_path, k, landmarks):
    X = np.load(cloud)
    flat = np.load(flat_path)
    n = len(X)
    rng = np.random.default_rng(0)
    pairs = (rng.integers(0, n, 2_000_000), rng.integers(0, n, 2_000_000))

    out = "/tmp/geodex_isomap_embedding.npy"
    t = time.perf_counter()
    line = subprocess.run([binary, "isomap", cloud, str(k), str(landmarks), out],
                          check=True, capture_output=True, text=True).stdout.strip()
    wall = time.perf_counter() - t
    g = json.loads(line)
    g["wall_s_with_process"] = round(wall, 3)
    g["residual_variance_vs_truth"] = residual(np.load(out), flat, pairs)
    print(json.dumps(g))

    for solver in ["auto"]:
        t = time.perf_counter()
        iso = Isomap(n_neighbors=k, n_components=2, eigen_solver=solver)
        Y = iso.fit_transform(X)
        secs = time.perf_counter() - t
        print(json.dumps({"tool": "scikit-learn", "case": "isomap", "points": n, "k": k,
                          "eigen_solver": solver, "seconds": round(secs, 3),
                          "residual_variance_vs_truth": residual(Y, flat, pairs)}))
    print(json.dumps({"speedup": round(secs / g["seconds"], 2)}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]))
