#!/usr/bin/env python3
"""How a walk's distance moves with the physics step (docs/walk.md, "Where the
walks part with the time step").

Runs one parameter set with `naofarm trial --json` at each count of physics
steps per 20 ms cycle given, everything else as the experiment file has it,
and prints a Markdown table: per step s, mx, the trials' spread of x (sd),
mx over the walk's plan, plants per trial and the torso's mean pitch
(negative: leaning back), then the range of mx over the steps.

    scripts/timestep.py --experiment experiments/physical-technical-arms-5ms.toml \\
        --param ThighRelHip2_Z=-0.0795 --param xlength_step_max=0.1041
    scripts/timestep.py --experiment experiments/physical-technical.toml \\
        --substeps 2 4 10 20 --trials 50 -- --param ankle_pitch_gain=0

Arguments after `--` go to every `naofarm trial` as they are.
"""
import argparse
import json
import statistics
import subprocess


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default="target/release/naofarm")
    ap.add_argument("--experiment", required=True)
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--substeps", type=int, nargs="+",
                    default=[3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 14, 16, 20, 24, 30])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("extra", nargs="*")
    a = ap.parse_args()
    print("| steps per cycle | step (ms) | s | mx (m) | sd of x (m) | × plan | plants | torso pitch |")
    print("|---|---|---|---|---|---|---|---|")
    mxs = []
    for k in a.substeps:
        cmd = [a.bin, "trial", "--experiment", a.experiment, "--json",
               "--trials", str(a.trials), "--seed", str(a.seed), "--substeps", str(k)]
        for p in a.param:
            cmd += ["--param", p]
        d = json.loads(subprocess.run(cmd + a.extra, check=True, capture_output=True,
                                      text=True).stdout)
        xs = [t["x"] for t in d["trials"] if not t["fell"]]
        sd = statistics.stdev(xs) if len(xs) > 1 else float("nan")
        w = d["footwork"] or {}
        plan = d["planned_m"]
        mxs.append(d["mx"])
        print(f"| {k} | {20 / k:.2f} | {d['s']:.2f} | {d['mx']:.3f} | {sd:.3f} | "
              f"{d['mx'] / plan:.2f} | {w.get('plants', '–')} | "
              f"{w.get('torso_pitch_deg', float('nan')):+.1f}° |")
    print(f"\nmx from {min(mxs):.3f} to {max(mxs):.3f} m over the steps "
          f"({a.trials} trials each from seed {a.seed}); the plan {plan:.3f} m")


if __name__ == "__main__":
    main()
