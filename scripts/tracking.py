#!/usr/bin/env python3
"""How a recorded trial's leg joints track their targets, and where its steps
land.

Reads replay files written by `naofarm trial --record FILE` (their `angles`,
`targets` and `load`) and prints, per file, a Markdown row per joint of the
left leg: the mean and rms of angle minus target and the range of each,
over the cycles after --skip seconds; then the steps: the foot-to-foot
distance along x at each landing (a foot's vertical load rising through
the header's `planted_n`, footwork's PLANTED_N, after the other foot's
landing), their median,
and the torso's advance; then the turn: the torso's yaw about the vertical
(its range and rms about its mean) and each stance foot's mean roll and
pitch while it alone carries the robot.

    naofarm trial --experiment experiments/physical-technical.toml \\
        --trials 1 --seed 777 --substeps 2 --record /tmp/r2.jsonl
    scripts/tracking.py /tmp/r2.jsonl /tmp/r10.jsonl
"""
import argparse
import json
import math
import statistics

def read(path):
    with open(path) as f:
        lines = [json.loads(line) for line in f]
    return lines[0], lines[1:]


def joints_table(head, rows, skip):
    names = head["joints"]
    cycles = [r for r in rows if r["t"] > skip]
    print("| joint | mean error (°) | rms error (°) | angle range (°) | target range (°) |")
    print("|---|---|---|---|---|")
    for j, name in enumerate(names):
        if not name.startswith("lle"):
            continue
        err = [math.degrees(r["angles"][j] - r["targets"][j]) for r in cycles]
        ang = [math.degrees(r["angles"][j]) for r in cycles]
        tgt = [math.degrees(r["targets"][j]) for r in cycles]
        rms = math.sqrt(sum(e * e for e in err) / len(err))
        print(f"| {name} | {statistics.mean(err):+.2f} | {rms:.2f} | "
              f"{min(ang):.1f} … {max(ang):.1f} | {min(tgt):.1f} … {max(tgt):.1f} |")


def steps(head, rows):
    bodies = [b["name"] for b in head["bodies"]]
    feet = [bodies.index("lfoot"), bodies.index("rfoot")]
    landings = []
    was = [True, True]
    for r in rows:
        for side in (0, 1):
            now = r["load"][side] >= head["planted_n"]
            if now and not was[side]:
                landings.append((side, r["poses"][feet[side]][0]))
            was[side] = now
    lengths = []
    for (a, xa), (b, xb) in zip(landings, landings[1:]):
        if a != b:
            lengths.append(xb - xa)
    torso = bodies.index("torso")
    advance = rows[-1]["poses"][torso][0] - rows[0]["poses"][torso][0]
    return lengths, advance


def euler(pose):
    """(roll, pitch, yaw) of a pose [x, y, z, qx, qy, qz, qw], degrees."""
    x, y, z, w = pose[3:]
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return [math.degrees(v) for v in (roll, pitch, yaw)]


def turn(head, rows, skip):
    bodies = [b["name"] for b in head["bodies"]]
    torso = bodies.index("torso")
    feet = [bodies.index("lfoot"), bodies.index("rfoot")]
    cycles = [r for r in rows if r["t"] > skip]
    if not cycles:
        return
    yaw = [euler(r["poses"][torso])[2] for r in cycles]
    mean = statistics.mean(yaw)
    rms = math.sqrt(statistics.mean((v - mean) ** 2 for v in yaw))
    print(f"\ntorso yaw {min(yaw):+.1f}° … {max(yaw):+.1f}°, rms {rms:.1f}° about its mean")
    for side, name in ((0, "left"), (1, "right")):
        alone = [euler(r["poses"][feet[side]]) for r in cycles
                 if r["load"][side] >= head["planted_n"] and r["load"][1 - side] < 1.0]
        if alone:
            print(f"{name} foot alone on the ground in {len(alone)} cycles: roll "
                  f"{statistics.mean(e[0] for e in alone):+.1f}°, pitch "
                  f"{statistics.mean(e[1] for e in alone):+.1f}° on average")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("records", nargs="+")
    ap.add_argument("--skip", type=float, default=2.0,
                    help="seconds left out of the joint table (the start)")
    a = ap.parse_args()
    for path in a.records:
        head, rows = read(path)
        print(f"\n{path} (seed {head['seed']}, {len(rows)} cycles)\n")
        joints_table(head, rows, a.skip)
        lengths, advance = steps(head, rows)
        if lengths:
            print(f"\n{len(lengths)} steps, median {statistics.median(lengths):.4f} m, "
                  f"mean {statistics.mean(lengths):.4f} m; the torso advanced {advance:.3f} m")
        else:
            print(f"\nno steps; the torso advanced {advance:.3f} m")
        turn(head, rows, a.skip)


if __name__ == "__main__":
    main()
