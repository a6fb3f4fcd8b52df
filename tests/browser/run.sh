#!/usr/bin/env bash
# Browser tests of the playground: a real headless Chromium (Debian's
# `chromium` + `chromium-driver`, driven by Selenium from a venv) against the
# real geodex binary. Installs what it needs itself.
#
#   tests/browser/run.sh                 # builds the debug binary
#   GEODEX_BIN=target/release/geodex tests/browser/run.sh
#
# Screenshots go to $GEODEX_SCREENSHOTS (default target/playground-screenshots).
set -euo pipefail
cd "$(dirname "$0")/../.."

if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
  echo "== installing chromium and chromium-driver (apt)"
  SUDO=""
  [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q chromium chromium-driver
fi

VENV="${GEODEX_BROWSER_VENV:-/tmp/geodex-browser-venv}"
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import selenium' 2>/dev/null; then
  echo "== venv with selenium at $VENV"
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q 'selenium==4.51.0'
fi

BIN="${GEODEX_BIN:-}"
if [ -z "$BIN" ]; then
  echo "== cargo build --bin geodex"
  cargo build --locked --bin geodex
  BIN="${CARGO_TARGET_DIR:-target}/debug/geodex"
fi

DATA="$(mktemp -d)"
PORT="${GEODEX_BROWSER_PORT:-$((20000 + RANDOM % 20000))}"
"$BIN" serve --addr "127.0.0.1:$PORT" --data-dir "$DATA" --job-workers 1 >"$DATA/server.log" 2>&1 &
SERVER=$!
cleanup() {
  kill "$SERVER" 2>/dev/null || true
  wait "$SERVER" 2>/dev/null || true
  rm -rf "$DATA"
}
trap cleanup EXIT
for _ in $(seq 1 100); do
  curl -sf "http://127.0.0.1:$PORT/healthz" >/dev/null && break
  sleep 0.1
done

export GEODEX_SCREENSHOTS="${GEODEX_SCREENSHOTS:-${CARGO_TARGET_DIR:-target}/playground-screenshots}"
mkdir -p "$GEODEX_SCREENSHOTS"
echo "== browser tests against $BIN on port $PORT"
if ! "$VENV/bin/python" tests/browser/test_playground.py "http://127.0.0.1:$PORT"; then
  echo "---- server log (tail)"
  tail -n 40 "$DATA/server.log"
  exit 1
fi
