"""Builders of CARMEN log lines for tests (the format of slam.io.carmen's docstring)."""

from __future__ import annotations

from collections.abc import Sequence


def _f(values: Sequence[float]) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def flaser(ranges, pose_laser, pose_base, t: float, kind: str = "FLASER") -> str:
    return (
        f"{kind} {len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} {_f(pose_laser)} "
        f"{_f(pose_base)} {t:.6f} nohost {t:.6f}"
    )


def odom(pose, t: float, tv: float = 0.1, rv: float = 0.01) -> str:
    return f"ODOM {_f(pose)} {tv:.6f} {rv:.6f} 0.000000 {t:.6f} nohost {t:.6f}"


def robotlaser(ranges, start, res, max_range, pose_laser, pose_base, t, remissions=()) -> str:
    rem = f"{len(remissions)}" + "".join(f" {v:.2f}" for v in remissions)
    return (
        f"ROBOTLASER1 0 {start:.6f} {res * len(ranges):.6f} {res:.6f} {max_range:.2f} 0.01 0 "
        f"{len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} {rem} {_f(pose_laser)} "
        f"{_f(pose_base)} 0 0 0 0 0 {t:.6f} nohost {t:.6f}"
    )


def rawlaser(ranges, start, res, max_range, t, kind="RAWLASER1") -> str:
    return (
        f"{kind} 0 {start:.6f} {res * len(ranges):.6f} {res:.6f} {max_range:.2f} 0.01 0 "
        f"{len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} 0 {t:.6f} nohost {t:.6f}"
    )
