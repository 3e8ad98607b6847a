#!/usr/bin/env python3
"""Where a T1 trial's time goes, side by side in one run, on this machine:

  1. the server's own walk: the league's 2026 server (rcssservermj, sync
     mode, started once per walk as its users start it) with naofarm's
     walker, from the first perception to the end of the stand and the walk
     (D s), wall and CPU seconds (server and walker);
  2. a trial of the program started for it (`t1-trial < TRIAL`): the whole
     process, wall and CPU;
  3. a trial of the program kept between trials (`t1-trial --serve`, as a
     worker runs it): wall and CPU per trial, and the process's start;
  4. the farm: `naofarm run` of experiments/t1.toml cut to a few iterations
     with W local workers (one slot each): trials per second, and per core.

Rounds interleave 1-3; each line gives the median. The kept trials' answers
must equal the fresh ones' to the bit (checked).

  scripts/t1-bench.py PROGRAM [--naofarm BIN] [--rounds N] [--iterations N]
      [--workers W]

PROGRAM is the T1 set-up's trial program (the last line setup.sh prints).
"""

import argparse
import importlib.machinery
import importlib.util
import json
import os
import resource
import socket
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.realpath(__file__))
sys.path.insert(0, HERE)
from farm_bench import Kept, children_cpu, farm, tree_cpu  # noqa: E402
ROOT = os.path.dirname(HERE)
DURATION = 10.0


def own_cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def load_program(program):
    """The trial program as a module: its walker and policy."""
    sys.path.insert(0, os.path.dirname(program))
    loader = importlib.machinery.SourceFileLoader("t1_trial", program)
    spec = importlib.util.spec_from_loader("t1_trial", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def trial_doc(scratch, seed):
    return {"run": "bench", "iteration": 0, "trial": seed, "seed": seed, "duration_s": DURATION,
            "robot_type": 0, "params": {}, "slot": 0, "scratch": scratch}


def server_walk(t1, policy, scratch, seed):
    """The stock server's walk with naofarm's walker: (wall, CPU) from the
    first perception to the end."""
    import numpy as np

    port, monitor = free_port(), free_port()
    rcssservermj = os.path.join(t1.PREFIX, "venv", "bin", "rcssservermj")
    server = subprocess.Popen(
        [rcssservermj, "--host", "127.0.0.1", "--aport", str(port), "--mport", str(monitor),
         "--sync", "--no-realtime", "--no-render"],
        cwd=scratch, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    try:
        link = t1.Link(port, server.pid)
        link.send("(init T1 naofarm 1)")
        link.recv()
        link.send("(beam -10.0 0.0 0.0)")
        first = link.recv
        mark = {}

        def recv():
            text = first()
            if not mark:
                mark.update(t=time.perf_counter(), cpu=own_cpu(), server=tree_cpu(server.pid))
            return text

        link.recv = recv
        t1.walk(link, policy, DURATION, dict(t1.WALK), np.random.default_rng(seed))
        wall = time.perf_counter() - mark["t"]
        cpu = own_cpu() - mark["cpu"] + tree_cpu(server.pid) - mark["server"]
    finally:
        server.kill()
        server.wait()
    return wall, cpu


def fresh_trial(program, scratch, seed):
    c0, t0 = children_cpu(), time.perf_counter()
    out = subprocess.run([program], input=json.dumps(trial_doc(scratch, seed)), cwd=scratch,
                         capture_output=True, text=True, check=True)
    return time.perf_counter() - t0, children_cpu() - c0, out.stdout.splitlines()[-1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    ap.add_argument("program")
    ap.add_argument("--naofarm", default=os.path.join(ROOT, "target", "release", "naofarm"))
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    program = os.path.realpath(a.program)
    t1 = load_program(program)
    t1.server.warm_up()
    policy = t1.nn.Policy(t1.WEIGHTS, t1.META)
    own, fresh, kept = [], [], []
    with tempfile.TemporaryDirectory() as scratch:
        served = Kept(program, scratch, trial_doc)
        start, _, _ = served.trial(0)
        for seed in range(1, a.rounds + 1):
            own.append(server_walk(t1, policy, scratch, seed))
            wall, cpu, cold = fresh_trial(program, scratch, seed)
            fresh.append((wall, cpu))
            wall, cpu, warm = served.trial(seed)
            kept.append((wall, cpu))
            if warm != cold:
                sys.exit(f"seed {seed}: the kept program answered {warm}, a fresh one {cold}")
        served.close()
    median = [tuple(statistics.median(x[i] for x in rows) for i in (0, 1))
              for rows in (own, fresh, kept)]
    (own_w, own_c), (fresh_w, fresh_c), (kept_w, kept_c) = median
    print(f"server's own walk ({DURATION + 1:.0f} s): {own_w:.3f} s wall, {own_c:.3f} s CPU "
          f"(server and walker; {DURATION / own_w:.1f}x real time)")
    print(f"fresh program per trial:  {fresh_w:.3f} s wall, {fresh_c:.3f} s CPU "
          f"({fresh_w / own_w:.2f}x the walk's wall, {fresh_c / own_c:.2f}x its CPU)")
    print(f"kept program per trial:   {kept_w:.3f} s wall, {kept_c:.3f} s CPU "
          f"({kept_w / own_w:.2f}x the walk's wall, {kept_c / own_c:.2f}x its CPU); "
          f"its start and first trial {start:.2f} s; answers equal to the fresh ones'")
    if a.iterations > 0:
        n, fwall, fcpu = farm(a.naofarm, "t1", f"t1={program}", a.iterations, a.workers)
        cores = min(a.workers, os.cpu_count() or 1)
        print(f"farm, {a.workers} workers:         {n} trials in {fwall:.1f} s: "
              f"{n / fwall:.3f} trials/s, {n / fwall / cores:.3f} per core; "
              f"{fcpu / n:.3f} s CPU per trial (the machine's, all of it)")


if __name__ == "__main__":
    main()
