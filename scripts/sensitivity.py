"""How much does a real-log result move under small perturbations of the configuration?

Line SLAM on a real log passes through many discrete decisions (which lines are extracted,
which landmarks are fused, which loop closures are accepted); a tiny change can flip one and
change the final error.  A single run therefore says little about how robust a number is.  This
script runs ``lineslam slam`` on one log with the default configuration and with a set of
small perturbations of it, one after another, and prints the relations error of each and the
spread (mean, worst).

    LINESLAM_DATA=/path/to/shared/datasets .venv/bin/python scripts/sensitivity.py fr079
    .venv/bin/python scripts/sensitivity.py aces --variants default keyframe-0.19 sigma-range+2%
    .venv/bin/python scripts/sensitivity.py fr079 --config my.toml   # perturb another setting
    .venv/bin/python scripts/sensitivity.py --row fr079-every2-max8m  # a robustness row
    .venv/bin/python scripts/sensitivity.py intel --keep runs/  # keep runs/<variant>/

The perturbations are changes no user would call a different configuration: the keyframe
distance by ±5 %, the range noise of the line fits by ±2 %, the fusion and loop-closing
intervals by one keyframe.  ``--draws 16`` adds eight more of the same kind (keyframe
distance ±2.5 % and ±7.5 %, range noise ±1 % and −3 %, fusion every 11 keyframes), for a
comparison of two configurations that eight draws cannot settle.

``--row NAME`` runs a row of ``scripts/robustness.py`` (its log made, or taken from the
cache ``--work``, as that script does) and scores it as that script does: on every relation,
a scan the variant dropped carried on by the source's odometry
(:func:`slam.experiments.robustness.score_run`).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)
import numpy as np

from slam.config import RunConfig
from slam.runner import run_slam

Perturbation = Callable[[RunConfig], RunConfig]


def _slam(**kw: object) -> Perturbation:
    def apply(c: RunConfig) -> RunConfig:
        s = c.slam
        for path, value in kw.items():
            head, _, leaf = path.partition("__")
            if leaf:
                s = replace(s, **{head: replace(getattr(s, head), **{leaf: value})})
            else:
                s = replace(s, **{head: value})
        return replace(c, slam=s)

    return apply


def _range_noise(factor: float) -> Perturbation:
    def apply(c: RunConfig) -> RunConfig:
        noise = c.linefit.noise
        noise = replace(noise, sigma_range_m=noise.sigma_range_m * factor)
        return replace(c, linefit=replace(c.linefit, noise=noise))

    return apply


VARIANTS: dict[str, Perturbation] = {
    "default": lambda c: c,
    "keyframe-0.19": _slam(keyframes__min_distance_m=0.19),
    "keyframe-0.21": _slam(keyframes__min_distance_m=0.21),
    "sigma-range-2%": _range_noise(0.98),
    "sigma-range+2%": _range_noise(1.02),
    "fusion-every-9": _slam(fusion__interval_keyframes=9),
    "closing-every-4": _slam(loop_closure__interval_keyframes=4),
    "closing-every-6": _slam(loop_closure__interval_keyframes=6),
}
#: The eight draws every figure in the docs uses (``--draws 8``, the default).
EIGHT = tuple(VARIANTS)
#: Eight more of the same kind (``--draws 16``): keyframes 7.5 % and 2.5 % closer or further
#: apart, the fits' range noise 1 % lower or higher or 3 % lower, fusion every 11 keyframes.
VARIANTS.update(
    {
        "keyframe-0.185": _slam(keyframes__min_distance_m=0.185),
        "keyframe-0.195": _slam(keyframes__min_distance_m=0.195),
        "keyframe-0.205": _slam(keyframes__min_distance_m=0.205),
        "keyframe-0.215": _slam(keyframes__min_distance_m=0.215),
        "sigma-range-1%": _range_noise(0.99),
        "sigma-range+1%": _range_noise(1.01),
        "sigma-range-3%": _range_noise(0.97),
        "fusion-every-11": _slam(fusion__interval_keyframes=11),
    }
)


def relations_error(out: Path, log: str, relations_path: Path | None = None) -> tuple[float, float]:
    """Mean absolute translational (m) and rotational (deg) relations error of a run.

    The relations are ``relations_path``, else the catalogue's for ``log``.
    """
    from slam.evaluation import relations_metric, relations_within
    from slam.io.catalog import resolve_log
    from slam.io.relations import read_relations
    from slam.io.tum import read_tum

    if relations_path is None:
        resolved = resolve_log(log)
        if resolved.relations is None:
            raise SystemExit(f"{log}: no relations file in the catalogue (give --relations)")
        relations_path = Path(resolved.relations)
    trajectory = read_tum(out / "trajectory.tum")
    relations = relations_within(read_relations(relations_path), trajectory.timestamps)
    metric = relations_metric(trajectory, relations)
    return metric.abs_trans_m.mean, metric.abs_rot_deg.mean


class _VariantScore:
    """Relations error of a run on a robustness row, scored as ``scripts/robustness.py`` does."""

    def __init__(self, name: str, work: Path | None) -> None:
        from slam.experiments.robustness import default_cache_dir, make_variant, variant_by_name

        cache = work if work is not None else default_cache_dir()
        self.files = make_variant(variant_by_name(name), cache)

    def __call__(self, out: Path) -> tuple[float, float]:
        import json

        from slam.experiments.robustness import score_run
        from slam.io.tum import read_tum

        frame = json.loads((out / "summary.json").read_text(encoding="utf-8"))["frame"]
        lineslam = score_run(read_tum(out / "trajectory.tum"), frame, self.files).lineslam
        return lineslam.abs_trans_m.mean, lineslam.abs_rot_deg.mean


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", nargs="?", help="dataset name or log file")
    parser.add_argument("--row", default=None, help="a row of scripts/robustness.py instead")
    parser.add_argument("--work", type=Path, default=None, help="variant cache (with --row)")
    parser.add_argument(
        "--relations", type=Path, default=None, help="relations file (default: the catalogue's)"
    )
    parser.add_argument(
        "--variants", nargs="+", choices=sorted(VARIANTS), default=None, metavar="V"
    )
    parser.add_argument(
        "--draws",
        type=int,
        choices=(8, 16),
        default=8,
        help="the eight draws (default), or sixteen: eight more perturbations of the same kind",
    )
    parser.add_argument("--max-scans", type=int, default=None)
    parser.add_argument(
        "--keep", type=Path, default=None, help="keep each run's results folder under this"
    )
    parser.add_argument(
        "--config", type=Path, default=None, help="TOML to perturb instead of the defaults"
    )
    args = parser.parse_args()
    if (args.log is None) == (args.row is None):
        parser.error("give a log or --row NAME")
    if args.row is not None and args.relations is not None:
        parser.error("--row takes the row's own relations; drop --relations")
    if args.variants is None:
        args.variants = list(EIGHT) if args.draws == 8 else list(VARIANTS)
    score = _VariantScore(args.row, args.work) if args.row is not None else None
    log = str(score.files.log) if score is not None else args.log
    base = RunConfig() if args.config is None else RunConfig.from_toml(args.config)
    trans, rot = [], []
    print(f"{'variant':<18}{'trans (m)':>11}{'rot (deg)':>11}{'time (s)':>10}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.variants:
            out = (args.keep if args.keep is not None else Path(tmp)) / name
            config = VARIANTS[name](base)
            t0 = time.perf_counter()
            run_slam(log, out, config, max_scans=args.max_scans)
            dt = time.perf_counter() - t0
            if score is not None:
                t, r = score(out)
            else:
                t, r = relations_error(out, args.log, args.relations)
            trans.append(t)
            rot.append(r)
            print(f"{name:<18}{t:>11.4f}{r:>11.3f}{dt:>10.1f}", flush=True)
    print(
        f"over {len(trans)} runs: translation mean {np.mean(trans):.4f} m, "
        f"worst {np.max(trans):.4f} m, best {np.min(trans):.4f} m; "
        f"rotation mean {np.mean(rot):.3f} deg"
    )


if __name__ == "__main__":
    main()
