#!/usr/bin/env bash
# End-to-end latency of an extra minimal path through HTTP (issue 4's target:
# at most 5 ms per new end point on a 1024² image once the map is cached).
#
# Starts the release binary on a free port with one pool thread, uploads a
# smooth 1024² cost (NPY written by numpy), asks for one path with the full
# map (`early_stop: false`, fills the cache), then N paths to random end
# points, each a fresh `curl` (new TCP connection, the whole JSON answer
# downloaded). Prints min / median / p90 / max of curl's time_total.
#
#   cargo build --release --bin geodex
#   PYTHON=/tmp/geodex-bench/bin/python tests/bench/paths_http.sh [N]
set -euo pipefail
N=${1:-100}
PYTHON=${PYTHON:-python3}
BIN=${BIN:-target/release/geodex}
PORT=${PORT:-18181}
WORK=$(mktemp -d)
trap 'kill $SERVER 2>/dev/null || true; rm -rf "$WORK"' EXIT
"$PYTHON" - "$WORK/cost.npy" <<'PY'
import sys, numpy as np
n = 1024
i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
np.save(sys.argv[1], 1.0 + 0.5 * np.sin(i / 37.0) * np.cos(j / 23.0))
PY
"$BIN" serve --addr 127.0.0.1:$PORT --data-dir "$WORK/data" --pool-threads 1 >"$WORK/serve.log" 2>&1 &
SERVER=$!
for _ in $(seq 50); do curl -sf http://127.0.0.1:$PORT/healthz >/dev/null && break; sleep 0.1; done
ID=$(curl -sf -X POST -H 'content-type: application/x-npy' --data-binary @"$WORK/cost.npy" \
  http://127.0.0.1:$PORT/v1/datasets | sed 's/.*"id":"\([^"]*\)".*/\1/')
body() { printf '{"cost":{"dataset":"%s"},"sources":[{"point":[51.2,51.2]}],"ends":[[%s,%s]],"early_stop":%s}' "$ID" "$1" "$2" "$3"; }
post() { curl -s -o "$WORK/out.json" -w '%{time_total}\n' -X POST -H 'content-type: application/json' \
  --data "$(body "$1" "$2" "$3")" http://127.0.0.1:$PORT/v1/grid/paths; }
echo "first request (full map + path): $(post 1023 1023 false) s"
RANDOM=7
for _ in $(seq "$N"); do post $((RANDOM % 1000 + 12)) $((RANDOM % 1000 + 12)) true; done | sort -n |
  awk '{t[NR] = $1 * 1000} END {printf "extra path, %d requests: min %.2f ms, median %.2f ms, p90 %.2f ms, max %.2f ms\n", NR, t[1], t[int(NR / 2) + 1], t[int(NR * 0.9)], t[NR]}'
grep -o '"cached":[a-z]*' "$WORK/out.json" | head -1
uptime
