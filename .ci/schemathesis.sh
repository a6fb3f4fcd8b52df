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
# shellcheck source=tests/support/serve.sh
source tests/support/serve.sh
work="$(mktemp -d)"
serve_geodex ./target/debug/geodex "$work" --max-cells 262144 --request-timeout-secs 10
port="$GEODEX_PORT"

status=0
"$venv/bin/schemathesis" run "http://127.0.0.1:$port/openapi.json" \
  --checks not_a_server_error,response_schema_conformance,status_code_conformance,content_type_conformance \
  --max-examples 30 --workers 2 --suppress-health-check all --warnings off \
  || status=$?
if [ "$status" -ne 0 ]; then
  echo "--- server log (tail)"; tail -n 50 "$work/server.log"
fi
exit "$status"
