#!/usr/bin/env python3
"""naofarm's shipped physics against MuJoCo's NAO, side by side.

Installs MuJoCo from PyPI into a private virtual environment (once), builds
bench/mujoco-nao/bench.c against the headers and library in its wheel, and
runs, in interleaved pairs on one core each: MuJoCo's closed C loop on the
same NAO (bench/mujoco-nao/nao.xml, 5 ms steps, discrete integrator,
Newton, the stepping motion of bench.c) and `naofarm bench sim` (the shipped
physics, 4 x 5 ms, walking the expert set). Prints each pair's physics steps
per CPU second and their ratio, then the median ratio.

    scripts/bench-mujoco.py [--pairs 5] [--venv DIR] [--naofarm target/release/naofarm]
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
    """naofarm's shipped walk's physics steps per CPU second (one round of `bench sim`)."""
    out = subprocess.run([binary, "bench", "sim", "--rounds", "1", "--seconds", "10", "--json"],
                         capture_output=True, text=True, check=True).stdout
    return float(json.loads(out)["steps_per_second"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--venv", default=os.path.join(os.path.expanduser("~"), ".cache", "naofarm", "mujoco-venv"))
    ap.add_argument("--naofarm", default=str(ROOT / "target" / "release" / "naofarm"))
    a = ap.parse_args()
    if not 1 <= a.pairs <= 100:
        sys.exit("--pairs must be in 1..=100")
    exe = mujoco_bench(pathlib.Path(a.venv))
    if not os.path.exists(a.naofarm):
        subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
    print("pair  naofarm steps/s  MuJoCo steps/s  naofarm / MuJoCo")
    ratios = []
    for k in range(a.pairs):
        ours, theirs = naofarm_steps(a.naofarm), mujoco_steps(exe)
        ratios.append(ours / theirs)
        print(f"{k + 1:4d}  {ours:15.0f}  {theirs:14.0f}  {ours / theirs:16.2f}")
    print(f"median over {a.pairs} pairs: {statistics.median(ratios):.2f} x MuJoCo's physics steps per second")


if __name__ == "__main__":
    main()
