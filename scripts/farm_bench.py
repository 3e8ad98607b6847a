"""What the trial-program benches share: a farm run of an experiment cut to
a few iterations, timed. Imported by league-bench.py and t1-bench.py."""

import json
import os
import resource
import subprocess
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def busy_cpu():
    """CPU seconds this machine has spent busy (all processes; /proc/stat):
    what a run costs, kept servers and all, on an otherwise quiet machine."""
    with open("/proc/stat", encoding="ascii") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    idle = fields[3] + fields[4]  # idle, iowait
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def farm(naofarm, experiment, program, iterations, workers):
    """`naofarm run experiments/EXPERIMENT.toml` cut to `iterations` with
    `workers` local workers and `--program NAME=PATH` (`program`): (trials
    decided, wall s, CPU s the machine spent meanwhile)."""
    with tempfile.TemporaryDirectory() as d:
        exp = os.path.join(d, f"{experiment}.toml")
        with open(os.path.join(ROOT, "experiments", f"{experiment}.toml"), encoding="utf-8") as f:
            lines = [f"iterations = {iterations}" if line.startswith("iterations = ") else line
                     for line in f.read().splitlines()]
        with open(exp, "w", encoding="utf-8") as f:
            f.write("\n".join(lines) + "\n")
        c0, t0 = busy_cpu(), time.monotonic()
        out = subprocess.run(
            [naofarm, "run", exp, "--out", os.path.join(d, "run"), "--json",
             "--workers", str(workers), "--program", program],
            capture_output=True, text=True, check=True)
        wall, cpu = time.monotonic() - t0, busy_cpu() - c0
    trials = sum(1 for line in out.stdout.splitlines()
                 if line.startswith('{"event":"decided"')) * 10
    return trials, wall, cpu


def tree_cpu(pid):
    """CPU seconds of a live process, its reaped children and its live
    descendants."""
    def stat(p):
        try:
            with open(f"/proc/{p}/stat", encoding="ascii") as f:
                return f.read().rsplit(")", 1)[1].split()
        except OSError:
            return None

    tick = os.sysconf("SC_CLK_TCK")
    kids = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            fields = stat(entry)
            if fields:
                kids.setdefault(int(fields[1]), []).append(int(entry))
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        fields = stat(p)
        if fields:
            total += sum(int(v) for v in fields[11:15]) / tick
        todo.extend(kids.get(p, []))
    return total


class Kept:
    """A trial program kept between trials (`PROGRAM --serve`), as a worker
    keeps it; `doc(scratch, k)` makes trial k's JSON document."""

    def __init__(self, program, scratch, doc):
        self.p = subprocess.Popen([program, "--serve"], cwd=scratch, stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self.scratch, self.doc = scratch, doc

    def trial(self, k):
        """Trial k: (wall s, CPU s of the program and all it runs, answer)."""
        cpu, t = tree_cpu(self.p.pid), time.perf_counter()
        self.p.stdin.write(json.dumps(self.doc(self.scratch, k)) + "\n")
        self.p.stdin.flush()
        answer = self.p.stdout.readline().strip()
        return time.perf_counter() - t, tree_cpu(self.p.pid) - cpu, answer

    def close(self):
        self.p.stdin.close()
        self.p.wait()
