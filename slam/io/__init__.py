"""Reading and writing: CARMEN logs, TUM trajectories, relations, the dataset catalogue.

Main entry points::

    from slam.io import iter_scans, resolve_log, write_tum, write_relations

    log = resolve_log("intel")                  # or a path; .log, .relations, .manifest
    for scan in iter_scans(log.log):            # streaming, file order
        ...
    write_tum("trajectory.tum", stamps, poses)  # poses (n, 3) = (x, y, θ)

See each module's docstring for formats and the handling of bad input.
"""

from slam.io.carmen import (
    LASER_MESSAGES,
    CarmenReader,
    CarmenStats,
    Odometry,
    iter_odometry,
    iter_scans,
    scan_trajectory,
)
from slam.io.catalog import (
    DatasetManifest,
    DatasetStatus,
    ResolvedLog,
    data_root,
    load_catalog,
    manifest_for_path,
    resolve_log,
    verify_dataset,
)
from slam.io.g2o import PoseGraph2D, odometry_pose_graph, read_g2o, write_g2o
from slam.io.geojson import line_map_to_geojson, write_geojson
from slam.io.laser import LaserGeometry, guess_laser_geometry
from slam.io.relations import (
    Relations,
    read_relations,
    relations_from_trajectory,
    write_relations,
)
from slam.io.results import (
    Results,
    read_results,
    to_jsonable,
    write_metrics,
    write_results,
    write_summary,
    write_trajectory,
)
from slam.io.rosbag import iter_rosbag_scans, read_rosbag_odometry
from slam.io.trajectory import Trajectory
from slam.io.tum import read_ground_truth, read_tum, write_tum

__all__ = [
    "LASER_MESSAGES",
    "CarmenReader",
    "CarmenStats",
    "DatasetManifest",
    "DatasetStatus",
    "LaserGeometry",
    "Odometry",
    "PoseGraph2D",
    "Relations",
    "ResolvedLog",
    "Results",
    "Trajectory",
    "data_root",
    "guess_laser_geometry",
    "iter_odometry",
    "iter_rosbag_scans",
    "iter_scans",
    "line_map_to_geojson",
    "load_catalog",
    "manifest_for_path",
    "odometry_pose_graph",
    "read_g2o",
    "read_ground_truth",
    "read_relations",
    "read_results",
    "read_rosbag_odometry",
    "read_tum",
    "relations_from_trajectory",
    "resolve_log",
    "scan_trajectory",
    "to_jsonable",
    "verify_dataset",
    "write_g2o",
    "write_geojson",
    "write_metrics",
    "write_relations",
    "write_results",
    "write_summary",
    "write_trajectory",
    "write_tum",
]
