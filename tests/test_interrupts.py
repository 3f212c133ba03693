"""slam.interrupts: the handler records, :func:`check` raises, a second signal insists.

In-process, with real signals (``signal.raise_signal``: the handler runs in this, the main
thread, before the call returns).  The end-to-end behaviour of the commands (exit status, the
one line, nothing left) is in ``tests/test_fault_injection.py``.
"""

from __future__ import annotations

import signal
import threading
import time

import pytest
from conftest import REPO_ROOT

from slam import interrupts
from slam.config import RunConfig
from slam.interrupts import Interrupted

DEMO_LOG = REPO_ROOT / "datasets" / "sim" / "demo" / "log.clf"


def test_the_first_signal_is_recorded_and_raised_at_the_next_check():
    with interrupts.handling_signals():
        interrupts.check()  # nothing recorded: no-op
        signal.raise_signal(signal.SIGTERM)  # the handler returns: nothing raised here
        assert interrupts.requested() == signal.SIGTERM
        with pytest.raises(Interrupted) as info:
            interrupts.check()
        assert info.value.signum == signal.SIGTERM and info.value.exit_status == 143
        with pytest.raises(Interrupted):  # and again at every later check
            interrupts.check()
        signal.raise_signal(signal.SIGINT)  # cleaning up: ignored
    assert interrupts.requested() is None


def test_a_second_signal_while_the_first_is_pending_raises_at_once():
    with interrupts.handling_signals():
        signal.raise_signal(signal.SIGINT)
        with pytest.raises(Interrupted) as info:
            signal.raise_signal(signal.SIGTERM)
        assert info.value.signum == signal.SIGINT  # the first signal is the one reported
        signal.raise_signal(signal.SIGINT)  # a third, while cleaning up: ignored
        with pytest.raises(Interrupted):
            interrupts.check()


def test_no_signal_raises_inside_a_deferred_block():
    with interrupts.handling_signals():
        with interrupts.deferred():
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGTERM)
        assert interrupts.requested() == signal.SIGINT
        with pytest.raises(Interrupted) as info:
            interrupts.check()
        assert info.value.exit_status == 130


def test_the_first_signal_raises_at_once_inside_an_at_once_block():
    with interrupts.handling_signals():
        with pytest.raises(Interrupted), interrupts.at_once():
            signal.raise_signal(signal.SIGTERM)
        signal.raise_signal(signal.SIGINT)  # cleaning up: ignored
        with pytest.raises(Interrupted) as info:
            interrupts.check()
        assert info.value.exit_status == 143
    with interrupts.handling_signals(), interrupts.at_once(), interrupts.deferred():
        signal.raise_signal(signal.SIGINT)  # deferred wins
        assert interrupts.requested() == signal.SIGINT


def test_handlers_and_state_are_restored():
    before = {s: signal.getsignal(s) for s in interrupts.SIGNALS}
    with interrupts.handling_signals():
        assert all(signal.getsignal(s) is not before[s] for s in interrupts.SIGNALS)
        interrupts.request(signal.SIGTERM)
        with interrupts.handling_signals():  # nested: starts clean
            assert interrupts.requested() is None
        assert interrupts.requested() == signal.SIGTERM
    assert {s: signal.getsignal(s) for s in interrupts.SIGNALS} == before
    assert interrupts.requested() is None
    interrupts.check()  # outside: nothing recorded


def test_request_without_handlers_is_honoured():
    try:
        interrupts.request(signal.SIGTERM)
        interrupts.request(signal.SIGINT)  # the first request stands
        with pytest.raises(Interrupted) as info:
            interrupts.check()
        assert info.value.signum == signal.SIGTERM
    finally:
        interrupts._set_state(interrupts._State())
    interrupts.check()


def test_call_in_thread_returns_raises_and_is_abandoned_on_a_signal():
    with interrupts.handling_signals():
        assert interrupts.call_in_thread(lambda: 41 + 1) == 42
        with pytest.raises(ZeroDivisionError):
            interrupts.call_in_thread(lambda: 1 / 0)
        release = threading.Event()

        def slow() -> int:
            release.wait(30.0)
            return 1

        threading.Timer(0.2, signal.raise_signal, (signal.SIGINT,)).start()
        t0 = time.monotonic()
        with pytest.raises(Interrupted):
            interrupts.call_in_thread(slow)
        assert time.monotonic() - t0 < 5.0
        assert interrupts.abandoned()
        release.set()
    for thread in interrupts._ABANDONED:
        thread.join(5.0)
    assert not interrupts.abandoned()
    interrupts._ABANDONED.clear()


def test_call_in_thread_outside_the_handlers_calls_directly():
    assert interrupts.call_in_thread(threading.current_thread) is threading.current_thread()


def test_feeding_stops_at_the_next_scan_after_a_request(tmp_path):
    """The runner checks between scans: a request stops it at once, nothing is written."""
    from slam.runner import run_ekf, run_slam

    for run in (run_slam, run_ekf):
        fed = []

        def progress(n: int, fed: list[int] = fed) -> None:
            fed.append(n)
            if sum(fed) >= 30:
                interrupts.request(signal.SIGTERM)

        with interrupts.handling_signals(), pytest.raises(Interrupted):
            run(DEMO_LOG, tmp_path / "run", RunConfig(), progress=progress)
        assert 30 <= sum(fed) <= 30 + 256  # a chunk at most (LineSlam.add_scans checks per scan)
        assert list(tmp_path.iterdir()) == []


def test_a_request_while_writing_keeps_the_earlier_results(tmp_path, capsys, monkeypatch):
    """A signal after the last check of the run: the results are not put in place."""
    import slam.io.results
    from slam.cli import main

    original = slam.io.results.write_summary

    def write_then_signal(*args, **kwargs):
        out = original(*args, **kwargs)
        signal.raise_signal(signal.SIGTERM)
        return out

    monkeypatch.setattr(slam.io.results, "write_summary", write_then_signal)
    target = tmp_path / "run"
    with pytest.raises(SystemExit) as info:
        main(["slam", str(DEMO_LOG), "--out", str(target), "--max-scans", "10", "--quiet"])
    err = capsys.readouterr().err
    assert info.value.code == 143
    assert err == "lineslam: interrupted (SIGTERM); nothing written, earlier results unchanged\n"
    assert list(tmp_path.iterdir()) == []


def test_a_signal_after_the_results_are_in_place_says_so(tmp_path, capsys, monkeypatch):
    import slam.cli.cmd_extract
    from slam.cli import main

    def signal_instead(*args, **kwargs):
        signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(slam.cli.cmd_extract, "warn_log_anomalies", signal_instead)
    target = tmp_path / "lines.jsonl"
    with pytest.raises(SystemExit) as info:
        main(["extract", str(DEMO_LOG), "--out", str(target), "--limit", "20", "--quiet"])
    last = capsys.readouterr().err.splitlines()[-1]  # after the warnings of the run
    assert info.value.code == 130
    assert last == f"lineslam: interrupted (SIGINT) after writing {tmp_path}/lines.config.toml"
    assert len(target.read_text().splitlines()) == 20
