"""Frozen-dataclass configuration <-> TOML.

Configurations in lineslam are frozen dataclasses (validated in ``__post_init__``).  This module
turns any such dataclass, possibly nested, into a TOML document and back, so that every run can
save the exact configuration it used (``config.toml``) and reload it with ``--config``.

Only the types used by configurations are supported: ``bool``, ``int``, ``float``, ``str``,
``None`` (written as a missing key, i.e. "use the default"), tuples/lists of those, and nested
dataclasses (written as TOML tables).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from linefit.errors import ConfigError

__all__ = ["config_from_dict", "config_to_dict", "dump_toml", "load_toml", "to_toml_string"]

T = TypeVar("T")


def config_to_dict(config: Any) -> dict[str, Any]:
    """Return a nested ``dict`` of the dataclass ``config`` (``None`` values dropped)."""
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise ConfigError(f"expected a dataclass instance, got {type(config).__name__}")
    out: dict[str, Any] = {}
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        if value is None:
            continue
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out[field.name] = config_to_dict(value)
        elif isinstance(value, tuple | list):
            out[field.name] = list(value)
        else:
            out[field.name] = value
    return out


def _format_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_format_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write {type(value).__name__} to TOML")


def to_toml_string(data: dict[str, Any], header: str | None = None) -> str:
    """Serialise a nested ``dict`` (scalars first, then sub-tables) as TOML text."""
    lines: list[str] = []
    if header:
        lines.extend(f"# {h}" for h in header.splitlines())

    def emit(table: dict[str, Any], prefix: str) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, dict)}
        tables = {k: v for k, v in table.items() if isinstance(v, dict)}
        if prefix and (scalars or not tables):
            lines.append("")
            lines.append(f"[{prefix}]")
        for key, value in scalars.items():
            lines.append(f"{key} = {_format_value(value)}")
        for key, sub in tables.items():
            emit(sub, f"{prefix}.{key}" if prefix else key)

    emit(data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def _resolve_hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _convert(value: Any, hint: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        non_none = [a for a in args if a is not type(None)]
        if value is None:
            return None
        errors = []
        for candidate in non_none:
            try:
                return _convert(value, candidate, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError("; ".join(errors))
    if typing.get_origin(hint) is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: {value!r} is not one of {list(args)}")
        return value
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
        return config_from_dict(hint, value, _where=where)
    if origin in (tuple, list):
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected an array, got {type(value).__name__}")
        item_hint = args[0] if args else Any
        items = [_convert(v, item_hint, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    return value


def config_from_dict(cls: type[T], data: dict[str, Any], _where: str = "") -> T:
    """Build the frozen dataclass ``cls`` from a nested ``dict``.

    Missing keys take the dataclass defaults; unknown keys raise :class:`ConfigError` (a typo
    in a configuration file must not be silently ignored); a key the class lists in its
    ``RENAMED_KEYS`` (old name → what became of it) gets that said in the message.
    Validation happens in the dataclass's own ``__post_init__``.
    """
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise ConfigError(f"{cls!r} is not a dataclass type")
    hints = _resolve_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = set(data) - names
    if unknown:
        prefix = f"[{_where}] " if _where else ""
        renamed: dict[str, str] = getattr(cls, "RENAMED_KEYS", {})
        hints_renamed = [f"{k}: {renamed[k]}" for k in sorted(unknown) if k in renamed]
        hint = f" ({'; '.join(hints_renamed)})" if hints_renamed else ""
        raise ConfigError(
            f"{prefix}unknown configuration key(s): {', '.join(sorted(unknown))}{hint}"
        )
    kwargs = {}
    for key, value in data.items():
        where = f"{_where}.{key}" if _where else key
        kwargs[key] = _convert(value, hints[key], where)
    try:
        return cls(**kwargs)
    except TypeError as exc:  # pragma: no cover - defensive, names were checked above
        raise ConfigError(str(exc)) from exc


def load_toml(cls: type[T], path: str | Path, section: str | None = None) -> T:
    """Load ``cls`` from the TOML file ``path`` (optionally from one of its tables)."""
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
    if section is not None:
        for part in section.split("."):
            data = data.get(part, {})
            if not isinstance(data, dict):
                raise ConfigError(f"{path}: [{section}] is not a table")
    try:
        return config_from_dict(cls, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def dump_toml(config: Any, path: str | Path, header: str | None = None) -> None:
    """Write the dataclass ``config`` to ``path`` as TOML (reloadable with :func:`load_toml`)."""
    Path(path).write_text(to_toml_string(config_to_dict(config), header=header), encoding="utf-8")
