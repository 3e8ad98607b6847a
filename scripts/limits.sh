#!/usr/bin/env bash
# Which of the robot's limits stops the closed-loop walk (docs/walk.md,
# "Limits met"): Optim.1's body of experiment 2 with the step length swept,
# under the league's limits and with one limit moved at a time
# (`naofarm trial --limit`, hidden; farm trials always use the league's).
# Prints s and mx over 20 trials, seed 3, per step length.
#   scripts/limits.sh [NAOFARM_BINARY]   (default target/release/naofarm)
set -euo pipefail
bin=${1:-target/release/naofarm}
body=(--param ThighRelHip2_Z=-0.0671 --param ratio_flexion=0.7376
      --param long_offset_MidAnkles_2_Torso_Init=0.0071 --param height_lift=0.0598)
row() {
  local label=$1; shift
  printf '%-34s' "$label"
  for step in 0.09 0.10 0.11 0.12 0.13; do
    "$bin" trial --walk closed-loop --trials 20 --seed 3 "${body[@]}" \
      --param xlength_step_max=$step "$@" --json |
      python3 -c 'import json,sys; d=json.load(sys.stdin); mx=d["mx"]; print(" %.2f %s" % (d["s"], "%.2f" % mx if mx is not None else "  -  "), end="")'
  done
  echo
}
echo "limits                             step 0.09 m  0.10 m     0.11 m     0.12 m     0.13 m (s, mx m)"
row "league (6.14 rad/s, 10 N·m)"
row "torque 20 N·m" --limit max_torque_nm=20
row "contact spring 1000 Hz" --limit contact_hz=1000
row "speed cap x1.25" --limit speed_cap_scale=1.25
row "speed cap x1.5" --limit speed_cap_scale=1.5
row "speed cap x1.25, 15 N·m" --limit speed_cap_scale=1.25 --limit max_torque_nm=15
row "speed cap x1.5, 20 N·m" --limit speed_cap_scale=1.5 --limit max_torque_nm=20
row "pitch joints x1.5, 15 N·m" --limit speed_cap_scale=1.5 --limit max_torque_nm=15 \
  --limit speed_cap_joints=le3,le4,le5
row "8 x 2.5 ms steps" --substeps 8
