#!/usr/bin/env bash
# Generated clients (issue 21): starts the service (debug build) on a free
# loopback port, generates a Python client from its /openapi.json with
# openapi-python-client and a TypeScript one with openapi-typescript, fails on
# any generator warning, type-checks the TypeScript with `tsc --strict`, and
# calls every operation through the Python client
# (tests/client/every_operation.py).
#
#   bash .ci/clients.sh            # the check
#   bash .ci/clients.sh --record   # also rewrites api/examples.json
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"

record=""
if [ "${1:-}" = "--record" ]; then
  record="--record $root/api/examples.json"
fi

venv="${GEODEX_CLIENT_VENV:-${TMPDIR:-/tmp}/geodex-client-venv}"
if [ ! -x "$venv/bin/openapi-python-client" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check \
    openapi-python-client==0.29.1 jsonschema==4.26.0
fi
node_dir="${GEODEX_CLIENT_NODE:-${TMPDIR:-/tmp}/geodex-client-node}"
if [ ! -x "$node_dir/node_modules/.bin/openapi-typescript" ]; then
  mkdir -p "$node_dir"
  (cd "$node_dir" && npm init -y >/dev/null \
    && npm install --silent --no-audit --no-fund openapi-typescript@7.13.0 typescript@5.9.3)
fi

cargo build --locked --quiet --bin geodex
# shellcheck source=tests/support/serve.sh
source tests/support/serve.sh
work="$(mktemp -d)"
serve_geodex ./target/debug/geodex "$work" --request-timeout-secs 120
port="$GEODEX_PORT"
curl -fsS "http://127.0.0.1:$port/openapi.json" -o "$work/openapi.json"

echo "-- openapi-python-client"
printf 'post_hooks: []\n' >"$work/client.yaml"
"$venv/bin/openapi-python-client" generate --path "$work/openapi.json" --meta none \
  --output-path "$work/py/geodex_client" --config "$work/client.yaml" 2>&1 | tee "$work/py.log"
if grep -qiE "warning|error|unable|skipp" "$work/py.log"; then
  echo "openapi-python-client warned: the document is not fully covered" >&2
  exit 1
fi

echo "-- openapi-typescript + tsc --strict"
"$node_dir/node_modules/.bin/openapi-typescript" "$work/openapi.json" -o "$work/api.ts" 2>&1 | tee "$work/ts.log"
if grep -qiE "warn|error" "$work/ts.log"; then
  echo "openapi-typescript warned" >&2
  exit 1
fi
"$node_dir/node_modules/.bin/tsc" --strict --noEmit --target es2020 "$work/api.ts"
python3 - "$work/openapi.json" "$work/api.ts" <<'EOF'
import json, sys
doc = json.load(open(sys.argv[1]))
ts = open(sys.argv[2]).read()
missing = [p for p in doc["paths"] if f'"{p}": {{' not in ts]
missing += [s for s in doc["components"]["schemas"] if f"        {s}: " not in ts and f'        "{s}": ' not in ts]
if missing:
    sys.exit(f"openapi-typescript left out: {missing}")
print(f"typescript: {len(doc['paths'])} paths and {len(doc['components']['schemas'])} schemas typed")
EOF

echo "-- every operation through the Python client"
status=0
# shellcheck disable=SC2086
"$venv/bin/python" tests/client/every_operation.py --url "http://127.0.0.1:$port" \
  --client "$work/py" $record || status=$?
if [ "$status" -ne 0 ]; then
  echo "--- server log (tail)"; tail -n 30 "$work/server.log"
fi
exit "$status"
