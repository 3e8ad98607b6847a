#!/usr/bin/env python3
"""Decision counts and each parameter's sample spread per 50 iterations of a
run (docs/walk.md), from `naofarm history RUN --csv` on stdin."""
import csv
import statistics
import sys

rows = list(csv.DictReader(sys.stdin))
params = [c for c in rows[0] if c not in
          ("iteration", "s", "mx", "my", "ex", "ey", "decision", "best")]
print("| iterations | ACCEPT | EQUIVALENT | REJECT | "
      + " | ".join(f"{p} mean ± sd" for p in params) + " |")
print("|---" * (4 + len(params)) + "|")
for b in range(0, len(rows), 50):
    chunk = rows[b:b + 50]
    n = {d: sum(r["decision"] == d for r in chunk)
         for d in ("ACCEPT", "EQUIVALENT", "REJECT")}
    cells = []
    for p in params:
        v = [float(r[p]) for r in chunk]
        sd = statistics.stdev(v) if len(v) > 1 else 0.0
        cells.append(f"{statistics.mean(v):.4f} ± {sd:.4f}")
    print(f"| {b}–{b + len(chunk) - 1} | {n['ACCEPT']} | {n['EQUIVALENT']} | "
          f"{n['REJECT']} | " + " | ".join(cells) + " |")
tot = {d: sum(r["decision"] == d for r in rows)
       for d in ("ACCEPT", "EQUIVALENT", "REJECT")}
print(f"\nIn all: {tot['ACCEPT']} ACCEPT, {tot['EQUIVALENT']} EQUIVALENT, "
      f"{tot['REJECT']} REJECT over {len(rows)} iterations.")
