"""How fast a ``lineslam`` command stops on SIGINT/SIGTERM (``slam.interrupts``).

Two measurements of one command line (``{out}`` in it stands for a fresh output path):

* ``gaps``: the command runs here, in this process, with :func:`slam.interrupts.check` wrapped
  to record when and where it is called; prints the longest gaps between two checks (from the
  start of ``main`` to its end), i.e. the longest a signal can wait before the run acts on it.
* ``signal`` (default): the command runs ``--runs`` times as a subprocess (``python -m slam``);
  each run gets the signal at a uniformly random moment of ``[0, --within]`` seconds after its
  start; prints, per run, the delay, the exit status, the time from the signal to the end of
  the process (wall clock: the process's exit included) and whether it left anything beside
  ``{out}``, then the largest and the median stop time.

Both depend on the machine and its load (printed).

    .venv/bin/python scripts/bench_interrupt.py --within 55 --runs 8 -- slam intel --out {out}
    .venv/bin/python scripts/bench_interrupt.py --gaps -- map aces --out {out}
"""

from __future__ import annotations

import argparse
import itertools
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.1f} {five:.1f} {fifteen:.1f} on {os.cpu_count()} CPUs"


def gaps(args: list[str], top: int) -> None:
    """Run ``lineslam ARGS`` here; print the longest gaps between two checks."""
    import slam.interrupts as interrupts

    original = interrupts.check
    calls: list[tuple[float, str]] = []

    def check() -> None:
        frame = sys._getframe(1)
        where = os.path.relpath(frame.f_code.co_filename, ROOT)
        calls.append((time.perf_counter(), f"{where}:{frame.f_lineno}"))
        original()

    interrupts.check = check  # type: ignore[assignment]
    from slam.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        argv = [a.replace("{out}", str(Path(tmp) / "out")) for a in args]
        calls.append((time.perf_counter(), "start"))
        status: object = 0
        try:
            main(argv)
        except SystemExit as exc:
            status = exc.code
        calls.append((time.perf_counter(), "end"))
    spans = sorted(((b[0] - a[0], a[1], b[1]) for a, b in itertools.pairwise(calls)), reverse=True)
    total = calls[-1][0] - calls[0][0]
    print(f"lineslam {' '.join(args)}: exit {status}, {total:.1f} s, {len(calls) - 2} checks")
    print(_load())
    for span, a, b in spans[:top]:
        print(f"  {span:6.2f} s  {a} -> {b}")


def signals(args: list[str], runs: int, within: float, signum: int, seed: int) -> None:
    """Signal ``runs`` subprocesses at random moments; print the stop times."""
    rng = random.Random(seed)
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    stops = []
    print(f"lineslam {' '.join(args)}: {signal.Signals(signum).name} within {within:g} s")
    print(_load())
    for i in range(runs):
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "out"
            cmd = [sys.executable, "-m", "slam", *(a.replace("{out}", str(out)) for a in args)]
            delay = rng.uniform(0.0, within)
            proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            time.sleep(delay)
            proc.send_signal(signum)
            t0 = time.monotonic()
            try:
                _, err = proc.communicate(timeout=300)
            except subprocess.TimeoutExpired:
                proc.kill()
                _, err = proc.communicate()
            stop = time.monotonic() - t0
            left = sorted(p.name for p in Path(tmp).iterdir())
            last = (err.decode(errors="replace").strip().splitlines() or [""])[-1]
            stops.append(stop)
            print(
                f"  {i:2d}  signal at {delay:6.2f} s  exit {proc.returncode:4d}  "
                f"stopped after {stop:5.2f} s  left {left or 'nothing'}  | {last[:70]}"
            )
    stops.sort()
    print(f"stop: largest {stops[-1]:.2f} s, median {stops[len(stops) // 2]:.2f} s ({runs} runs)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--gaps", action="store_true", help="gaps between checks (in-process)")
    parser.add_argument("--top", type=int, default=8, help="gaps shown")
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--within", type=float, default=10.0, help="latest signal (s)")
    parser.add_argument("--sigterm", action="store_true", help="SIGTERM instead of SIGINT")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- lineslam arguments")
    ns = parser.parse_args()
    args = ns.command[1:] if ns.command[:1] == ["--"] else ns.command
    if not args:
        parser.error("give the lineslam command line after --")
    if ns.gaps:
        gaps(args, ns.top)
    else:
        signum = signal.SIGTERM if ns.sigterm else signal.SIGINT
        signals(args, ns.runs, ns.within, signum, ns.seed)


if __name__ == "__main__":
    main()
