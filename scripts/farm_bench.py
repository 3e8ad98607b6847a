"""What the trial-program benches share: a farm run of an experiment cut to
a few iterations, timed. Imported by league-bench.py and t1-bench.py."""

import os
import resource
import subprocess
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def farm(naofarm, experiment, program, iterations, workers):
    """`naofarm run experiments/EXPERIMENT.toml` cut to `iterations` with
    `workers` local workers and `--program NAME=PATH` (`program`): (trials
    decided, wall s, CPU s of everything it ran)."""
    with tempfile.TemporaryDirectory() as d:
        exp = os.path.join(d, f"{experiment}.toml")
        with open(os.path.join(ROOT, "experiments", f"{experiment}.toml"), encoding="utf-8") as f:
            lines = [f"iterations = {iterations}" if line.startswith("iterations = ") else line
                     for line in f.read().splitlines()]
        with open(exp, "w", encoding="utf-8") as f:
            f.write("\n".join(lines) + "\n")
        c0, t0 = children_cpu(), time.monotonic()
        out = subprocess.run(
            [naofarm, "run", exp, "--out", os.path.join(d, "run"), "--json",
             "--workers", str(workers), "--program", program],
            capture_output=True, text=True, check=True)
        wall, cpu = time.monotonic() - t0, children_cpu() - c0
    trials = sum(1 for line in out.stdout.splitlines()
                 if line.startswith('{"event":"decided"')) * 10
    return trials, wall, cpu
