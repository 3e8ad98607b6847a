#!/usr/bin/env python3
"""Does an experiment's walk lean on its balance feedback? (docs/walk.md,
"Is the feedback load-bearing on the band?")

For the file's expert set and L's corners and centre (every searched
parameter at its lower or upper bound, others as the corner has them),
runs `naofarm trial` with the file's engine and again with
`--engine feedback=off` (no sensor reaches a joint), TRIALS trials from
seed 777 each, and prints s and mx of both per set, then a summary: sets
that fall more without the feedback, sets that walk more than 0.15 m
shorter or longer without it, and the mean difference.

    scripts/feedback.py EXPERIMENT.toml [TRIALS] [NAOFARM_BINARY]

Defaults: 5 trials, target/release/naofarm. About 6 min on 2 cores for a
six-parameter file at 5 trials (65 sets, twice).
"""

import json
import statistics
import subprocess
import sys

from stops import bounds, corners_and_centre


def trial(binary, path, trials, params, extra):
    args = [binary, "trial", "--experiment", path, "--trials", str(trials),
            "--seed", "777", "--json"]
    for name, value in params.items():
        args += ["--param", f"{name}={value!r}"]
    out = subprocess.run(args + extra, check=True, capture_output=True,
                         text=True).stdout
    d = json.loads(out)
    return d["s"], d["mx"], d["planned_m"]


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    path = sys.argv[1]
    trials = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    binary = sys.argv[3] if len(sys.argv) > 3 else "target/release/naofarm"
    sets = [("expert", {})] + corners_and_centre(bounds(path))
    print(f"{'set':<16} {'planned':>8}  {'s':>4} {'mx':>7}  "
          f"{'s off':>5} {'mx off':>7}")
    diffs, falls_more, shorter, longer = [], [], [], []
    for label, values in sets:
        s_on, mx_on, planned = trial(binary, path, trials, values, [])
        s_off, mx_off, _ = trial(binary, path, trials, values,
                                 ["--engine", "feedback=off"])
        fmt = lambda mx: "   -   " if mx is None else f"{mx:7.3f}"
        print(f"{label:<16} {planned:8.3f}  {s_on:4.2f} {fmt(mx_on)}  "
              f"{s_off:5.2f} {fmt(mx_off)}")
        if s_off < s_on:
            falls_more.append(label)
        if mx_on is not None and mx_off is not None:
            d = mx_off - mx_on
            diffs.append(d)
            if d < -0.15:
                shorter.append(label)
            elif d > 0.15:
                longer.append(label)
    print(f"\n{len(sets)} sets, {trials} trials each")
    print(f"fall more without the feedback: {len(falls_more)} {falls_more}")
    print(f"walk > 0.15 m shorter without it: {len(shorter)}")
    print(f"walk > 0.15 m further without it: {len(longer)}")
    if diffs:
        print(f"mean mx without minus with: {statistics.mean(diffs):+.3f} m")


if __name__ == "__main__":
    main()
