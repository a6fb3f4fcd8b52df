#!/usr/bin/env bash
# Contract fuzz run: starts the service (debug build from `cargo test`) on a
# free loopback port with small limits, and runs schemathesis against its
# OpenAPI document. Fails on any server error (5xx) or any response that
# violates the documented schema, status codes or content types.
set -euo pipefail
cd "$(dirname "$0")/.."

venv="${GEODEX_CI_VENV:-${TMPDIR:-/tmp}/geodex-ci-venv}"
if [ ! -x "$venv/bin/schemathesis" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check schemathesis==4.32.5
fi

cargo build --locked --quiet --bin geodex
data_dir="$(mktemp -d)"
port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
./target/debug/geodex serve --addr "127.0.0.1:$port" --data-dir "$data_dir" \
  --max-cells 262144 --request-timeout-secs 10 >"$data_dir/server.log" 2>&1 &
pid=$!
cleanup() { kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; rm -rf "$data_dir"; }
trap cleanup EXIT

for _ in $(seq 1 100); do
  curl -fsS "http://127.0.0.1:$port/healthz" >/dev/null 2>&1 && break
  sleep 0.1
done

status=0
"$venv/bin/schemathesis" run "http://127.0.0.1:$port/openapi.json" \
  --checks not_a_server_error,response_schema_conformance,status_code_conformance,content_type_conformance \
  --max-examples 30 --workers 2 --suppress-health-check all --warnings off \
  || status=$?
if [ "$status" -ne 0 ]; then
  echo "--- server log (tail)"; tail -n 50 "$data_dir/server.log"
fi
exit "$status"
