# Sourced by the scripts that test a live geodex (.ci/schemathesis.sh,
# .ci/clients.sh, tests/readme/run.sh): one way to start it.
#
#   source tests/support/serve.sh
#   serve_geodex BIN WORKDIR [serve flags...]
#
# Starts `BIN serve` on a free loopback port with its data in WORKDIR/data and
# its log in WORKDIR/server.log, waits up to 20 s for /healthz, and sets
# GEODEX_PORT, GEODEX_URL and GEODEX_PID. On exit the server is stopped and
# WORKDIR removed (an EXIT trap).
serve_geodex() {
  local bin="$1" work="$2"
  shift 2
  mkdir -p "$work/data"
  GEODEX_PORT="$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
  GEODEX_URL="http://127.0.0.1:$GEODEX_PORT"
  "$bin" serve --addr "127.0.0.1:$GEODEX_PORT" --data-dir "$work/data" "$@" >"$work/server.log" 2>&1 &
  GEODEX_PID=$!
  # shellcheck disable=SC2064  # expand now: the trap must stop this server
  trap "kill $GEODEX_PID 2>/dev/null || true; wait $GEODEX_PID 2>/dev/null || true; rm -rf '$work'" EXIT
  for _ in $(seq 1 200); do
    curl -sf "$GEODEX_URL/healthz" >/dev/null 2>&1 && return 0
    if ! kill -0 "$GEODEX_PID" 2>/dev/null; then
      echo "geodex did not start:" >&2
      cat "$work/server.log" >&2
      return 1
    fi
    sleep 0.1
  done
  echo "geodex did not answer /healthz within 20 s" >&2
  return 1
}
