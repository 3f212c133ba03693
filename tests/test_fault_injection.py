"""Fault injection: signals, read-only targets, a full disk, concurrent runs, a killed run.

Each test proves that nothing is lost or half-written: after a fault the target is either
absent, unchanged (an earlier results folder or file, byte for byte) or, when the run won,
one run's complete results; no temporary ``.NAME.partial-*`` is left behind (except after
``SIGKILL``, where the next run removes it).

The signal tests run ``python -m slam`` as real processes, wait until the run has started (its
temporary folder or file appears beside the target), wait a random (seeded) moment more, send
the signal, and check the exit status (130 for SIGINT, 143 for SIGTERM), the one line saying
so, and the target.  The only time bound is the generous "stops within a few seconds" (the
stop times themselves are measured by ``scripts/bench_interrupt.py``).  Signals are recorded
and acted on at the run's next check (``slam.interrupts``), never inside compiled code: a
signal during the first compiled extraction (numba loading or compiling its code) is tested
by sending it from inside numba's object-cache callback.
"""

from __future__ import annotations

import errno
import hashlib
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT

from slam.cli import main
from slam.io import atomic
from slam.io.atomic import PARTIAL_MARK, staged_dir

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"
STOP_WITHIN_S = 10.0  # generous: a loaded two-core machine


def run_cli(args, capsys):
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def snapshot(path: Path) -> dict[str, str]:
    """Every file under ``path`` (or ``path`` itself) by relative name → sha256."""
    if path.is_file():
        return {path.name: hashlib.sha256(path.read_bytes()).hexdigest()}
    return {
        str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if PARTIAL_MARK in p.name)


def env() -> dict[str, str]:
    out = dict(os.environ)
    out["PYTHONPATH"] = str(REPO_ROOT) + os.pathsep + out.get("PYTHONPATH", "")
    out.setdefault("MPLBACKEND", "Agg")
    return out


@pytest.fixture(scope="module")
def long_log(tmp_path_factory) -> Path:
    """The demo log twelve times over (each copy 1000 s later): runs of ten seconds or more."""
    lines = DEMO_LOG.read_text().splitlines()
    out = []
    for k in range(12):
        for line in lines:
            tokens = line.split()
            if tokens and tokens[0] in ("FLASER", "ODOM"):
                tokens[-3] = f"{float(tokens[-3]) + 1000.0 * k:.6f}"
                tokens[-1] = f"{float(tokens[-1]) + 1000.0 * k:.6f}"
                line = " ".join(tokens)
            elif k:
                continue
            out.append(line)
    path = tmp_path_factory.mktemp("long") / "long.clf"
    path.write_text("\n".join(out) + "\n")
    return path


@pytest.fixture(scope="module")
def earlier(tmp_path_factory) -> Path:
    """A complete earlier results folder of ``lineslam slam`` (25 scans of the demo)."""
    folder = tmp_path_factory.mktemp("earlier") / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "slam", "slam", str(DEMO_LOG), "--out", str(folder)]
        + ["--max-scans", "25", "--quiet"],
        env=env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    return folder


def copy_tree(source: Path, dest: Path) -> None:
    import shutil

    shutil.copytree(source, dest)


def wait_for_partial(parent: Path, name: str, proc: subprocess.Popen, timeout: float = 120.0):
    """Wait until ``.NAME.partial-*`` appears in ``parent`` (the run has started)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if any(p.name.startswith(f".{name}{PARTIAL_MARK}") for p in parent.iterdir()):
            return
        if proc.poll() is not None:
            _, err = proc.communicate()
            pytest.fail(f"the run ended before it started writing ({proc.returncode}): {err}")
        time.sleep(0.02)
    proc.kill()
    pytest.fail("the run did not start within the timeout")


SIGNAL_CASES = [
    # (command, signal, earlier results at the target?)
    ("slam-batch", signal.SIGINT, False),
    ("slam-batch", signal.SIGTERM, True),
    ("ekf", signal.SIGINT, True),
    ("map", signal.SIGTERM, False),
    ("extract", signal.SIGINT, True),
    ("extract", signal.SIGTERM, False),
]


def command(kind: str, log: Path, target: Path) -> list[str]:
    base = [sys.executable, "-m", "slam"]
    if kind == "slam-batch":
        return [*base, "slam", str(log), "--out", str(target), "--backend", "batch"]
    if kind == "extract":
        return [*base, "extract", str(log), "--out", str(target)]
    return [*base, kind, str(log), "--out", str(target)]


@pytest.mark.parametrize(("kind", "signum", "with_earlier"), SIGNAL_CASES)
def test_signal_stops_the_run_cleanly(tmp_path, long_log, earlier, kind, signum, with_earlier):
    rng = np.random.default_rng([int(signum), len(kind), int(with_earlier)])
    if kind == "extract":
        target = tmp_path / "lines.jsonl"
        config = tmp_path / "lines.config.toml"
        if with_earlier:
            target.write_text('{"scan": 0, "t": 1.0, "lines": []}\n')
            config.write_text("# lineslam run configuration; reload with --config\nseed = 3\n")
    else:
        target = tmp_path / "run"
        config = target / "config.toml"
        if with_earlier:
            copy_tree(earlier, target)
    before = snapshot(target) if with_earlier else None
    before_config = snapshot(config) if with_earlier else None
    proc = subprocess.Popen(
        command(kind, long_log, target),
        env=env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for_partial(tmp_path, target.name, proc)
    time.sleep(float(rng.uniform(0.0, 1.0)))  # a random point of the run
    assert proc.poll() is None, "the run ended before the signal (the log is too short)"
    proc.send_signal(signum)
    t_signal = time.monotonic()
    try:
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    stopped_after = time.monotonic() - t_signal
    assert proc.returncode == 128 + signum, err
    assert stopped_after < STOP_WITHIN_S
    last = err.strip().splitlines()[-1]
    assert last.startswith("lineslam: interrupted (") and signal.Signals(signum).name in last
    assert "nothing written" in last
    if with_earlier:
        assert snapshot(target) == before
        assert snapshot(config) == before_config
    else:
        assert not target.exists() and not config.exists()
    assert leftovers(tmp_path) == []


# Runs lineslam with numba's object-cache hook (called by LLVM, through a ctypes callback,
# while numba loads or compiles the kernel's machine code) patched to send the process SIGINT,
# COUNT times, the first time it is called: the signal arrives inside compiled code's loading.
SIGNAL_IN_FIRST_KERNEL_CALL = """
import os, signal, sys
from numba.core.codegen import JITCodeLibrary

original = JITCodeLibrary._object_getbuffer_hook.__func__
sent = []

def getbuffer(cls, ll_module):
    if not sent:
        sent.append(1)
        for _ in range({count}):
            os.kill(os.getpid(), signal.SIGINT)
    return original(cls, ll_module)

JITCodeLibrary._object_getbuffer_hook = classmethod(getbuffer)
from slam.cli import main
main(sys.argv[1:])
"""


WARM_UP = (
    "import numpy as np; from linefit import extract_lines; "
    "extract_lines(np.full(61, 3.0), np.linspace(-1.5, 1.5, 61))"
)


@pytest.mark.parametrize(
    ("kind", "cache", "count"),
    [("extract", "warm", 1), ("slam-batch", "warm", 2), ("extract", "cold", 1)],
)
def test_signal_in_the_first_compiled_extraction(tmp_path, kind, cache, count):
    """A signal while numba loads (warm cache) or compiles (cold) the kernel: 130, nothing left.

    The kernel is loaded off the main thread (``slam.extraction.ensure_kernel``): the run stops
    at once, not after the loading or the compilation (about 30 s), and no exception is raised
    inside numba (no "Exception ignored" line, no crash).  Two signals: the second raises at
    once, still outside numba.
    """
    target = tmp_path / ("lines.jsonl" if kind == "extract" else "run")
    run_env = env()
    if cache == "cold":
        run_env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")  # empty: numba compiles
    else:  # the kernel is in numba's cache (compiled here if not yet)
        subprocess.run(
            [sys.executable, "-c", WARM_UP],
            env=run_env,
            check=True,
            timeout=600,
        )
    script = SIGNAL_IN_FIRST_KERNEL_CALL.format(count=count)
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-c", script, *command(kind, DEMO_LOG, target)[3:], "--quiet"],
        env=run_env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    took = time.monotonic() - t0
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.splitlines() == [
        "lineslam: interrupted (SIGINT); nothing written, earlier results unchanged"
    ]
    assert took < STOP_WITHIN_S + 10.0  # the start-up included; a compilation takes ~30 s more
    assert not target.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name != "numba-cache"] == []


def test_sigint_stops_a_parallel_compare(tmp_path):
    target = tmp_path / "cmp"
    proc = subprocess.Popen(
        [sys.executable, "-m", "slam", "compare", str(DEMO_LOG), "--out", str(target)]
        + ["--workers", "2", "--variants", "graph-isam2,ekf,graph-batch", "--no-figures"],
        env=env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for_partial(tmp_path, "cmp", proc)
    time.sleep(3.0)  # the cluster is up or starting
    proc.send_signal(signal.SIGINT)
    t_signal = time.monotonic()
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert time.monotonic() - t_signal < STOP_WITHIN_S
    assert err.strip().splitlines()[-1].startswith("lineslam: interrupted (SIGINT)")
    assert "CancelledError" not in err and "Traceback" not in err
    assert not target.exists() and leftovers(tmp_path) == []


def test_sigkill_leaves_the_target_and_the_next_run_cleans_up(tmp_path, long_log, earlier):
    target = tmp_path / "run"
    copy_tree(earlier, target)
    before = snapshot(target)
    proc = subprocess.Popen(
        command("slam-batch", long_log, target),
        env=env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    wait_for_partial(tmp_path, "run", proc)
    time.sleep(0.5)
    proc.kill()
    proc.wait(timeout=60)
    assert snapshot(target) == before
    stale = leftovers(tmp_path)
    assert len(stale) == 1 and stale[0].startswith(f".run{PARTIAL_MARK}{proc.pid}-")
    proc = subprocess.run(
        [sys.executable, "-m", "slam", "slam", str(DEMO_LOG), "--out", str(target)]
        + ["--max-scans", "10", "--quiet"],
        env=env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert leftovers(tmp_path) == []
    assert json.loads((target / "summary.json").read_text())["scans"] == 10


# ---------------------------------------------------------------------------------------------
# full disk, read-only target
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("failing", ["trajectory", "map", "summary", "config"])
def test_full_disk_leaves_the_earlier_folder(tmp_path, capsys, monkeypatch, earlier, failing):
    target = tmp_path / "run"
    copy_tree(earlier, target)
    before = snapshot(target)
    full = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def no_space(*args, **kwargs):
        raise full

    if failing == "trajectory":
        monkeypatch.setattr("slam.io.results.write_tum", no_space)
    elif failing == "map":
        monkeypatch.setattr("slam.lines.mapio.write_map_json", no_space)
    elif failing == "summary":
        monkeypatch.setattr("slam.io.results.write_summary", no_space)
    else:
        monkeypatch.setattr("slam.config.RunConfig.to_toml", no_space)
    code, _, err = run_cli(
        ["slam", DEMO_LOG, "--out", target, "--max-scans", "20", "--quiet"], capsys
    )
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("lineslam: error: ")
    assert str(target) in err and "No space left on device" in err
    assert snapshot(target) == before
    assert leftovers(tmp_path) == []


def test_full_disk_during_extract_keeps_the_earlier_file(tmp_path, capsys, monkeypatch):
    target = tmp_path / "lines.jsonl"
    target.write_text("earlier\n")
    import slam.cli.cmd_extract as cmd_extract

    calls = {"n": 0}
    original = cmd_extract.scan_record

    def fill_up(scan, lines):
        calls["n"] += 1
        if calls["n"] > 100:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return original(scan, lines)

    monkeypatch.setattr(cmd_extract, "scan_record", fill_up)
    code, _, err = run_cli(["extract", DEMO_LOG, "--out", target, "--quiet"], capsys)
    assert code == 2 and err.count("\n") == 1 and "No space left on device" in err
    assert target.read_text() == "earlier\n"
    assert not (tmp_path / "lines.config.toml").exists()
    assert leftovers(tmp_path) == []


def _without_privileges() -> list[str]:
    """A command prefix under which file modes apply (root ignores them otherwise)."""
    if os.geteuid() != 0:
        return []
    import shutil

    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: a read-only folder cannot be made")
    return ["setpriv", "--bounding-set=-all", "--inh-caps=-all", "--"]


@pytest.mark.parametrize("existing", [False, True])
def test_read_only_target_is_one_line_and_nothing_changes(tmp_path, earlier, existing):
    parent = tmp_path / "ro"
    parent.mkdir()
    target = parent / "run"
    if existing:
        copy_tree(earlier, target)
    before = snapshot(parent)
    parent.chmod(0o555)
    try:
        proc = subprocess.run(
            [*_without_privileges(), sys.executable, "-m", "slam", "slam", str(DEMO_LOG)]
            + ["--out", str(target), "--max-scans", "10", "--quiet"],
            env=env(),
            capture_output=True,
            text=True,
            timeout=300,
        )
    finally:
        parent.chmod(0o755)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("lineslam: error: ")
    assert str(target) in proc.stderr
    assert snapshot(parent) == before
    assert leftovers(parent) == []


# ---------------------------------------------------------------------------------------------
# two runs into the same folder at once
# ---------------------------------------------------------------------------------------------
def test_two_runs_into_one_folder_leave_one_whole(tmp_path, capsys):
    """``slam`` and ``ekf`` into the same folder at once: it holds one run's files, whole."""
    refs = {}
    for kind in ("slam", "ekf"):
        ref = tmp_path / f"ref-{kind}"
        code, _, err = run_cli(
            [kind, DEMO_LOG, "--out", ref, "--max-scans", "60", "--quiet"], capsys
        )
        assert code == 0, err
        refs[kind] = ref
    target = tmp_path / "shared"
    for _ in range(1):
        procs = [
            subprocess.Popen(
                [sys.executable, "-m", "slam", kind, str(DEMO_LOG), "--out", str(target)]
                + ["--max-scans", "60", "--quiet"],
                env=env(),
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for kind in ("slam", "ekf")
        ]
        for p in procs:
            _, err = p.communicate(timeout=300)
            assert p.returncode == 0, err
        got = snapshot(target)
        matches = []
        for ref in refs.values():
            want = snapshot(ref)
            same_files = set(got) == set(want)
            same_bytes = same_files and all(
                got[name] == want[name] for name in want if name != "summary.json"
            )
            matches.append(same_files and same_bytes)
        assert sum(matches) == 1, sorted(got)
        assert leftovers(tmp_path) == []


def _commit_many(args: tuple[str, int]) -> None:
    target, writer = args
    for round_ in range(5):
        with staged_dir(target) as work:
            (work / "config.toml").write_text(f"# lineslam test\nwriter = {writer}\n")
            for k in range(20):
                (work / f"part{k:02d}.txt").write_text(f"{writer} {round_}\n")


def test_concurrent_commits_never_mix(tmp_path):
    """Eight processes replace the same folder five times each: it is always one writer's."""
    target = tmp_path / "t"
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(8) as pool:
        pool.map(_commit_many, [(str(target), w) for w in range(8)])
    texts = {p.read_text() for p in target.glob("part*.txt")}
    assert len(list(target.glob("part*.txt"))) == 20
    assert len(texts) == 1
    writer = next(iter(texts)).split()[0]
    assert f"writer = {writer}" in (target / "config.toml").read_text()
    assert leftovers(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# failures: the earlier folder is untouched, a success replaces it whole
# ---------------------------------------------------------------------------------------------
def test_failed_run_keeps_the_earlier_folder_and_its_config(tmp_path, capsys, earlier):
    target = tmp_path / "run"
    copy_tree(earlier, target)
    before = snapshot(target)
    bad = tmp_path / "bad.clf"
    lines = DEMO_LOG.read_text().splitlines()
    bad.write_text("\n".join([*lines[:40], "FLASER 3 1 2 x", *lines[40:60]]) + "\n")
    code, _, err = run_cli(
        ["slam", bad, "--out", target, "--seed", "7", "--backend", "batch", "--quiet"], capsys
    )
    assert code == 2 and err.count("\n") == 1 and f"{bad}:41:" in err
    assert snapshot(target) == before
    assert "seed = 7" not in (target / "config.toml").read_text()
    new = tmp_path / "new"
    code, _, _ = run_cli(["map", bad, "--out", new], capsys)
    assert code == 2 and not new.exists() and leftovers(tmp_path) == []


def test_successful_rerun_replaces_the_folder_whole(tmp_path, capsys, earlier):
    target = tmp_path / "run"
    copy_tree(earlier, target)
    (target / "metrics.json").write_text("{}")
    (target / "figures").mkdir()
    (target / "figures" / "old.png").write_bytes(b"png")
    code, _, err = run_cli(
        ["slam", DEMO_LOG, "--out", target, "--max-scans", "12", "--seed", "7", "--quiet"],
        capsys,
    )
    assert code == 0, err
    assert not (target / "metrics.json").exists() and not (target / "figures").exists()
    assert "seed = 7" in (target / "config.toml").read_text()
    assert json.loads((target / "summary.json").read_text())["scans"] == 12


def test_failing_extract_keeps_the_earlier_file(tmp_path, capsys):
    target = tmp_path / "lines.jsonl"
    code, _, _ = run_cli(["extract", DEMO_LOG, "--out", target, "--quiet"], capsys)
    assert code == 0
    before = snapshot(target)
    config_before = (tmp_path / "lines.config.toml").read_text()
    late = tmp_path / "late.clf"
    lines = DEMO_LOG.read_text().splitlines()
    late.write_text("\n".join([*lines[:-3], "FLASER 3 1 2", *lines[-3:]]) + "\n")
    code, _, err = run_cli(["extract", late, "--out", target, "--quiet", "--seed", "9"], capsys)
    assert code == 2 and f"{late}:{len(lines) - 2}:" in err
    assert snapshot(target) == before
    assert (tmp_path / "lines.config.toml").read_text() == config_before
    assert leftovers(tmp_path) == []


def test_parent_folders_of_a_failed_run_are_removed(tmp_path, capsys):
    bad = tmp_path / "bad.clf"
    bad.write_text("FLASER 3 1 2 x\n")
    for cmd, out in (("slam", "a/b/run"), ("extract", "c/d/lines.jsonl")):
        code, _, err = run_cli([cmd, bad, "--out", tmp_path / out, "--quiet"], capsys)
        assert code == 2 and "bad.clf:1:" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.clf"]


def test_stale_folders_of_other_machines_are_left_alone(tmp_path, capsys):
    foreign = tmp_path / f".run{PARTIAL_MARK}999999999-zzzzzz-abc"
    foreign.mkdir()
    dead_here = tmp_path / f".run{PARTIAL_MARK}999999999-{atomic._HOST}-abc"
    dead_here.mkdir()
    code, _, err = run_cli(
        ["slam", DEMO_LOG, "--out", tmp_path / "run", "--max-scans", "5", "--quiet"], capsys
    )
    assert code == 0, err
    assert foreign.is_dir() and not dead_here.exists()
