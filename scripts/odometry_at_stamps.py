"""A CARMEN log as a bag converter would write it: scans in stamp order, odometry at the stamps.

Usage::

    python scripts/odometry_at_stamps.py LOG --out DIR

``LOG`` is a CARMEN file (or catalogued name) with ``FLASER`` lines and ``ODOM`` messages.
Two logs are written to ``DIR``:

* ``sorted.clf``: the ``FLASER`` lines (and the ``PARAM``/comment lines) in the order of their
  ``ipc_timestamp`` (stable), each with the odometry logged with it;
* ``interpolated.clf``: the same, each scan's odometry (``x y theta`` and ``odom_x odom_y
  odom_theta``) replaced by the ``ODOM`` messages' poses interpolated at its ``ipc_timestamp``
  (linear in x and y and in the unwrapped heading), as :mod:`slam.io.rosbag` gives a scan its
  odometry from a bag's odometry topic.

Time stamps and ranges are unchanged, so the log's relations score both.  Where the stamps are
jittered against the moment each scan was taken (Intel's go back 631 times, by up to 0.9 s),
the odometry logged with a scan and the odometry at its stamp differ: comparing runs of the
two logs measures what that costs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from slam.io.catalog import resolve_log


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", help="CARMEN log file or catalogued name")
    ap.add_argument("--out", type=Path, required=True, help="folder for the two logs")
    args = ap.parse_args()
    path = resolve_log(args.log).log
    head: list[str] = []
    scans: list[list[str]] = []
    odom: list[list[str]] = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            tokens = line.split()
            if not tokens:
                continue
            if tokens[0] == "FLASER":
                scans.append(tokens)
            elif tokens[0] == "ODOM":
                odom.append(tokens)
            elif tokens[0] == "PARAM" or line.startswith("#"):
                head.append(line.rstrip("\n"))
    if not scans or len(odom) < 2:
        raise SystemExit(f"{path}: needs FLASER lines and at least two ODOM messages")
    stamps = np.array([float(t[-3]) for t in scans])
    order = np.argsort(stamps, kind="stable")
    o_stamps = np.array([float(t[-3]) for t in odom])
    o_order = np.argsort(o_stamps, kind="stable")
    o_stamps = o_stamps[o_order]
    o_pose = np.array([[float(v) for v in odom[i][1:4]] for i in o_order])
    o_pose[:, 2] = np.unwrap(o_pose[:, 2])

    args.out.mkdir(parents=True, exist_ok=True)

    def write(name: str, rows: list[list[str]]) -> None:
        with open(args.out / name, "w", encoding="utf-8") as f:
            for line in head:
                f.write(line + "\n")
            for tokens in rows:
                f.write(" ".join(tokens) + "\n")

    write("sorted.clf", [scans[i] for i in order])
    rows = []
    for i in order:
        tokens = list(scans[i])
        n = int(tokens[1])
        x, y, th = (float(np.interp(stamps[i], o_stamps, o_pose[:, k])) for k in range(3))
        th = (th + np.pi) % (2.0 * np.pi) - np.pi
        pose = [f"{x:.6f}", f"{y:.6f}", f"{th:.6f}"]
        tokens[2 + n : 5 + n] = pose
        tokens[5 + n : 8 + n] = pose
        rows.append(tokens)
    write("interpolated.clf", rows)
    moved = int(np.count_nonzero(order != np.arange(order.size)))
    print(f"{path}: {len(scans)} scans ({moved} moved by sorting), {len(odom)} ODOM messages")
    print(f"wrote {args.out / 'sorted.clf'} and {args.out / 'interpolated.clf'}")


if __name__ == "__main__":
    main()
