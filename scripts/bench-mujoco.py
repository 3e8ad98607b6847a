#!/usr/bin/env python3
"""naofarm's shipped physics against MuJoCo's NAO, side by side.

Installs MuJoCo from PyPI into a private virtual environment (once), builds
bench/mujoco-nao/bench.c against the headers and library in its wheel, and
runs, in interleaved pairs on one core each: MuJoCo's closed C loop on the
same NAO (bench/mujoco-nao/nao.xml, 5 ms steps, discrete integrator,
Newton, the stepping motion of bench.c) and `naofarm bench sim` (the shipped
physics, 4 x 5 ms, walking the expert set; the median of 3 rounds). Prints
each pair's physics steps per CPU second and their ratio, then the median
ratio. Given `--naofarm` more than once (builds to compare, say before and
after a change), each pair runs every build beside the same MuJoCo runs.

    scripts/bench-mujoco.py [--pairs 5] [--venv DIR] [--naofarm target/release/naofarm ...]
"""
import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import json

ROOT = pathlib.Path(__file__).resolve().parent.parent
BENCH = ROOT / "bench" / "mujoco-nao"
MUJOCO = "mujoco==4.0.0"


def mujoco_bench(venv: pathlib.Path) -> pathlib.Path:
    """The built bench.c of `venv`'s MuJoCo (installed and built on first use)."""
    python = venv / "bin" / "python"
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    if subprocess.run([str(python), "-c", "import mujoco"], capture_output=True).returncode:
        subprocess.run([str(venv / "bin" / "pip"), "install", "-q", MUJOCO], check=True)
    mj = subprocess.run([str(python), "-c", "import mujoco, os; print(os.path.dirname(mujoco.__file__))"],
                        capture_output=True, text=True, check=True).stdout.strip()
    exe = venv / "nao-bench"
    source = BENCH / "bench.c"
    if not exe.exists() or exe.stat().st_mtime < source.stat().st_mtime:
        subprocess.run(["gcc", "-O2", "-o", str(exe), str(source), f"-I{mj}/include", f"-L{mj}",
                        "-l:libmujoco.so.4.0.0", f"-Wl,-rpath,{mj}", "-lpthread", "-lm"], check=True)
    return exe


def mujoco_steps(exe: pathlib.Path) -> float:
    """MuJoCo's physics steps per CPU second, the median of 3 timed 10 s episodes."""
    out = subprocess.run([str(exe), str(BENCH / "nao.xml"), "0.005", "discrete", "newton", "step", "10",
                          "1", "3", "1"], capture_output=True, text=True, check=True).stdout
    sps = [float(f.split("=")[1]) for line in out.splitlines() if line.startswith("RESULT")
           for f in line.split() if f.startswith("sps_cpu=")]
    return statistics.median(sps)


def naofarm_steps(binary: str) -> float:
    """naofarm's shipped walk's physics steps per CPU second (the median of 3 rounds of `bench sim`)."""
    out = subprocess.run([binary, "bench", "sim", "--rounds", "3", "--seconds", "10", "--json"],
                         capture_output=True, text=True, check=True).stdout
    return float(json.loads(out)["steps_per_second"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--venv", default=os.path.join(os.path.expanduser("~"), ".cache", "naofarm", "mujoco-venv"))
    ap.add_argument("--naofarm", action="append",
                    help="a naofarm binary (repeatable; default target/release/naofarm)")
    a = ap.parse_args()
    if not 1 <= a.pairs <= 100:
        sys.exit("--pairs must be in 1..=100")
    binaries = a.naofarm or [str(ROOT / "target" / "release" / "naofarm")]
    exe = mujoco_bench(pathlib.Path(a.venv))
    for binary in binaries:
        if not os.path.exists(binary):
            if binary != str(ROOT / "target" / "release" / "naofarm"):
                sys.exit(f"no naofarm binary at {binary}")
            subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
    for i, binary in enumerate(binaries):
        print(f"naofarm {i + 1}: {binary}")
    print("pair  " + "  ".join(f"naofarm {i + 1} steps/s" for i in range(len(binaries)))
          + "  MuJoCo steps/s  " + "  ".join(f"{i + 1} / MuJoCo" for i in range(len(binaries))))
    ratios = [[] for _ in binaries]
    for k in range(a.pairs):
        ours = [naofarm_steps(b) for b in binaries]
        theirs = mujoco_steps(exe)
        for r, o in zip(ratios, ours):
            r.append(o / theirs)
        print(f"{k + 1:4d}  " + "  ".join(f"{o:17.0f}" for o in ours) + f"  {theirs:14.0f}  "
              + "  ".join(f"{o / theirs:11.2f}" for o in ours))
    for i, r in enumerate(ratios):
        print(f"naofarm {i + 1}, median over {a.pairs} pairs: {statistics.median(r):.2f} x MuJoCo's "
              "physics steps per second")

if __name__ == "__main__":
    main()
