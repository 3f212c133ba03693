"""Check that two versions of lineslam give bit-identical results on the same inputs.

Runs a fixed set of jobs (``lineslam slam`` on the demo log and the three catalogued logs,
``lineslam ekf`` and ``lineslam map`` on the demo, ``lineslam extract`` on the demo, the batch
back-end on the demo) into ``--out``, then, with ``--against DIR`` (an earlier ``--out`` of this
script), compares the files byte for byte.  ``summary.json`` is compared without its timing
fields (``runtime_s``, ``scan_runtime_s``, any key ending in ``_s`` under ``backend``), which
differ from run to run, and without ``log_anomalies`` (counts of the log's anomalies, a field
newer than some of the outputs compared; the demo and catalogued logs have none).

Usage::

    python scripts/identity_check.py --out /tmp/after --against /tmp/before
    PYTHONPATH=/path/to/old/checkout python scripts/identity_check.py --out /tmp/before

``--jobs`` selects a subset (``demo``, ``demo-batch``, ``demo-ekf``, ``demo-map``,
``demo-extract``, ``intel``, ``aces``, ``fr079``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

DEMO = "datasets/sim/demo/log.clf"

JOBS: dict[str, list[str]] = {
    "demo": ["slam", DEMO],
    "demo-batch": ["slam", DEMO, "--backend", "batch"],
    "demo-ekf": ["ekf", DEMO],
    "demo-map": ["map", DEMO],
    "demo-extract": ["extract", DEMO],
    "aces": ["slam", "aces"],
    "fr079": ["slam", "fr079"],
    "intel": ["slam", "intel"],
}

TIMING_KEYS = {"runtime_s", "scan_runtime_s", "time_s", "elapsed_s"}


def _strip_timing(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {
            k: _strip_timing(v)
            for k, v in obj.items()
            if k not in TIMING_KEYS
            and not k.endswith("_time_s")
            and k not in ("log", "log_anomalies")
        }
    if isinstance(obj, list):
        return [_strip_timing(v) for v in obj]
    return obj


def _digest(path: Path) -> str:
    if path.name in ("summary.json",):
        data = _strip_timing(json.loads(path.read_text("utf-8")))
        blob = json.dumps(data, sort_keys=True).encode()
    elif path.suffix == ".jsonl":
        blob = path.read_bytes()
    else:
        blob = path.read_bytes()
    return hashlib.sha256(blob).hexdigest()


def run_job(name: str, out: Path) -> float:
    cmd = JOBS[name]
    target = out / name
    if cmd[0] == "extract":
        args = [*cmd, "--out", str(target / "lines.jsonl")]
        target.mkdir(parents=True, exist_ok=True)
    else:
        args = [*cmd, "--out", str(target)]
    t0 = time.process_time()
    proc = subprocess.run(
        [sys.executable, "-m", "slam", *args, "--quiet"], capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise SystemExit(f"{name}: lineslam {' '.join(args)} failed:\n{proc.stderr}")
    return time.process_time() - t0


def digests(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.suffix in (".tum", ".json", ".jsonl", ".txt", ".toml"):
            out[str(p.relative_to(folder))] = _digest(p)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--against", type=Path, default=None)
    ap.add_argument("--jobs", nargs="*", default=list(JOBS))
    ap.add_argument("--no-run", action="store_true", help="only compare existing folders")
    args = ap.parse_args()
    if not args.no_run:
        for name in args.jobs:
            t0 = time.perf_counter()
            run_job(name, args.out)
            print(f"ran {name:14s} {time.perf_counter() - t0:7.1f} s wall", flush=True)
    if args.against is None:
        return 0
    bad = 0
    for name in args.jobs:
        mine = digests(args.out / name)
        theirs = digests(args.against / name)
        for f in sorted(set(mine) | set(theirs)):
            same = mine.get(f) == theirs.get(f)
            bad += not same
            print(f"{'identical' if same else 'DIFFERENT':9s}  {name}/{f}")
    print("all identical" if bad == 0 else f"{bad} files differ")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
