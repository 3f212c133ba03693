"""Writing results so that a failed or interrupted run loses nothing.

Every command that writes a results folder writes it into a temporary folder beside the
target and moves it into place only when it is complete (:func:`staged_dir`); a command whose
output is a file (``lineslam extract``) does the same with temporary files beside the targets
(:func:`staged_files`).  So:

* a failed or interrupted run leaves the target as it was (absent, or the earlier folder or
  file, untouched) and removes its temporary folder;
* a successful run replaces an earlier results folder **whole** (no stale file of the earlier
  run survives): the complete new folder and the old one are swapped in one atomic
  ``renameat2(RENAME_EXCHANGE)`` where the file system has it (Linux), else by two renames;
* two runs into the same target at once each write their own temporary folder; the swaps are
  serialised (a lock on the parent folder), so the target ends up holding one run's folder
  whole, never a mix;
* a run killed outright (``SIGKILL``, power loss) leaves its temporary folder
  ``.NAME.partial-PID-HOST-XXXX`` beside the target (the target itself untouched); the next
  run into the same target on the same machine removes such folders whose process is gone;
* parent folders created for a run that then fails are removed again (if still empty).

Nothing is copied: results are written once, where they will stay, and renamed.

Refused before anything is read or written (:class:`~slam.errors.OutputError`, one line naming
the path): an empty path; a target that exists and is not a folder (a file, ``/dev/null``) or,
for files, not a regular file; a folder that is neither empty nor a lineslam results folder
(one holding a ``config.toml`` written by lineslam), so that ``--out ~`` cannot wipe a home
folder; the current folder or one holding it; a mount point; a symbolic link; a parent that
is a file; a target that is, or holds, the command's input.  Errors of the file system while
writing (read-only, full disk, permission denied) become an :class:`~slam.errors.OutputError`
naming the target.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import os
import secrets
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

from slam import interrupts
from slam.errors import OutputError

__all__ = [
    "PARTIAL_MARK",
    "check_output_dir",
    "check_output_file",
    "committed_targets",
    "is_results_folder",
    "staged_dir",
    "staged_files",
    "staged_into",
    "write_text_atomic",
]

PARTIAL_MARK = ".partial-"
"""Part of the name of a temporary folder or file: ``.NAME.partial-PID-XXXX``."""

_CONFIG_FILE = "config.toml"
_COMMITTED: list[Path] = []


def _read_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()
"""The process's umask: finished files and folders get the modes a plain write gives."""


def committed_targets() -> list[Path]:
    """Targets this process has put in place so far (newest last)."""
    return list(_COMMITTED)


def _shown(path: str | os.PathLike[str]) -> str:
    text = os.fspath(path)
    return text if text else "''"


def _absolute(path: str | os.PathLike[str]) -> Path:
    """``path`` absolute, its parent's symbolic links resolved (the last part kept)."""
    text = os.fspath(path)
    if not text or not text.strip():
        raise OutputError(_shown(path), "empty path")
    p = Path(os.path.abspath(text))
    return Path(os.path.realpath(p.parent)) / p.name if p.name else p


def _contains(folder: Path, other: Path) -> bool:
    """``other`` is ``folder`` or lies inside it (both absolute and resolved)."""
    try:
        return os.path.commonpath([folder, other]) == str(folder)
    except ValueError:
        return False


def _check_parent(target: Path, shown: str) -> None:
    """The nearest existing ancestor of ``target`` must be a folder we may write in."""
    parent = target.parent
    while not parent.exists():
        if parent.is_symlink():
            raise OutputError(shown, f"{parent} is a broken symbolic link")
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(shown, f"{parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(shown, f"cannot write in {parent} (permission denied or read-only)")


def _check_inputs(target: Path, inputs: Iterable[str | os.PathLike[str]], shown: str) -> None:
    real_target = Path(os.path.realpath(target))
    for item in inputs:
        if item is None or not os.fspath(item):
            continue
        source = Path(os.path.realpath(item))
        same = source == real_target
        if not same and target.exists() and Path(item).exists():
            with contextlib.suppress(OSError):
                same = os.path.samefile(item, target)
        if same:
            raise OutputError(shown, f"is the input {item}; refusing to write over it")
        if _contains(real_target, source):
            raise OutputError(shown, f"holds the input {item}; refusing to replace it")


def is_results_folder(folder: str | os.PathLike[str]) -> bool:
    """``folder`` holds a ``config.toml`` written by lineslam (its first line names it)."""
    config = Path(folder) / _CONFIG_FILE
    try:
        with config.open("rb") as handle:
            head = handle.read(200)
    except OSError:
        return False
    return b"lineslam" in head.split(b"\n", 1)[0]


def _is_empty_folder(folder: Path) -> bool:
    with os.scandir(folder) as entries:
        return next(entries, None) is None


def check_output_dir(
    target: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]] = ()
) -> Path:
    """Check that a results folder may be (re)placed at ``target``; return it absolute.

    Raises
    ------
    OutputError
        See the module docstring (one line, naming ``target``).
    """
    shown = _shown(target)
    path = _absolute(target)
    if path.is_symlink():
        raise OutputError(shown, "is a symbolic link; give the folder it points to")
    if path.exists():
        if not path.is_dir():
            raise OutputError(shown, "exists and is not a folder")
        if _contains(path, Path(os.path.realpath(os.getcwd()))):
            raise OutputError(shown, "is the current folder (or holds it); give another folder")
        if os.path.ismount(path):
            raise OutputError(shown, "is a mount point; give a folder inside it")
        if not _is_empty_folder(path) and not is_results_folder(path):
            raise OutputError(
                shown,
                "exists and is not a lineslam results folder (no config.toml written by "
                "lineslam); give a new or empty folder",
            )
    _check_parent(path, shown)
    _check_inputs(path, inputs, shown)
    return path


def check_output_file(
    target: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]] = ()
) -> Path:
    """Check that a results file may be (re)placed at ``target``; return it absolute.

    Raises
    ------
    OutputError
        Empty path, a folder, an existing file that is not a regular file (``/dev/null``, a
        FIFO), a parent that is a file or cannot be written, or the input itself.
    """
    shown = _shown(target)
    if os.fspath(target).endswith(os.sep):
        raise OutputError(shown, "is a folder name; give a file")
    path = _absolute(target)
    if path.is_dir():
        raise OutputError(shown, "is a folder; give a file")
    if path.exists() and not path.is_file():
        raise OutputError(shown, "exists and is not a regular file")
    _check_parent(path, shown)
    _check_inputs(path, inputs, shown)
    return path


def _output_error(exc: OSError, shown: str) -> OutputError:
    reason = exc.strerror or str(exc)
    return OutputError(shown, f"cannot write: {reason}")


def _mkdirs(folder: Path, shown: str) -> list[Path]:
    """Create ``folder`` and its missing parents; return those created, outermost first."""
    missing = []
    here = folder
    while not here.exists():
        missing.append(here)
        here = here.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _output_error(exc, shown) from None
    return missing[::-1]


def _remove_created(created: list[Path]) -> None:
    """Remove the folders :func:`_mkdirs` created, if still empty (a failed run)."""
    for folder in reversed(created):
        try:
            folder.rmdir()
        except OSError:
            return


def _temp_prefix(name: str) -> str:
    """``.NAME.partial-PID-HOST-``: whose temporary file or folder it is."""
    return f".{name}{PARTIAL_MARK}{os.getpid()}-{_HOST}-"


def _host_tag() -> str:
    import hashlib
    import socket

    return hashlib.blake2s(socket.gethostname().encode(), digest_size=3).hexdigest()


_HOST = _host_tag()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale(parent: Path, name: str) -> None:
    """Remove ``.NAME.partial-PID-HOST-*`` left by killed runs of this host (process gone)."""
    prefix = f".{name}{PARTIAL_MARK}"
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return
    for entry in entries:
        if not entry.name.startswith(prefix):
            continue
        pid_text, host, *_ = [*entry.name[len(prefix) :].split("-", 2), "", ""]
        if not pid_text.isdigit() or host != _HOST:
            continue  # not ours to judge (e.g. written from another machine)
        if int(pid_text) == os.getpid() or _pid_alive(int(pid_text)):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.unlink(entry.path)


@contextlib.contextmanager
def _quiet_signals() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back while the results are swapped into place."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def _folder_lock(folder: Path) -> Iterator[None]:
    """An exclusive ``flock`` on ``folder``: one commit at a time per parent folder."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        yield  # no lock possible (e.g. an unreadable parent): renames are still atomic
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` atomically (Linux ``renameat2``); False where not supported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    rc = renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _replace_dir(work: Path, target: Path, shown: str) -> None:
    """Put the complete folder ``work`` at ``target``; the old target is removed whole."""
    if target.exists() or target.is_symlink():
        if not target.is_dir() or target.is_symlink():
            raise OutputError(shown, "exists and is not a folder")
        if not _is_empty_folder(target) and not is_results_folder(target):
            raise OutputError(shown, "exists and is not a lineslam results folder")
        if _exchange(work, target):
            shutil.rmtree(work, ignore_errors=True)  # now holds the old folder
            return
        old = target.with_name(f"{_temp_prefix(target.name)}old-{secrets.token_hex(4)}")
        os.rename(target, old)
        try:
            os.rename(work, target)
        except OSError:
            os.rename(old, target)
            raise
        shutil.rmtree(old, ignore_errors=True)
        return
    os.rename(work, target)


def _is_inside(path: str | None, folder: Path) -> bool:
    return bool(path) and _contains(folder, Path(os.path.abspath(str(path))))


@contextlib.contextmanager
def staged_dir(
    target: str | os.PathLike[str],
    inputs: Iterable[str | os.PathLike[str]] = (),
    *,
    reuse: Sequence[str] = (),
) -> Iterator[Path]:
    """Write a results folder in a temporary folder; put it at ``target`` when complete.

    Parameters
    ----------
    target
        The results folder (created, or replaced whole).
    inputs
        Files or folders the run reads: ``target`` must not be or hold any of them.
    reuse
        Names of sub-folders of an earlier ``target`` (e.g. a cache) whose files are
        hard-linked into the new folder before the run (nothing is copied; skipped where the
        file system has no hard links).

    Yields
    ------
    Path
        The temporary folder to write into (beside ``target``).

    Raises
    ------
    OutputError
        ``target`` cannot be used or written (module docstring).
    """
    shown = _shown(target)
    path = check_output_dir(target, inputs)
    created = _mkdirs(path.parent, shown)
    _remove_stale(path.parent, path.name)
    try:
        work = Path(tempfile.mkdtemp(prefix=_temp_prefix(path.name), dir=path.parent))
    except OSError as exc:
        _remove_created(created)
        raise _output_error(exc, shown) from None
    done = False
    try:
        for name in reuse:
            _link_tree(path / name, work / name)
        try:
            yield work
        except OSError as exc:
            if _is_inside(exc.filename, work) or exc.errno in (errno.ENOSPC, errno.EDQUOT):
                raise _output_error(exc, shown) from None
            raise
        interrupts.check()  # a run interrupted while writing is not put in place
        with _quiet_signals(), _folder_lock(path.parent):
            try:
                os.chmod(work, 0o777 & ~_UMASK)
                _replace_dir(work, path, shown)
            except OSError as exc:
                raise _output_error(exc, shown) from None
            _COMMITTED.append(path)
            done = True
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)
        if not done:
            _remove_created(created)


def _link_tree(source: Path, dest: Path) -> None:
    if not source.is_dir() or source.is_symlink():
        return
    try:
        for root, _dirs, files in os.walk(source):
            here = dest / Path(root).relative_to(source)
            here.mkdir(parents=True, exist_ok=True)
            for name in files:
                os.link(Path(root) / name, here / name)
    except OSError:
        shutil.rmtree(dest, ignore_errors=True)


@contextlib.contextmanager
def staged_files(
    targets: Sequence[str | os.PathLike[str]],
    inputs: Iterable[str | os.PathLike[str]] = (),
    *,
    record: bool = True,
) -> Iterator[list[Path]]:
    """Write files under temporary names beside ``targets``; rename them into place at the end.

    The temporary files (``.NAME.partial-PID-XXXX``) are removed if the block fails or is
    interrupted, so an earlier file at a target stays as it was.  The renames of one call
    happen together under a lock on each parent folder.  ``record``: list the targets in
    :func:`committed_targets`.

    Yields
    ------
    list of Path
        One temporary path per target (created empty).

    Raises
    ------
    OutputError
        A target cannot be used (:func:`check_output_file`) or written.
    """
    shown = [_shown(t) for t in targets]
    paths = [check_output_file(t, inputs) for t in targets]
    if len({str(p) for p in paths}) != len(paths):
        raise OutputError(shown[0], "the same file is named twice")
    work: list[Path] = []
    created: list[Path] = []
    done = False
    try:
        for p, s in zip(paths, shown, strict=True):
            created += _mkdirs(p.parent, s)
            _remove_stale(p.parent, p.name)
            try:
                fd, name = tempfile.mkstemp(prefix=_temp_prefix(p.name), dir=p.parent)
            except OSError as exc:
                raise _output_error(exc, s) from None
            os.close(fd)
            work.append(Path(name))
        try:
            yield list(work)
        except OSError as exc:
            for w, s in zip(work, shown, strict=False):
                if _is_inside(exc.filename, w) or exc.errno in (errno.ENOSPC, errno.EDQUOT):
                    raise _output_error(exc, s) from None
            raise
        interrupts.check()
        parents = sorted({str(p.parent) for p in paths})
        with _quiet_signals(), contextlib.ExitStack() as locks:
            for parent in parents:
                locks.enter_context(_folder_lock(Path(parent)))
            for w, p, s in zip(work, paths, shown, strict=True):
                if p.exists() and not p.is_file():
                    raise OutputError(s, "exists and is not a regular file")
                try:
                    os.chmod(w, 0o666 & ~_UMASK)
                    os.replace(w, p)
                except OSError as exc:
                    raise _output_error(exc, s) from None
                if record:
                    _COMMITTED.append(p)
            done = True
    finally:
        for w in work:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(w)
        if not done:
            _remove_created(created)


@contextlib.contextmanager
def staged_into(
    target: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[Path]:
    """Write files into a temporary folder; move them into the folder ``target`` at the end.

    For folders that are not results folders (e.g. ``lineslam extract --plot DIR``): the
    files written are added to ``target`` (created if needed), each replacing a file of the
    same name; other files in ``target`` are kept.  On failure nothing reaches ``target``.
    """
    shown = _shown(target)
    path = _absolute(target)
    if path.exists() and not path.is_dir():
        raise OutputError(shown, "exists and is not a folder")
    _check_parent(path, shown)
    _check_inputs(path, inputs, shown)
    created = _mkdirs(path.parent, shown)
    _remove_stale(path.parent, path.name)
    try:
        work = Path(tempfile.mkdtemp(prefix=_temp_prefix(path.name), dir=path.parent))
    except OSError as exc:
        _remove_created(created)
        raise _output_error(exc, shown) from None
    done = False
    try:
        try:
            yield work
        except OSError as exc:
            if _is_inside(exc.filename, work) or exc.errno in (errno.ENOSPC, errno.EDQUOT):
                raise _output_error(exc, shown) from None
            raise
        interrupts.check()
        with _quiet_signals():
            try:
                path.mkdir(exist_ok=True)
                for root, _dirs, files in os.walk(work):
                    here = path / Path(root).relative_to(work)
                    here.mkdir(exist_ok=True)
                    for name in files:
                        os.replace(Path(root) / name, here / name)
            except OSError as exc:
                raise _output_error(exc, shown) from None
            _COMMITTED.append(path)
            done = True
    finally:
        shutil.rmtree(work, ignore_errors=True)
        if not done:
            _remove_created(created)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename.

    A reader sees the old file or the new one, never a part; on failure the old file stays.
    """
    with staged_files([path], record=False) as (work,):
        work.write_text(text, encoding="utf-8")
    return Path(path)
