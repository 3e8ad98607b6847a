#!/usr/bin/env python3
"""How far the closed-loop walk takes its joints past their stops, by physics
step (docs/walk.md, "Physics at speed").

Runs the expert set (seeds 1-5) and experiment 2's L at its 32 corners and
centre (seed 1) with `naofarm trial --walk closed-loop --json --substeps K`
for each K given, and prints a Markdown table: per K the worst overrun of the
hip yaw-pitch (`le1`) and of any other joint, on the expert set and over L,
how many of L's 33 trials fell, and what the expert set walked (5 trials).

    scripts/stops.py [--bin target/release/naofarm] [--substeps 2 3 5 10]

(from the repository's root: it reads L from experiments/physical-technical.toml)
"""
import argparse
import itertools
import json
import subprocess
import tomllib

with open("experiments/physical-technical.toml", "rb") as f:
    L = [(p["name"], p["lower"], p["upper"]) for p in tomllib.load(f)["parameter"]]


def trial(binary, params, substeps, seed, trials):
    cmd = [binary, "trial", "--walk", "closed-loop", "--json", "--threads", "1",
           "--trials", str(trials), "--seed", str(seed), "--substeps", str(substeps)]
    for k, v in params.items():
        cmd += ["--param", f"{k}={v}"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
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
    ap.add_argument("--substeps", type=int, nargs="+", default=[2, 3, 5, 10])
    a = ap.parse_args()
    sets = [{n: (hi if bit else lo) for (n, lo, hi), bit in zip(L, bits)}
            for bits in itertools.product([0, 1], repeat=len(L))]
    sets.append({n: (lo + hi) / 2 for n, lo, hi in L})
    print("| physics | expert: hip yaw-pitch | expert: others | L: hip yaw-pitch "
          "| L: others | L: falls of 33 | expert: s, mx (m) |")
    print("|---|---|---|---|---|---|---|")
    for k in a.substeps:
        expert = [trial(a.bin, {}, k, 1, 5)]
        over_l = [trial(a.bin, p, k, 1, 1) for p in sets]
        e_yp, e_other = worst(expert)
        l_yp, l_other = worst(over_l)
        falls = sum(t["fell"] for d in over_l for t in d["trials"])
        print(f"| {k} × {20 / k:.3g} ms | {e_yp:.2f}° | {e_other:.2f}° | "
              f"{l_yp:.2f}° | {l_other:.2f}° | {falls} | "
              f"{expert[0]['s']:.2f}, {expert[0]['mx'] or 0:.2f} |")


if __name__ == "__main__":
    main()
