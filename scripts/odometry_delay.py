"""Is a log's odometry out of step with its scans?  The delay, estimated without a SLAM run.

Reads the log as ``lineslam slam`` does (``--config``: a run's ``config.toml``, its
``[scanner]`` table; the default otherwise) and estimates how many scans late the odometry a
scan carries is (:func:`slam.frontend.odometry_delay.estimate_odometry_delay`: the scans' own
rotation from one scan to the next at the log's first turns against the odometry's heading
read ``λ`` scans later).  Prints the estimate, its standard deviation, the same in seconds,
the pairs of scans it used and its likelihood ratio against no delay, with whether
``[scanner] odometry_delay = "estimated"`` would apply it (beyond χ²₁'s 99 % point).
``--json FILE`` writes the same numbers.

    python scripts/odometry_delay.py fr079
    python scripts/odometry_delay.py my_log.clf --config results/my_log/config.toml
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

from slam import blas as _blas  # noqa: F401  # isort: skip  (before numpy: slam.blas)

from slam.config import RunConfig, open_run_log
from slam.frontend.odometry_delay import estimate_odometry_delay
from slam.inputs import DELAY_CHI2_99


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("log", help="log file, bag or dataset name")
    ap.add_argument("--config", type=Path, default=None, help="a run's config.toml")
    ap.add_argument("--max-pairs", type=int, default=300, help="turning pairs to use")
    ap.add_argument("--json", type=Path, default=None, help="write the numbers here")
    args = ap.parse_args(argv)
    config = RunConfig() if args.config is None else RunConfig.from_toml(args.config)
    # the poses as logged: the delay is what is being estimated
    scanner = replace(config.scanner, odometry_delay="off", odometry_delay_scans=None)
    config = replace(config, scanner=scanner)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the log's own warnings belong to a run
        source = open_run_log(args.log, config)
        c0 = time.process_time()
        estimate = estimate_odometry_delay(
            source.scans(), source.noise, source.matching, max_pairs=args.max_pairs
        )
        cpu = time.process_time() - c0
    out: dict[str, object] = {"log": str(source.log), "cpu_s": cpu}
    if estimate is None:
        print(f"{source.log}: no estimate (too few turns, or the scans turn against the odometry)")
        out["estimate"] = None
    else:
        applied = estimate.chi2 > DELAY_CHI2_99
        seconds = "" if estimate.seconds is None else f" ({estimate.seconds:+.3f} s)"
        print(
            f"{source.log}: odometry {estimate.scans:+.3f} ± {estimate.sd_scans:.3f} scans late"
            f"{seconds}; {estimate.pairs} turning pairs; χ² against none {estimate.chi2:.1f}"
            f' ({"applied" if applied else "not applied"} with odometry_delay = "estimated");'
            f" {cpu:.1f} s CPU"
        )
        out["estimate"] = estimate.to_dict()
        out["applied_when_estimated"] = applied
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
