#!/usr/bin/env python3
"""How long a walk lasts: the same trials run for longer than the farm's 10 s.

The paper's trials (and the farm's) last 10 s, so a walk that drifts and
falls in its eleventh second scores as one that walks on. This runs each
walk's trials for each duration (the first 10 s of a 30 s trial are the
10 s trial, bit for bit) and prints, per duration, s, mx over the trials that
stood, the torso's mean pitch over them, and the median time of the falls.

    scripts/endurance.py [--bin target/release/naofarm] [--trials 40]
                         [--durations 10,20,30] "label|naofarm trial args" ...

e.g. "expert|--experiment experiments/physical-technical.toml".
Trials start at seed 777 (Table IV's) on 2 threads.
"""
import argparse
import json
import shlex
import statistics
import subprocess


def run(binary, args, trials, duration):
    cmd = [binary, "trial", *args, "--json", "--trials", str(trials),
           "--seed", "777", "--threads", "2", "--duration", str(duration)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def cell(r):
    falls = [t["fall_time_s"] for t in r["trials"] if t["fell"]]
    mx = "–" if r["mx"] is None else f"{r['mx']:.2f}"
    pitch = (r.get("footwork") or {}).get("torso_pitch_deg")
    pitch = "–" if pitch is None else f"{pitch:.0f}°"
    median = f"{statistics.median(falls):.1f}" if falls else "–"
    return f"{r['s']:.2f}, {mx} m, {pitch}, {median}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/naofarm")
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--durations", default="10,20,30")
    ap.add_argument("walks", nargs="+", help='"label|naofarm trial args"')
    a = ap.parse_args()
    durations = [float(d) for d in a.durations.split(",")]
    print(f"{a.trials} trials from seed 777 per cell: s, mx over the trials that stood, "
          "their torso's mean pitch (− leans back), the median fall (s)\n")
    print("| walk | " + " | ".join(f"{d:g} s" for d in durations) + " |")
    print("|---" * (1 + len(durations)) + "|")
    for spec in a.walks:
        label, _, args = spec.partition("|")
        cells = [cell(run(a.bin, shlex.split(args), a.trials, d)) for d in durations]
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
