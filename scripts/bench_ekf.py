"""EKF-SLAM cost per scan against the number of landmarks (printed table).

For each map size M a synthetic filter state (pose + M line landmarks with a dense, positive
definite covariance, as after a loop closure) is timed on the steps of one scan:
prediction (O(M)), association of K scan lines (χ² gate against all landmarks + NN), the
Joseph-form update with m matched lines (sparse O(M² m), and filterpy's dense O(M³) update
side by side where it is affordable), augmentation with one new landmark (O(M²) copy).

Usage: python scripts/bench_ekf.py [--sizes 50 100 200 500 1000 2000] [--lines 10] [--repeat 5]

BLAS runs single-threaded unless OPENBLAS_NUM_THREADS / OMP_NUM_THREADS are set: on a shared
2-core machine multi-threaded BLAS on these small matrices gives erratic timings.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import timeit  # noqa: E402

import numpy as np  # noqa: E402

from slam.association import AssociationConfig  # noqa: E402
from slam.ekf import EkfConfig, EkfSlam  # noqa: E402
from slam.ekf.augment import augment_state  # noqa: E402
from slam.ekf.update import filterpy_update, joseph_update, line_measurements  # noqa: E402
from slam.geometry import predict_line_measurement  # noqa: E402
from slam.lines.lineset import LineSet  # noqa: E402


def make_state(M: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    n = 3 + 2 * M
    x = np.concatenate(
        [[0.0, 0.0, 0.1], np.column_stack([rng.uniform(1, 6, M), rng.uniform(-3, 3, M)]).ravel()]
    )
    A = rng.standard_normal((n, 20)) * 0.01
    P = A @ A.T + np.diag(np.full(n, 1e-4))
    return x, P


def best_of(fn, repeat: int) -> float:
    return min(timeit.repeat(fn, number=1, repeat=repeat))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[50, 100, 200, 500, 1000, 2000])
    ap.add_argument("--lines", type=int, default=10, help="matched lines per update (m)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--filterpy-max", type=int, default=500, help="largest M for filterpy")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    m = args.lines
    threads = os.environ.get("OPENBLAS_NUM_THREADS")
    print(
        f"EKF cost per scan: m = {m} matched lines, K = {m + 2} scan lines, "
        f"best of {args.repeat}, BLAS threads = {threads}"
    )
    head = (
        f"{'M':>6} {'n':>6} {'predict ms':>11} {'assoc ms':>9} {'update ms':>10} "
        f"{'filterpy ms':>12} {'ratio':>7} {'augment ms':>11} {'scan ms':>9}"
    )
    print(head)
    print("-" * len(head))
    rows = []
    for M in args.sizes:
        x, P = make_state(M, rng)
        idx = rng.choice(M, size=m, replace=False)
        lm = x[3:].reshape(M, 2)[idx]
        z, _, _ = predict_line_measurement(lm, x[:3])
        z = z + rng.normal(0, 0.005, z.shape)
        R = np.stack([np.diag([1e-4, 1e-5])] * m)
        ekf = EkfSlam(
            EkfConfig(association=AssociationConfig(overlap_margin_m=1e9), merge_landmarks=False)
        )
        ekf.set_state(x, P)
        lines = LineSet(
            np.vstack([z, [[0.5, 0.3], [7.0, -2.0]]]),
            np.concatenate([R, R[:2]]),
            np.zeros((m + 2, 2, 2)),
            np.arange(m + 2),
        )

        def predict(ekf=ekf):
            ekf.predict(np.array([0.1, 0.0, 0.01]))

        t_pred = best_of(predict, args.repeat)
        t_assoc = best_of(lambda ekf=ekf, lines=lines: ekf.associate(lines), args.repeat)
        meas = line_measurements(x, idx, z, R)
        t_upd = best_of(lambda x=x, P=P, meas=meas: joseph_update(x, P, meas), args.repeat)
        if args.filterpy_max >= M:
            t_fp = best_of(
                lambda x=x, P=P, idx=idx, z=z, R=R: filterpy_update(x, P, idx, z, R),
                max(1, args.repeat // 2),
            )
        else:
            t_fp = float("nan")
        t_aug = best_of(
            lambda x=x, P=P, z1=z[:1], R1=R[:1]: augment_state(x, P, z1, R1), args.repeat
        )
        t_scan = t_pred + t_assoc + t_upd + t_aug
        rows.append((M, t_scan))
        ratio = t_fp / t_upd if math.isfinite(t_fp) else float("nan")
        print(
            f"{M:>6} {3 + 2 * M:>6} {t_pred * 1e3:>11.3f} {t_assoc * 1e3:>9.3f} "
            f"{t_upd * 1e3:>10.3f} {t_fp * 1e3:>12.3f} {ratio:>7.1f} {t_aug * 1e3:>11.3f} "
            f"{t_scan * 1e3:>9.3f}"
        )
    if len(rows) >= 2:
        Ms = np.array([r[0] for r in rows[-3:]], dtype=float)
        ts = np.array([r[1] for r in rows[-3:]])
        slope = np.polyfit(np.log(Ms), np.log(ts), 1)[0]
        print(f"\nscan cost grows as M^{slope:.2f} over the largest sizes (O(M^2) expected)")
        print("'ratio' = filterpy's dense update / the sparse Joseph update, same numbers")


if __name__ == "__main__":
    main()
