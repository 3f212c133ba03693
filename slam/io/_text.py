"""Reading text files line by line with clear errors for files that are not text.

Every reader in :mod:`slam.io` goes through :func:`iter_text_lines`, so an empty file, a
binary file, a directory or a missing file gives one clear :class:`~slam.errors.InputError`
(naming the file and, where it helps, the 1-based line number) instead of a traceback from
deep inside a decoder.  Gzip-compressed files (``.clf.gz`` as CARMEN tools write them) are
read transparently.
"""

from __future__ import annotations

import gzip
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from slam.errors import InputError, LogFormatError

__all__ = ["iter_text_lines", "parse_float"]

_HEAD_BYTES = 8192


def _open_binary(path: Path) -> IO[bytes]:
    with path.open("rb") as raw:
        head = raw.read(_HEAD_BYTES)
    if not head:
        raise LogFormatError("empty file", str(path))
    if head[:2] == b"\x1f\x8b":
        return gzip.GzipFile(path, "rb")  # type: ignore[return-value]
    nul = head.find(b"\x00")
    if nul >= 0:
        line = head.count(b"\n", 0, nul) + 1
        raise LogFormatError("binary data (NUL byte): not a text file", str(path), line)
    return path.open("rb")


def iter_text_lines(path: str | Path) -> Iterator[tuple[int, str]]:
    """Yield ``(line_number, text)`` for every line of a text file (1-based, newline kept).

    Parameters
    ----------
    path
        A plain or gzip-compressed UTF-8 (or ASCII) text file.

    Raises
    ------
    InputError
        ``path`` does not exist or is a directory.
    LogFormatError
        The file is empty, binary (a NUL byte, or bytes that are not UTF-8) or a truncated
        gzip stream; the message names the file and the line.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("no such file", str(path))
    if path.is_dir():
        raise InputError("is a directory, expected a file", str(path))
    line_number = 0
    with _open_binary(path) as handle:
        try:
            for line_number, raw in enumerate(handle, 1):
                if b"\x00" in raw:
                    raise LogFormatError(
                        "binary data (NUL byte): not a text file", str(path), line_number
                    )
                try:
                    text = raw.decode("utf-8")
                except UnicodeDecodeError:
                    raise LogFormatError(
                        "bytes that are not UTF-8 text (binary file?)", str(path), line_number
                    ) from None
                yield line_number, text
        except (OSError, EOFError) as exc:  # truncated or corrupt gzip stream
            raise LogFormatError(f"cannot read: {exc}", str(path), line_number + 1) from None


def parse_float(token: str, what: str, path: str, line_number: int) -> float:
    """``float(token)``, or a :class:`LogFormatError` naming the field, file and line."""
    try:
        return float(token)
    except ValueError:
        raise LogFormatError(f"{what}: {token!r} is not a number", path, line_number) from None
