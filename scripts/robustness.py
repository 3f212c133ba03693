"""Robustness table: ``lineslam slam`` on variants of the catalogued logs it was never tuned on.

Each row of :data:`slam.experiments.robustness.VARIANTS` is a catalogued log (Intel, ACES,
fr079), unmodified or rewritten: laser lines decimated (every 3rd / 4th, from line 0, 1 or 2),
readings above 8 m set to the log's no-return value, odometry biased (translation ×1.02, heading
increments ``dθ + 0.02·|dθ|``) or made noisier (a seeded random walk added to every increment),
the odometry moved to a robot centre 0.2 m behind the laser (relations rewritten for the
centre), fewer beams.  The variant logs are generated once into a
cache outside the repository (keyed by the source log's sha256 and the transform's parameters).
A variant log is named after the variant, so it is a log the dataset catalogue does not know:
the catalogue's sensor facts (ACES's 50 m no-return value, fr079's 0.04 m mounting) do not
apply to it, only what the log itself states; the variants with fewer beams or clipped ranges
are written as ``ROBOTLASER1`` lines, which state beam layout and maximum range
(``--catalogued-names`` names every variant log as its source, and the catalogue's facts apply
as to the original).

For every row ``lineslam slam LOG --out DIR --quiet`` runs as a subprocess (the default
configuration, or ``--config``) and is scored with the Kümmerle relations metric on every
relation (a scan a variant dropped takes the pose of the last kept scan carried on by the
source's logged odometry; the trajectory is scored in the frame the run reports), next to the
variant's own logged odometry in the frame of the relations (laser poses; base poses for the
centre-frame relations of the mount variant).  ``--odometry-sign velocity`` reads both
odometries as the estimators do (fr079's hidden reversing repaired).  Also reported: the same
two on the relations shorter than 10 s, the run's CPU time (``os.wait4`` of the child: user +
system) and wall time, and from ``summary.json`` keyframes, landmarks, loop closures accepted /
attempted and failed registrations.

Prints a Markdown table and a summary line (how many rows are within their bars).

Usage::

    PYTHONPATH=. .venv/bin/python scripts/robustness.py                  # every row
    .venv/bin/python scripts/robustness.py --only aces-every3 aces-mount-0.2
    .venv/bin/python scripts/robustness.py --workers 2 --json after.json
    .venv/bin/python scripts/robustness.py --config new.toml --baseline before.json
    .venv/bin/python scripts/robustness.py --list                        # rows and bars
    .venv/bin/python scripts/robustness.py --summary after.json          # the README's table

Options: ``--only NAME...`` runs a subset; ``--extra`` also runs the extra rows
(:data:`slam.experiments.robustness.EXTRA_VARIANTS`: the same transforms on Intel, chains
of two or three transforms on the three logs, the three logs with noisier odometry, a noisier
laser, a narrower scanner or no odometry, and the held-out rows: a 5.6 m scanner and odometry
one laser line late; ``--list`` shows them); ``--workers N`` runs N rows at
once (1 by default; the times are only comparable between runs on an equally loaded machine);
``--config FILE.toml`` is passed to every run; ``--keep DIR`` keeps the results folders
(``DIR/NAME``, with the run's output in ``DIR/NAME.log``); ``--work DIR`` is the variant cache
(default ``~/.cache/lineslam/variants``); ``--catalogued-names`` (see above); ``--json FILE``
writes every number and the run's arithmetic (CPU, BLAS kernels, numpy's loops:
:func:`slam.experiments.robustness.arithmetic`); ``--baseline FILE.json`` (a previous
``--json``) also prints a before/after table: the baseline's mean translation error, this
run's, and the change, for every row in both, after a line naming any difference of
arithmetic between the two (which can move a row with no change of code).

The data root is ``$LINESLAM_DATA`` or ``../shared/datasets`` beside the repository.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import slam
from slam.experiments.robustness import (
    EXTRA_VARIANTS,
    VARIANTS,
    VariantFiles,
    arithmetic,
    arithmetic_difference,
    default_cache_dir,
    make_variant,
    score_run,
    variant_by_name,
)
from slam.io.tum import read_tum

DIAGNOSTICS = (
    "keyframes",
    "landmarks",
    "loop_closures",
    "loop_closure_candidates",
    "loop_closure_attempts",
    "registrations_failed",
)


def run_variant(
    files: VariantFiles, out: Path, config: Path | None, odometry_sign: str = "logged"
) -> dict[str, Any]:
    """Run ``lineslam slam`` on one variant (subprocess) and score it; a JSON-ready record."""
    variant = files.variant
    record: dict[str, Any] = {
        **variant.params(),
        "log": str(files.log),
        "relations": str(files.relations),
        "error": None,
    }
    cmd = [sys.executable, "-m", "slam", "slam", str(files.log), "--out", str(out), "--quiet"]
    if config is not None:
        cmd += ["--config", str(config)]
    env = dict(os.environ)
    repo = str(Path(slam.__file__).resolve().parents[1])  # the child runs this very code
    env["PYTHONPATH"] = os.pathsep.join(p for p in (repo, env.get("PYTHONPATH")) if p)
    log_path = out.with_name(out.name + ".log")
    wall = time.perf_counter()
    with log_path.open("w", encoding="utf-8") as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    record["wall_s"] = time.perf_counter() - wall
    record["cpu_s"] = usage.ru_utime + usage.ru_stime
    if proc.returncode != 0:
        tail = log_path.read_text(encoding="utf-8", errors="replace").splitlines()[-5:]
        record["error"] = f"exit {proc.returncode}: " + " / ".join(tail)
        return record
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    record["scans"] = summary["scans"]
    record["frame"] = summary["frame"]
    record["diagnostics"] = {k: summary.get(k) for k in DIAGNOSTICS}
    try:
        trajectory = read_tum(out / "trajectory.tum")
        score = score_run(trajectory, summary["frame"], files, odometry_sign=odometry_sign)
    except Exception as exc:  # a row that cannot be scored is reported, not fatal
        record["error"] = f"scoring: {type(exc).__name__}: {exc}"
        return record
    record["score"] = score.to_dict()
    record["trans_m"] = score.lineslam.abs_trans_m.mean
    record["rot_deg"] = score.lineslam.abs_rot_deg.mean
    record["within_bar"] = bool(record["trans_m"] <= variant.bar_m)
    return record


def _f(value: float | None, digits: int) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _mean(score: dict[str, Any], key: str, what: str) -> float | None:
    metric = score.get(key)
    return None if metric is None else float(metric[what]["mean"])


def _short(score: dict[str, Any], digits: int) -> str:
    """Relations shorter than 10 s: lineslam / odometry translation (m); rotation (deg)."""
    return (
        f"{_f(_mean(score, 'lineslam_short', 'abs_trans_m'), digits)} / "
        f"{_f(_mean(score, 'odometry_short', 'abs_trans_m'), digits)}; "
        f"{_f(_mean(score, 'lineslam_short', 'abs_rot_deg'), 2)} / "
        f"{_f(_mean(score, 'odometry_short', 'abs_rot_deg'), 2)}"
    )


def table(records: list[dict[str, Any]]) -> str:
    """The Markdown table of the records and a summary line."""
    lines = [
        "| variant | scans | bar (m) | lineslam (m / deg) | within bar | odometry (m / deg)"
        " | <10 s lineslam / odometry (m; deg) | CPU / wall (s) | keyframes | landmarks"
        " | closures accepted / attempts | registrations failed |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    within = 0
    for r in records:
        if r["error"] is not None:
            lines.append(f"| {r['name']} | | {r['bar_m']:.3f} | failed: {r['error']} |" + " |" * 8)
            continue
        s = r["score"]
        d = r["diagnostics"]
        within += r["within_bar"]
        short = _short(s, 4)
        cells = [
            r["name"],
            f"{r['scans']:,}",
            f"{r['bar_m']:.3f}",
            f"{r['trans_m']:.4f} / {r['rot_deg']:.2f}",
            "✓" if r["within_bar"] else "✗",
            f"{_f(_mean(s, 'odometry', 'abs_trans_m'), 4)} / "
            f"{_f(_mean(s, 'odometry', 'abs_rot_deg'), 2)}",
            short,
            f"{r['cpu_s']:.0f} / {r['wall_s']:.0f}",
            str(d["keyframes"]),
            str(d["landmarks"]),
            f"{d['loop_closures']} / {d['loop_closure_attempts']}",
            str(d["registrations_failed"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    failed = sum(r["error"] is not None for r in records)
    lines.append("")
    lines.append(
        f"{within} of {len(records)} within their bars"
        + (f" ({failed} failed)" if failed else "")
        + "; lineslam = mean absolute translation / rotation error on every relation."
    )
    return "\n".join(lines)


def summary_table(records: list[dict[str, Any]]) -> str:
    """The short Markdown table of the README: error, bar, odometry, short relations, closures."""
    lines = [
        "| variant | bar (m) | lineslam (m) | within | odometry (m)"
        " | < 10 s: lineslam / odometry (m; deg) | closures accepted / attempts |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in records:
        if r["error"] is not None:
            lines.append(f"| {r['name']} | {r['bar_m']:.3f} | failed: {r['error']} | ✗ | | | |")
            continue
        s = r["score"]
        d = r["diagnostics"]
        short = _short(s, 3)
        cells = [
            f"{r['name']} ({r['description']})".replace("|", "\\|"),  # a Markdown cell
            f"{r['bar_m']:.3f}",
            f"{r['trans_m']:.3f}",
            "✓" if r["within_bar"] else "✗",
            _f(_mean(s, "odometry", "abs_trans_m"), 3),
            short,
            f"{d['loop_closures']} / {d['loop_closure_attempts']}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def baseline_table(records: list[dict[str, Any]], baseline: dict[str, Any]) -> str:
    """Before (``baseline``) / after (``records``) mean translation error per row."""
    before = {r["name"]: r for r in baseline.get("runs", [])}
    lines = [
        "| variant | bar (m) | before (m) | after (m) | change (m) | within before → after"
        " | CPU before / after (s) |",
        "|---|---|---|---|---|---|---|",
    ]

    def trans(r: dict[str, Any] | None) -> float | None:
        return None if r is None or r.get("error") is not None else float(r["trans_m"])

    def ok(r: dict[str, Any] | None) -> str:
        if r is None:
            return "–"
        return "failed" if r.get("error") is not None else ("✓" if r["within_bar"] else "✗")

    counts = [0, 0]
    for r in records:
        b = before.get(r["name"])
        t0, t1 = trans(b), trans(r)
        change = "–" if t0 is None or t1 is None else f"{t1 - t0:+.4f}"
        counts[0] += ok(b) == "✓"
        counts[1] += ok(r) == "✓"
        cpu0 = "–" if b is None or "cpu_s" not in b else f"{b['cpu_s']:.0f}"
        cpu1 = f"{r['cpu_s']:.0f}" if "cpu_s" in r else "–"
        lines.append(
            f"| {r['name']} | {r['bar_m']:.3f} | {_f(t0, 4)} | {_f(t1, 4)} | {change}"
            f" | {ok(b)} → {ok(r)} | {cpu0} / {cpu1} |"
        )
    lines.append("")
    lines.append(f"within their bars: {counts[0]} before, {counts[1]} after (rows of this run)")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    names = [v.name for v in VARIANTS]
    extra = [v.name for v in EXTRA_VARIANTS]
    parser.add_argument(
        "--only", nargs="+", choices=names + extra, metavar="NAME", help="rows to run"
    )
    parser.add_argument(
        "--extra", action="store_true", help="also the extra rows (Intel's variants, chains)"
    )
    parser.add_argument("--workers", type=int, default=1, help="rows run at once (default 1)")
    parser.add_argument("--config", type=Path, default=None, help="TOML run configuration")
    parser.add_argument("--keep", type=Path, default=None, help="keep results folders here")
    parser.add_argument("--work", type=Path, default=None, help="variant cache folder")
    parser.add_argument(
        "--catalogued-names",
        action="store_true",
        help="name variant logs as their source (the catalogue's sensor facts then apply)",
    )
    parser.add_argument(
        "--odometry-sign",
        choices=("logged", "velocity"),
        default="logged",
        help="how the odometry of the fill-in and of the baseline is read (default logged)",
    )
    parser.add_argument("--json", type=Path, default=None, help="write every number here")
    parser.add_argument("--baseline", type=Path, default=None, help="a previous --json")
    parser.add_argument("--list", action="store_true", help="list the rows and exit")
    parser.add_argument(
        "--summary",
        type=Path,
        default=None,
        help="print the README's short table of a previous --json and exit",
    )
    args = parser.parse_args()
    if args.summary is not None:
        print(summary_table(json.loads(args.summary.read_text(encoding="utf-8"))["runs"]))
        return
    if args.list:
        for v in VARIANTS + EXTRA_VARIANTS:
            print(f"{v.name:<22} {v.dataset:<6} bar {v.bar_m:.3f} m  {v.description}")
        return
    if args.workers < 1:
        parser.error("--workers must be >= 1")
    config = args.config.resolve() if args.config is not None else None
    if config is not None and not config.is_file():
        parser.error(f"--config {config}: no such file")
    baseline = None
    if args.baseline is not None:
        baseline = json.loads(args.baseline.read_text(encoding="utf-8"))
    variants = [variant_by_name(n) for n in (args.only or names + (extra if args.extra else []))]
    cache = args.work if args.work is not None else default_cache_dir()
    print(f"variants in {cache}", file=sys.stderr, flush=True)
    files = [make_variant(v, cache, catalogued_name=args.catalogued_names) for v in variants]

    with tempfile.TemporaryDirectory(prefix="lineslam-robustness-") as tmp:
        results = Path(tmp) if args.keep is None else args.keep
        results.mkdir(parents=True, exist_ok=True)

        def job(f: VariantFiles) -> dict[str, Any]:
            record = run_variant(f, results / f.variant.name, config, args.odometry_sign)
            state = record["error"] or f"{record['trans_m']:.4f} m"
            print(f"{f.variant.name}: {state} ({record['wall_s']:.0f} s)", file=sys.stderr)
            return record

        started = time.perf_counter()
        with ThreadPoolExecutor(max_workers=args.workers) as pool:
            records = list(pool.map(job, files))
        total_s = time.perf_counter() - started
    print(table(records))
    here = arithmetic()
    if baseline is not None:
        print()
        print(f"before: {args.baseline}")
        differs = arithmetic_difference(baseline.get("arithmetic"), here)
        if differs is not None:
            print(
                f"other arithmetic than the baseline's ({differs}): a row can move by which "
                "closures pass, with no change of code"
            )
        print(baseline_table(records, baseline))
    if args.json is not None:
        out = {
            "version": 1,
            "config": None if config is None else str(config),
            "workers": args.workers,
            "catalogued_names": args.catalogued_names,
            "odometry_sign": args.odometry_sign,
            "arithmetic": here,
            "total_wall_s": total_s,
            "within_bars": sum(bool(r.get("within_bar")) for r in records),
            "runs": records,
        }
        args.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {args.json}", file=sys.stderr)


if __name__ == "__main__":
    main()
