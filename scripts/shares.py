#!/usr/bin/env python3
"""Each walk's share of the open loop's speed, by rounds (docs/walk.md, "The
speed bound, lever by lever").

`naofarm bench sim` measures its own fixed rows. This measures any
`naofarm trial` arguments against the open loop at the default: every round
runs 20 expert trials of the open loop on one thread, then 20 of each walk,
and takes each walk's share as the open loop's wall time over its own. It
prints the median share over the rounds with their spread, and each walk's
s and mx (the trials are the same in every round).

    scripts/shares.py [--bin target/release/naofarm] [--rounds 7] \\
        "firm|--experiment experiments/physical-technical-firm.toml" \\
        "firm, 20 PGS|--experiment experiments/physical-technical-firm.toml --pgs-iterations 20"

(from the repository's root; a walk is `LABEL|ARGUMENTS`)
"""
import argparse
import json
import shlex
import statistics
import subprocess
import sys

OPEN_LOOP = ["--experiment", "experiments/physical-technical.toml", "--walk", "open-loop"]


def trial(binary, args):
    cmd = [binary, "trial", *args, "--trials", "20", "--seed", "777", "--threads", "1", "--json"]
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"`{' '.join(cmd)}` failed: {out.stderr.strip()}")
    return json.loads(out.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/naofarm")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("walks", nargs="+", help="LABEL|ARGUMENTS of `naofarm trial`")
    a = ap.parse_args()
    walks = []
    for w in a.walks:
        label, sep, args = w.partition("|")
        if not sep:
            ap.error(f"`{w}`: give a walk as LABEL|ARGUMENTS")
        walks.append((label, shlex.split(args)))
    shares = {label: [] for label, _ in walks}
    last = {}
    for _ in range(a.rounds):
        reference = trial(a.bin, OPEN_LOOP)["wall_s"]
        for label, args in walks:
            d = trial(a.bin, args)
            shares[label].append(reference / d["wall_s"])
            last[label] = d
    print("| walk | share of the open loop's speed (median; rounds) | s | mx (m) |")
    print("|---|---|---|---|")
    for label, _ in walks:
        v = sorted(shares[label])
        d = last[label]
        mx = "–" if d["mx"] is None else f"{d['mx']:.3f}"
        print(f"| {label} | {100 * statistics.median(v):.0f} % ({100 * v[0]:.0f}–{100 * v[-1]:.0f} %)"
              f" | {d['s']:.2f} | {mx} |")


if __name__ == "__main__":
    main()
