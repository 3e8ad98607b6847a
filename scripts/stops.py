#!/usr/bin/env python3
"""How far the closed-loop walk takes its joints past their stops, by physics
step (docs/walk.md, "Physics at speed").

Runs the expert set (seeds 1-5) and experiment 2's L at its 32 corners and
centre (one trial each, seed --l-seed) with `naofarm trial --walk closed-loop
--json --substeps K` for each K given, and prints a Markdown table: per K the
worst overrun of the hip yaw-pitch (`le1`) and of any other joint, on the
expert set and over L, how many of L's 33 trials fell, and what the expert set
walked (5 trials).

    scripts/stops.py [--bin target/release/naofarm] [--substeps 2 3 5 10]
    scripts/stops.py --experiment experiments/physical-technical-stiff.toml \\
        --l-seed 2 -- --pgs-iterations 56

With --experiment every trial starts from that file (its physics, its fixed
engine values; L is read from its parameters), and --substeps defaults to
the file's own. Arguments after `--` go to every `naofarm trial` as they are.

(from the repository's root: without --experiment it reads L from
experiments/physical-technical.toml)
"""
import argparse
import itertools
import json
import subprocess
import tomllib


def bounds(path):
    with open(path, "rb") as f:
        return [(p["name"], p["lower"], p["upper"]) for p in tomllib.load(f)["parameter"]]


def corners_and_centre(L):
    """L's corners (every parameter at its lower or upper bound, labelled by
    its bits in L's order, 1: upper) and its centre, as (label, values)."""
    sets = [("corner " + "".join(map(str, bits)),
             {n: (hi if bit else lo) for (n, lo, hi), bit in zip(L, bits)})
            for bits in itertools.product([0, 1], repeat=len(L))]
    sets.append(("centre", {n: (lo + hi) / 2 for n, lo, hi in L}))
    return sets


def trial(a, params, substeps, seed, trials):
    cmd = [a.bin, "trial", "--walk", "closed-loop", "--json", "--threads", "1",
           "--trials", str(trials), "--seed", str(seed)]
    if a.experiment:
        cmd += ["--experiment", a.experiment]
    if substeps is not None:
        cmd += ["--substeps", str(substeps)]
    for k, v in params.items():
        cmd += ["--param", f"{k}={v}"]
    out = subprocess.run(cmd + a.extra, check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def worst(runs):
    """(hip yaw-pitch, others): the worst overrun in degrees over the trials."""
    yp, other = 0.0, 0.0
    for d in runs:
        for t in d["trials"]:
            for e in t["stop_excess"]:
                if e["joint"].endswith("le1"):
                    yp = max(yp, e["deg"])
                else:
                    other = max(other, e["deg"])
    return yp, other


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/naofarm")
    ap.add_argument("--experiment", help="start every trial from this experiment file")
    ap.add_argument("--substeps", type=int, nargs="+",
                    help="physics steps per cycle (default 2 3 5 10, or the file's)")
    ap.add_argument("--l-seed", type=int, default=1, help="seed of L's 33 trials")
    ap.add_argument("extra", nargs="*", help="after --: more `naofarm trial` arguments")
    a = ap.parse_args()
    if a.substeps is None:
        a.substeps = [None] if a.experiment else [2, 3, 5, 10]
    L = bounds(a.experiment or "experiments/physical-technical.toml")
    sets = [values for _, values in corners_and_centre(L)]
    print("| physics | expert: hip yaw-pitch | expert: others | L: hip yaw-pitch "
          "| L: others | L: falls of 33 | expert: s, mx (m) |")
    print("|---|---|---|---|---|---|---|")
    for k in a.substeps:
        expert = [trial(a, {}, k, 1, 5)]
        over_l = [trial(a, p, k, a.l_seed, 1) for p in sets]
        e_yp, e_other = worst(expert)
        l_yp, l_other = worst(over_l)
        falls = sum(t["fell"] for d in over_l for t in d["trials"])
        physics = expert[0]["physics"]
        steps = physics["substeps"]
        name = f"{steps} × {20 / steps:.3g} ms, {physics['pgs_iterations']} PGS"
        print(f"| {name} | {e_yp:.2f}° | {e_other:.2f}° | "
              f"{l_yp:.2f}° | {l_other:.2f}° | {falls} | "
              f"{expert[0]['s']:.2f}, {expert[0]['mx'] or 0:.2f} |")


if __name__ == "__main__":
    main()
