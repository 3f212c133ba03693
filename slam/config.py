"""The configuration of a whole run: one frozen dataclass with one table per component.

``config.toml`` in every results folder is this dataclass dumped to TOML; ``--config FILE``
loads it back.  Each component owns its own table (``[scanner]``, ``[linefit]``, ``[map]``,
``[slam]``, ...); missing tables take their defaults, unknown keys are an error.

Older files: the input keys that used to be in ``[slam]`` (``pose_base_laser``,
``mount_source``, ``laser_odometry``, ``output_frame``, ``odometry_sign``) are moved to
``[scanner]`` on loading (:func:`slam.inputs.migrate_slam_keys`: an old default value is
dropped, any other value keeps its meaning).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace
from pathlib import Path

from linefit.config import LineFitConfig
from linefit.errors import ConfigError
from linefit.tomlconfig import config_from_dict, dump_toml
from slam.ekf.config import EkfConfig
from slam.inputs import LogInput, ScannerConfig, migrate_slam_keys, open_log
from slam.line_slam.config import SlamConfig
from slam.lines.config import MapConfig

__all__ = ["RunConfig", "check_run_config", "open_run_log"]


@dataclass(frozen=True)
class RunConfig:
    """Everything a ``lineslam`` command needs to reproduce its results.

    Attributes
    ----------
    seed : int
        Seed of every random choice of the run.
    scanner : ScannerConfig
        The log's scanner (beam geometry, range limits), laser mounting, odometry and the
        reported frame (:mod:`slam.inputs`).
    linefit : LineFitConfig
        Per-scan line extraction.
    map : MapConfig
        Merging lines across poses (``lineslam map``; paper Sec. V).
    slam : SlamConfig
        Factor-graph SLAM (``lineslam slam``): back-end, motion noise, keyframes,
        association, fusion, solver.
    ekf : EkfConfig
        EKF-SLAM baseline (``lineslam ekf``).
    """

    seed: int = 0
    scanner: ScannerConfig = field(default_factory=ScannerConfig)
    linefit: LineFitConfig = field(default_factory=LineFitConfig)
    map: MapConfig = field(default_factory=MapConfig)
    slam: SlamConfig = field(default_factory=SlamConfig)
    ekf: EkfConfig = field(default_factory=EkfConfig)

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral):
            raise ConfigError(f"seed must be a whole number, got {self.seed!r}")
        if self.seed < 0:
            raise ConfigError(f"seed must be >= 0, got {self.seed}")
        for name, kind in (
            ("scanner", ScannerConfig),
            ("linefit", LineFitConfig),
            ("map", MapConfig),
            ("slam", SlamConfig),
            ("ekf", EkfConfig),
        ):
            value = getattr(self, name)
            if not isinstance(value, kind):
                raise ConfigError(
                    f"RunConfig.{name} must be a {kind.__name__}, got {type(value).__name__}"
                )

    @classmethod
    def from_toml(cls, path: str | Path) -> RunConfig:
        """Load a run configuration (:meth:`to_toml`'s, hand-written, or an older version's)."""
        import tomllib

        path = Path(path)
        try:
            with path.open("rb") as handle:
                data = tomllib.load(handle)
        except FileNotFoundError as exc:
            raise ConfigError(f"{path}: configuration file not found") from exc
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not valid TOML ({exc})") from exc
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{path}: not a text file") from exc
        try:
            return config_from_dict(cls, migrate_slam_keys(data))
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from exc

    def to_toml(self, path: str | Path) -> None:
        """Write the full configuration (every value, defaults included) to ``path``."""
        dump_toml(self, path, header="lineslam run configuration; reload with --config")

    def with_sensor_noise(
        self, sigma_d: float | None = None, sigma_phi: float | None = None
    ) -> RunConfig:
        """Return a copy with the sensor noise (``--sigma-d``, ``--sigma-phi``) overridden."""
        noise = self.linefit.noise
        noise = replace(
            noise,
            sigma_range_m=noise.sigma_range_m if sigma_d is None else sigma_d,
            sigma_bearing_rad=noise.sigma_bearing_rad if sigma_phi is None else sigma_phi,
        )
        return replace(self, linefit=replace(self.linefit, noise=noise))


def check_run_config(config: object, name: str = "config") -> RunConfig:
    """``config`` if it is a :class:`RunConfig`, else a :class:`ConfigError` naming ``name``."""
    if not isinstance(config, RunConfig):
        raise ConfigError(f"{name} must be a RunConfig, got {type(config).__name__}")
    return config


def open_run_log(log: str | Path, config: RunConfig, *, max_scans: int | None = None) -> LogInput:
    """Open ``log`` as a run with ``config`` reads it (:func:`slam.inputs.open_log`).

    Its ``[scanner]`` settings, and for a log whose motion comes from its scans the laser
    odometry's points with the run's sensor noise (``[linefit.noise]``) and its matcher with
    the run's scan-matcher settings (``[slam.frontend.scan_matching]``).
    """
    return open_log(
        log,
        config.scanner,
        max_scans=max_scans,
        noise=config.linefit.noise,
        matching=config.slam.frontend.scan_matching,
    )
