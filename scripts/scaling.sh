#!/usr/bin/env bash
# One run alone on N worker processes of one slot, synthetic trials of a
# fixed 1 s, pipeline depth 4 × 10 trials (a window of 40 in flight): trials/s
# from the coordinator's start to its end (start-up and the last iteration's
# tail included). The coordinator listens itself (no router), so that builds
# from before `naofarm router` can be measured the same way.
#   scripts/scaling.sh NAOFARM_BINARY [WORKERS...]   (default 1 2 4 8 16)
set -euo pipefail
bin=$(realpath "$1"); shift
counts=("${@:-1 2 4 8 16}")
[ $# -eq 0 ] && counts=(1 2 4 8 16)
tmp=$(mktemp -d /dev/shm/naofarm-scaling.XXXX)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$tmp"' EXIT
echo "workers trials seconds trials_per_s"
for n in "${counts[@]}"; do
  iters=$((2 * n + 2))
  cat > "$tmp/exp.toml" <<TOML
name = "scaling"
seed = 1
iterations = $iters
trials_per_iteration = 10
pipeline_depth = 4
model = "synthetic"
start = "expert"

[[parameter]]
name = "ThighRelHip2_Z"
lower = -0.08
upper = -0.03
expert = -0.04

[[parameter]]
name = "xlength_step_max"
lower = 0.02
upper = 0.15
expert = 0.08

[clop]
n_mcmc = 100
TOML
  port=$((20000 + RANDOM % 20000))
  rm -rf "$tmp/run"
  for _ in $(seq 1 "$n"); do
    RUST_LOG=error "$bin" worker --connect "tcp/127.0.0.1:$port" --slots 1 --min-trial-ms 1000 \
      >/dev/null 2>&1 &
  done
  t0=$(date +%s.%N)
  RUST_LOG=error "$bin" coordinator "$tmp/exp.toml" --out "$tmp/run" \
    --listen "tcp/127.0.0.1:$port" --json >/dev/null 2>&1
  t1=$(date +%s.%N)
  kill $(jobs -p) 2>/dev/null || true
  wait 2>/dev/null || true
  python3 -c "n=$n; t=$iters*10; s=$t1-$t0; print(n, t, round(s,1), round(t/s,2))"
done
