#!/usr/bin/env python3
"""Where a league trial's time goes, side by side in one run, on this machine:

  1. the server's own sync-mode speed: one agent walking N walks of D s on
     one server (UT's own optimisation loop), seconds per walk;
  2. the trial program started for each trial (programs/league/league-trial):
     a server and an agent per walk, wall and CPU seconds per trial (CPU of
     the program and everything it started), and the walks' spread;
  3. the trial program kept between trials (`league-trial --serve`, as a
     worker runs it): one server, an agent per walk; the same figures, and
     the same trials' spread, which must match the fresh one's (nothing
     carried over);
  4. the farm: `naofarm run` of experiments/league.toml cut to a few
     iterations, with W local workers (one slot each): trials per second,
     and per core.

  scripts/league-bench.py PROGRAM [--naofarm BIN] [--walks N] [--trials N]
      [--iterations N] [--workers W]

PROGRAM is the league build's trial program (the last line build.sh prints).
"""

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.realpath(__file__))
sys.path.insert(0, HERE)
from farm_bench import Kept, children_cpu, farm  # noqa: E402
ROOT = os.path.dirname(HERE)


DURATION = 10.0


def trial_doc(scratch, k):
    return {
        "run": "bench", "iteration": 0, "trial": k, "seed": k,
        "duration_s": DURATION, "robot_type": 0, "params": {},
        "slot": 0, "scratch": scratch,
    }


def server_walks(program, walks, duration):
    """One server, one agent walking `walks` walks in UT's own loop
    (`naofarm_walks`): the server's speed without a start per walk."""
    prefix = os.path.dirname(os.path.dirname(os.path.realpath(program)))
    agent_dir = os.path.join(prefix, "agent")
    with tempfile.TemporaryDirectory() as scratch:
        libs = [os.path.join(prefix, "lib", d) for d in ("simspark", "rcssserver3d")]
        env = dict(os.environ, HOME=scratch, LD_LIBRARY_PATH=":".join(libs))
        socks = [socket.socket() for _ in range(2)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        ports = [s.getsockname()[1] for s in socks]
        for s in socks:
            s.close()
        server = subprocess.Popen(
            [os.path.join(prefix, "bin", "rcssserver3d"), "--agent-port", str(ports[0]),
             "--server-port", str(ports[1])],
            cwd=scratch, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                with open("/proc/net/tcp", encoding="ascii") as f:
                    up = {int(l.split()[1].rsplit(":", 1)[1], 16) for l in f.readlines()[1:]
                          if l.split()[3] == "0A"}
                if set(ports) <= up:
                    break
                time.sleep(0.02)
            params = os.path.join(scratch, "p.txt")
            with open(params, "w", encoding="utf-8") as f:
                f.write(f"naofarm_walks\t{walks}\nnaofarm_walk_time\t{duration}\n")
            t0 = time.monotonic()
            agent = subprocess.Popen(
                [os.path.join(agent_dir, "agentspark"), "--unum", "2", "--type", "0",
                 "--paramsfile", "paramfiles/defaultParams.txt",
                 "--paramsfile", "paramfiles/defaultParams_t0.txt",
                 "--paramsfile", params, "--experimentout", os.path.join(scratch, "out.txt"),
                 "--optimize", "walkForwardAgent", "--port", str(ports[0]),
                 "--mport", str(ports[1])],
                cwd=agent_dir, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                text=True)
            stamps = []
            for line in agent.stdout:
                if line.startswith("naofarm-walk "):
                    stamps.append(time.monotonic())
                    if len(stamps) == walks:
                        break
            agent.kill()
            agent.wait()
        finally:
            server.send_signal(2)
            try:
                server.wait(timeout=2)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()
    first = stamps[0] - t0
    per_walk = (stamps[-1] - stamps[0]) / (len(stamps) - 1)
    return first, per_walk


def program_trials(program, trials):
    """Fresh and kept trials, interleaved: [(wall, CPU, x)] of each."""
    fresh, kept = [], []
    with tempfile.TemporaryDirectory() as scratch:
        served = Kept(program, scratch, trial_doc)
        served.trial(0)  # its server's start
        for k in range(1, trials + 1):
            c0, t0 = children_cpu(), time.monotonic()
            out = subprocess.run([program], input=json.dumps(trial_doc(scratch, k)), text=True,
                                 capture_output=True, check=True)
            x = json.loads(out.stdout.strip().splitlines()[-1])["x_m"]
            fresh.append((time.monotonic() - t0, children_cpu() - c0, x))
            wall, cpu, answer = served.trial(k)
            kept.append((wall, cpu, json.loads(answer)["x_m"]))
        served.close()
    return fresh, kept


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("program")
    ap.add_argument("--naofarm", default=os.path.join(ROOT, "target", "release", "naofarm"))
    ap.add_argument("--walks", type=int, default=10)
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    first, per_walk = server_walks(a.program, a.walks, DURATION)
    fresh, kept = program_trials(a.program, a.trials)
    print(f"server's own sync mode: {per_walk:.2f} s per {DURATION:.0f}-s walk "
          f"({DURATION / per_walk:.1f}x real time); the first walk after the agent "
          f"starts {first:.2f} s (both with UT's 3-s settle)")
    for name, rows in (("fresh program per trial", fresh), ("kept program per trial ", kept)):
        wall = statistics.median(r[0] for r in rows)
        cpu = statistics.median(r[1] for r in rows)
        xs = [r[2] for r in rows]
        print(f"{name}: {wall:.2f} s wall, {cpu:.2f} s CPU ({wall / per_walk:.2f}x a walk "
              f"in the server's loop); x {statistics.mean(xs):.3f} m, "
              f"sd {statistics.stdev(xs):.3f} m over {len(xs)} walks")
    if a.iterations > 0:
        n, fwall, fcpu = farm(a.naofarm, "league", f"league={a.program}", a.iterations,
                              a.workers)
        cores = min(a.workers, os.cpu_count() or 1)
        print(f"farm, {a.workers} workers:       {n} trials in {fwall:.1f} s: "
              f"{n / fwall:.3f} trials/s, {n / fwall / cores:.3f} per core; "
              f"{fcpu / n:.2f} s CPU per trial (the machine's, all of it)")


if __name__ == "__main__":
    sys.exit(main())
