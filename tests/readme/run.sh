#!/usr/bin/env bash
# The README's examples, run as written (issue 21).
#
#   tests/readme/run.sh                                  # builds target/debug/geodex
#   GEODEX_BIN=target/release/geodex tests/readme/run.sh
#
# Starts the geodex binary on a free loopback port with a fresh data directory,
# writes the input files the README names (road.png, phi.npy, mask.npy,
# shaded.png, bunny.ply, ...: tests/readme/make_inputs.py) into a scratch
# directory, and runs every ```sh block of README.md, in order, there. The only
# change made to a block is the server's address: http://127.0.0.1:8080 and
# localhost:8080 become the test's port. Each block runs on its own, in a fresh
# `bash -euo pipefail` (blocks are self-contained: a block that needs a dataset
# id uploads its input itself), with
#   - `curl` a shell function that adds --fail-with-body --show-error: any 4xx
#     or 5xx fails the block, and the problem+json it got is printed;
#   - `geodex` on PATH: the binary under test, for the command-line examples.
# It prints one line per block (`ok  README.md:LINE  <first command>`, or FAIL
# followed by the block's output and a README line of the command that failed),
# then `N passed, M failed`, and exits non-zero when a block failed.
# GEODEX_README_VERBOSE=1 also prints what every block printed (to compare with
# the README's `# ->` comments). About 10 s with a debug build.
#
# Blocks fenced as ```sh no-run are listed as skipped and not run. That is
# allowed only for what cannot run here: building or testing the project itself
# (cargo run, cargo test, cargo build), starting a long-lived server (geodex
# serve, which needs the port or a PostgreSQL database) and the full benchmark
# (geodex bench: minutes), and generating clients (the generators come from
# PyPI and npm; .ci/clients.sh runs those same commands). Everything else runs.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT="$(pwd)"

# The examples use curl and jq (installed from apt when missing, as
# tests/browser/run.sh does for chromium); the inputs are made by python3.
if ! command -v jq >/dev/null 2>&1; then
  echo "== installing jq (apt)"
  SUDO=""
  [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q jq
fi
for tool in curl jq python3 timeout; do
  command -v "$tool" >/dev/null 2>&1 || { echo "tests/readme/run.sh needs $tool" >&2; exit 1; }
done

BIN="${GEODEX_BIN:-}"
if [ -z "$BIN" ]; then
  cargo build --locked --quiet --bin geodex
  BIN="${CARGO_TARGET_DIR:-target}/debug/geodex"
fi
BIN="$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")"
[ -x "$BIN" ] || { echo "no geodex binary at $BIN" >&2; exit 1; }

WORK="$(mktemp -d)"
mkdir -p "$WORK/run" "$WORK/bin" "$WORK/blocks"
# shellcheck source=tests/support/serve.sh
source "$ROOT/tests/support/serve.sh"
serve_geodex "$BIN" "$WORK"
PORT="$GEODEX_PORT"

ln -s "$BIN" "$WORK/bin/geodex"
(cd "$WORK/run" && python3 "$ROOT/tests/readme/make_inputs.py")

# What every block runs with (read through BASH_ENV, so that the block's own
# line numbers are those of the file, and README.md:LINE can be named).
cat >"$WORK/prelude.sh" <<'EOF'
curl() {
  local out="" prev="" a rc=0 body
  for a in "$@"; do
    if [ "$prev" = -o ] || [ "$prev" = --output ]; then out="$a"; fi
    prev="$a"
  done
  body="$(mktemp)"
  command curl --fail-with-body --show-error "$@" >"$body" || rc=$?
  if [ "$rc" -eq 0 ]; then
    cat "$body"
  else
    # The answer (problem+json) goes to stderr, wherever the example sent it.
    echo "curl exited $rc; the answer:" >&2
    if [ -n "$out" ] && [ -f "$out" ]; then cat "$out" >&2; fi
    cat "$body" >&2
    echo >&2
  fi
  rm -f "$body"
  return "$rc"
}
trap 'echo "failed near README.md:$((README_FENCE + LINENO)) (bash names a line of the failing command)" >&2' ERR
EOF

# Split README.md into its ```sh blocks: blocks/NNN.sh, and a table
# "NNN fence-line run|no-run".
awk -v dir="$WORK/blocks" '
  /^```/ && inside { inside = 0; close(file); next }
  /^```sh([ \t]|$)/ && !inside && !other {
    inside = 1; n++; file = sprintf("%s/%03d.sh", dir, n)
    mode = ($0 ~ /no-run/) ? "no-run" : "run"
    printf "%03d %d %s\n", n, NR, mode > (dir "/index")
    printf "" > file
    next
  }
  /^```/ { other = !other; next }
  inside { print > file }
' README.md

passed=0
failed=0
while read -r n fence mode; do
  block="$WORK/blocks/$n.sh"
  first="$(grep -v -E '^[[:space:]]*(#|$)' "$block" | head -n 1 | cut -c1-100)"
  if [ "$mode" = no-run ]; then
    echo "skip README.md:$fence  $first  (no-run)"
    continue
  fi
  sed -i -e "s#http://127\.0\.0\.1:8080#http://127.0.0.1:$PORT#g" -e "s#localhost:8080#localhost:$PORT#g" "$block"
  if (cd "$WORK/run" && PATH="$WORK/bin:$PATH" BASH_ENV="$WORK/prelude.sh" README_FENCE="$fence" \
      timeout 120 bash -euo pipefail "$block") >"$WORK/blocks/$n.log" 2>&1; then
    echo "ok  README.md:$fence  $first"
    if [ -n "${GEODEX_README_VERBOSE:-}" ]; then sed 's/^/    /' "$WORK/blocks/$n.log"; fi
    passed=$((passed + 1))
  else
    echo "FAIL README.md:$fence  $first"
    sed 's/^/    /' "$WORK/blocks/$n.log" | tail -n 40
    failed=$((failed + 1))
  fi
done <"$WORK/blocks/index"

if [ "$failed" -gt 0 ]; then
  echo "---- server log (tail)"
  tail -n 20 "$WORK/server.log"
fi
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
