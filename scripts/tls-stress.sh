#!/usr/bin/env bash
# Whether a router over mutual TLS lives through workers killed mid-run: a
# router on 127.0.0.1, a synthetic run of many iterations as its client, and
# six workers, one of them killed (SIGKILL: its links reset while the router
# writes to it) and replaced every 0.3 s, for SECONDS (default 60). Prints
# whether the router is alive, after how many kills, and the run's decided
# iterations. zenoh's own TLS link (eclipse-zenoh/zenoh#2557) lost the router
# after 5-41 kills; with vendor/zenoh-link-tls it lives (docs/fleet.md, Trust).
# Re-run it before dropping the patch for a zenoh release.
#   scripts/tls-stress.sh NAOFARM_BINARY [SECONDS]
set -euo pipefail
bin=$(realpath "$1")
secs=${2:-60}
root=$(cd "$(dirname "$0")/.." && pwd)
tmp=$(mktemp -d /tmp/naofarm-tls-stress.XXXX)
trap 'kill -9 $(jobs -p) 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$tmp"' EXIT
cd "$tmp"
"$bin" certs pki >/dev/null 2>&1
sed 's/^iterations = 60$/iterations = 100000/' "$root/experiments/synthetic.toml" >s.toml
"$bin" router --listen tls/127.0.0.1:0 --tls pki >router.out 2>router.err &
router=$!
ep=""
for _ in $(seq 100); do
  ep=$(grep -ho "tls/127.0.0.1:[0-9]*" router.out router.err 2>/dev/null | head -1 || true)
  [ -n "$ep" ] && break
  sleep 0.1
done
[ -n "$ep" ] || { echo "the router never listened" >&2; exit 1; }
"$bin" coordinator --connect "$ep" --tls pki s.toml --out run >/dev/null 2>coordinator.err &
worker() { "$bin" worker --connect "$ep" --tls pki --slots 2 >/dev/null 2>>workers.err & echo $!; }
ws=()
for i in 0 1 2 3 4 5; do ws[i]=$(worker); done
kills=0
end=$((SECONDS + secs))
while [ $SECONDS -lt $end ] && kill -0 "$router" 2>/dev/null; do
  sleep 0.3
  k=$((RANDOM % 6))
  kill -9 "${ws[k]}" 2>/dev/null || true
  kills=$((kills + 1))
  ws[k]=$(worker)
done
decided=$("$bin" history run 2>/dev/null | grep -c "^[0-9]" || true)
if kill -0 "$router" 2>/dev/null; then
  echo "router alive after $kills kills in $secs s; the run decided $decided iterations"
else
  echo "router DEAD after $kills kills; the run decided $decided iterations; its stderr:"
  grep -v "^  " router.err | head -5
  exit 1
fi
