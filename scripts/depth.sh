#!/usr/bin/env bash
# Speed against quality (docs/results.md): experiment 2 at pipeline depths
# 1, 4 and 16 over seeds 1 and 2, each followed by its report's Table IV.
#   scripts/depth.sh [BIN] [OUT]
set -euo pipefail
bin=${1:-target/release/naofarm}
out=${2:-runs/depth}
mkdir -p "$out"
for seed in 1 2; do
  for depth in 1 4 16; do
    name="d${depth}-s${seed}"
    sed -e "s/^pipeline_depth = .*/pipeline_depth = ${depth}/" \
        -e "s/^seed = .*/seed = ${seed}/" \
        experiments/physical-technical.toml > "$out/$name.toml"
    start=$(date +%s)
    "$bin" run "$out/$name.toml" --out "$out/$name" > "$out/$name.log" 2>&1
    end=$(date +%s)
    "$bin" report "$out/$name" --trials 100 > "$out/$name.table" 2>&1
    echo "$name wall $((end - start)) s" | tee -a "$out/summary.txt"
  done
done
