#!/usr/bin/env python3
"""The closed-loop walk's landscape over experiment 2's L (docs/walk.md).

Sweeps each parameter over its range (others at expert; mx and s per point)
and runs a random search of uniformly drawn sets, each point with
`naofarm trial --walk closed-loop --json`. Prints Markdown tables.
With `--experiment FILE`, L, the expert set, the fixed values, the walk and
the physics are that file's (`naofarm trial --experiment FILE`).

    scripts/landscape.py [--bin target/release/naofarm] [--sets 200] [--experiment FILE]
                         [--duration S]

`--duration` sets each trial's simulated seconds (default: the file's, or 10):
a walk that drifts and falls after its tenth second shows only in longer
trials (docs/walk.md, "How long the walks last").
"""
import argparse
import json
import random
import subprocess
import tomllib

L = [  # experiments/physical-technical.toml
    ("ThighRelHip2_Z", -0.08, -0.03, -0.040),
    ("ratio_flexion", 0.60, 0.95, 0.730),
    ("long_offset_MidAnkles_2_Torso_Init", 0.001, 0.030, 0.011),
    ("height_lift", 0.025, 0.070, 0.042),
    ("xlength_step_max", 0.020, 0.150, 0.080),
]


def f(v, fmt=".3f"):
    return "–" if v is None else format(v, fmt)


def parameter_space(experiment):
    """L as (name, lower, upper, expert): the file's, or experiment 2's."""
    if experiment is None:
        return L
    with open(experiment, "rb") as fh:
        exp = tomllib.load(fh)
    return [(p["name"], p["lower"], p["upper"], p["expert"]) for p in exp["parameter"]]


def trial(binary, params, trials, seed, experiment=None, duration=None):
    walk = ["--walk", "closed-loop"] if experiment is None else ["--experiment", experiment]
    cmd = [binary, "trial", *walk, "--json",
           "--trials", str(trials), "--seed", str(seed)]
    if duration is not None:
        cmd += ["--duration", str(duration)]
    for k, v in params.items():
        cmd += ["--param", f"{k}={v}"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def stop(r):
    """The trials' farthest excursion past a stop: degrees and joint."""
    w = r.get("worst_stop_excess")
    return "0" if not w else f"{w['deg']:.2f} {w['joint']}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/naofarm")
    ap.add_argument("--points", type=int, default=9)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--sets", type=int, default=200)
    ap.add_argument("--set-trials", type=int, default=10)
    ap.add_argument("--experiment", default=None)
    ap.add_argument("--no-sweeps", action="store_true")
    ap.add_argument("--duration", type=float, default=None)
    a = ap.parse_args()
    space = parameter_space(a.experiment)
    if a.experiment is not None:
        print(f"(L, expert set, walk and physics of `{a.experiment}`)\n")
    if a.duration is not None:
        print(f"(trials of {a.duration:g} s)\n")
    if not a.no_sweeps:
        print(f"## Sweeps ({a.trials} trials per point, seed 3; others at expert)\n")
    for name, lo, hi, _ in ([] if a.no_sweeps else space):
        print(f"### {name}\n\n| value | s | mx (m) | my (m) | planned (m) | past a stop (°) |"
              "\n|---|---|---|---|---|---|")
        for i in range(a.points):
            v = lo + (hi - lo) * i / (a.points - 1)
            r = trial(a.bin, {name: round(v, 5)}, a.trials, 3, a.experiment, a.duration)
            print(f"| {v:.4f} | {r['s']:.2f} | {f(r['mx'])} | {f(r['my'])} | "
                  f"{f(r['planned_m'])} | {stop(r)} |")
        print()
    rng = random.Random(1)
    rows = []
    for k in range(a.sets):
        p = {n: round(rng.uniform(lo, hi), 5) for n, lo, hi, _ in space}
        r = trial(a.bin, p, a.set_trials, 1000 + 100 * k, a.experiment, a.duration)
        rows.append((r["mx"] if r["s"] >= 0.9 else -1.0, r, p))
        r["mx"] = r["mx"] or 0.0
    ok = [x for x in rows if x[1]["s"] >= 0.9]
    mxs = sorted(x[1]["mx"] for x in rows)  # a set whose trials all fell counts 0
    print(f"## Random search ({a.sets} sets drawn uniformly from L, "
          f"{a.set_trials} trials each)\n")
    print(f"- sets with s ≥ 0.9: {len(ok)} of {len(rows)}")
    print(f"- mx over all sets: min {mxs[0]:.3f}, median {mxs[len(mxs)//2]:.3f}, "
          f"max {mxs[-1]:.3f} m")
    print("\nThe ten best sets with s ≥ 0.9:\n")
    print("| mx | s | my | planned | past a stop (°) | "
          + " | ".join(n for n, *_ in space) + " |")
    print("|---" * (5 + len(space)) + "|")
    for _, r, p in sorted(ok, key=lambda x: -x[0])[:10]:
        print(f"| {r['mx']:.3f} | {r['s']:.2f} | {f(r['my'])} | {f(r['planned_m'])} | "
              f"{stop(r)} | " + " | ".join(f"{p[n]:.4f}" for n, *_ in space) + " |")
    print(f"\nThe five sets farthest past a stop of the {len(rows)}:\n")
    print("| past a stop (°) | at (s) | mx | s | planned | "
          + " | ".join(n for n, *_ in space) + " |")
    print("|---" * (5 + len(space)) + "|")
    far = sorted(rows, key=lambda x: -((x[1].get("worst_stop_excess") or {}).get("deg", 0.0)))
    for _, r, p in far[:5]:
        w = r.get("worst_stop_excess") or {}
        fell = [t["fall_time_s"] for t in r["trials"] if t["seed"] == w.get("seed")]
        at = f"{w.get('time_s', 0):.2f}" + (f", fell {fell[0]:.2f}" if fell and fell[0] else "")
        print(f"| {stop(r)} | {at} | {f(r['mx'])} | {r['s']:.2f} | {f(r['planned_m'])} | "
              + " | ".join(f"{p[n]:.4f}" for n, *_ in space) + " |")


if __name__ == "__main__":
    main()
