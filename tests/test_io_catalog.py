"""Dataset catalogue: entries, name/path resolution, checksum verification."""

from __future__ import annotations

import hashlib
import math

import pytest

from slam.errors import DatasetError
from slam.io import load_catalog, manifest_for_path, resolve_log, verify_dataset


def test_catalogue_has_the_three_logs_with_their_laser_facts():
    catalog = load_catalog()
    assert set(catalog) == {"intel", "aces", "fr079"}
    intel = catalog["intel"].laser_geometry()
    assert intel.n_beams == 180 and intel.step_rad == pytest.approx(math.pi / 180)
    assert intel.first_angle_rad == pytest.approx(-math.pi / 2) and intel.max_range_m == 81.83
    fr079 = catalog["fr079"]
    assert fr079.laser_geometry().step_rad == pytest.approx(math.pi / 360)
    assert fr079.laser.mount_x_m == 0.04 and not fr079.laser.mount_applied_in_log
    assert catalog["aces"].laser.max_range_m == 50.0
    assert not catalog["intel"].stamps_monotonic and catalog["intel"].backward_steps == 631
    for manifest in catalog.values():
        assert len(manifest.log_sha256) == 64 and len(manifest.relations_sha256) == 64
        assert manifest.relations_frame == "laser"  # the relations relate laser scans' poses


def test_a_relations_frame_other_than_laser_or_base_is_named(tmp_path):
    entry = tmp_path / "catalog.toml"
    entry.write_text(
        'schema = 1\n[datasets.x]\ntitle = "x"\nlog = "x.clf"\nlog_sha256 = ""\n'
        'relations_frame = "robot"\n[datasets.x.laser]\nbeams = 180\nfirst_angle_deg = -90.0\n'
        "step_deg = 1.0\nmax_range_m = 80.0\n"
    )
    with pytest.raises(DatasetError, match=r"\[datasets.x\]: relations_frame: 'robot' is not"):
        load_catalog(entry)


def fake_root(tmp_path):
    (tmp_path / "aces").mkdir()
    (tmp_path / "aces" / "aces.clf").write_text("ODOM 0 0 0 0 0 0 1.0 nohost 1.0\n")
    (tmp_path / "aces" / "aces.relations").write_text("1 2 0 0 0 0 0 0\n")
    return tmp_path


def test_resolve_by_name_under_lineslam_data(tmp_path, monkeypatch):
    root = fake_root(tmp_path)
    monkeypatch.setenv("LINESLAM_DATA", str(root))
    log = resolve_log("aces")
    assert log.log == root / "aces" / "aces.clf"
    assert log.relations == root / "aces" / "aces.relations"
    assert log.manifest is not None and log.manifest.name == "aces" and log.name == "aces"
    with pytest.raises(DatasetError, match=r"dataset 'intel': .*intel.clf not found"):
        resolve_log("intel")
    with pytest.raises(DatasetError, match="neither an existing file nor a registered"):
        resolve_log("nonesuch")


def test_resolve_a_path_as_is(tmp_path, monkeypatch):
    monkeypatch.setenv("LINESLAM_DATA", str(tmp_path / "elsewhere"))
    root = fake_root(tmp_path)
    log = resolve_log(root / "aces" / "aces.clf")  # ACES by name, not by content
    assert log.manifest is None and log.relations is None and log.name == "aces"
    other = tmp_path / "mine.clf"
    other.write_text("ODOM 0 0 0 0 0 0 1.0\n")
    log = resolve_log(str(other))
    assert log.manifest is None and log.relations is None and log.name == "mine"
    assert manifest_for_path("x/fr079.relations") is None  # no such file: not recognised


def test_a_log_is_recognised_by_content_not_by_name(tmp_path, monkeypatch):
    """A renamed copy of a catalogued log keeps its entry; another file under the name does not."""
    from dataclasses import replace

    from slam.io import catalog

    data = b"ODOM 0 0 0 0 0 0 1.0\n"
    entry = replace(
        load_catalog()["aces"], log_bytes=len(data), log_sha256=hashlib.sha256(data).hexdigest()
    )
    monkeypatch.setattr(catalog, "load_catalog", lambda path=None: {"aces": entry})
    renamed = tmp_path / "my_copy.clf"
    renamed.write_bytes(data)
    assert manifest_for_path(renamed) is not None and resolve_log(renamed).name == "aces"
    impostor = tmp_path / "aces.clf"
    impostor.write_bytes(b"ODOM 1 0 0 0 0 0 1.0\n")  # same size, other content
    assert manifest_for_path(impostor) is None and resolve_log(impostor).manifest is None


def test_verify_detects_missing_and_altered_files(tmp_path):
    root = fake_root(tmp_path)
    catalog = load_catalog()
    status = verify_dataset(catalog["intel"], root)
    assert not status.present and status.intact is None
    status = verify_dataset(catalog["aces"], root)
    assert status.present and status.intact is False
    assert any("bytes" in p for p in status.problems)


def test_verify_accepts_a_file_matching_its_checksum(tmp_path, monkeypatch):
    from dataclasses import replace

    root = fake_root(tmp_path)
    manifest = load_catalog()["aces"]
    data = (root / "aces" / "aces.clf").read_bytes()
    rel = (root / "aces" / "aces.relations").read_bytes()
    manifest = replace(
        manifest,
        log_bytes=len(data),
        log_sha256=hashlib.sha256(data).hexdigest(),
        relations_bytes=len(rel),
        relations_sha256=hashlib.sha256(rel).hexdigest(),
    )
    assert verify_dataset(manifest, root).intact is True
    (root / "aces" / "aces.clf").write_bytes(data.replace(b"1.0", b"2.0"))
    status = verify_dataset(manifest, root)
    assert status.intact is False and "sha256" in status.problems[0]
