"""Typed configuration from TOML: a file read within limits, then built into frozen dataclasses.

    table = read_toml(path, "configuration file")
    cfg = build(PlanConfig, table, str(path))   # unknown keys, wrong types: InputError in one line

Every key of the file names a field; a table names a dataclass field (a section). A value must have the
field's type: `true`/`false` for a bool, an integer for an int, a number for a float, a string for a str,
an array of as many items for a fixed-length tuple (`tuple[float, float, float]`, a position).
TOML has no null, so an optional field (`int | None`, an option that can be off) is switched off with
`false`. An unknown key is refused with the nearest known key; a value of the wrong type names the key
and the type it takes; a value out of range is refused by the dataclass's own checks (`__post_init__`),
whose message is passed on with the file's name. `render` writes a dataclass back as TOML, each field
with the one-line comment its class gives it in the source, so that `tamp config show` reads back equal.
"""
from __future__ import annotations

import ast
import dataclasses
import difflib
import inspect
import io
import json
import math
import textwrap
import tokenize
import tomllib
import types
import typing
from functools import cache
from pathlib import Path
from typing import Any, Iterable, Mapping

from guarded.read import InputError, Limits, read_bytes

CONFIG_LIMITS = Limits(max_bytes=2**20)  # a configuration is a few kB


def parse_toml(text: str, where: str) -> dict[str, Any]:
    """The table of TOML `text` (`where` names it in errors)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"{where}: not TOML: {error}") from None
    except RecursionError:
        raise InputError(f"{where}: nested too deep") from None


def read_toml(path: str | Path, what: str, limits: Limits = CONFIG_LIMITS) -> dict[str, Any]:
    """The table of the TOML file at `path` (`what` it should be, for the error when there is none)."""
    data = read_bytes(path, what, limits)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(f"{path}: not UTF-8 text (byte {error.start})") from None
    return parse_toml(text, str(path))


def _optional(tp: Any) -> tuple[Any, bool]:
    """(the type inside `X | None`, True), or (tp, False)."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(tp)) == 2:
            return args[0], True
    return tp, False


def _type_name(tp: Any, optional: bool) -> str:
    name = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(tp, str(tp))
    return f"{name}, or false for off" if optional else name


def _value(value: Any, tp: Any, key: str, where: str) -> Any:
    """`value` as a field of type `tp` (a scalar, or `X | None`), or InputError naming `key`."""
    inner, optional = _optional(tp)
    if optional and value is False and inner is not bool:
        return None
    if typing.get_origin(inner) is tuple:  # a fixed-length array, e.g. a position: each item of its own type
        items = typing.get_args(inner)
        if not isinstance(value, list) or len(value) != len(items):
            raise InputError(f"{where}: {key} must be an array of {len(items)} items, "
                             f"each {_type_name(items[0], False)}")
        return tuple(_value(v, t, f"{key}[{i}]", where) for i, (v, t) in enumerate(zip(value, items)))
    ok = (isinstance(value, bool) if inner is bool
          else isinstance(value, int) and not isinstance(value, bool) if inner is int
          else isinstance(value, (int, float)) and not isinstance(value, bool) if inner is float
          else isinstance(value, str) if inner is str else False)
    if not ok:
        shown = json.dumps(value, default=str)
        shown = shown if len(shown) <= 40 else shown[:37] + "..."
        raise InputError(f"{where}: {key} must be {_type_name(inner, optional)}, got {shown}")
    if inner is float:
        if not math.isfinite(value):
            raise InputError(f"{where}: {key} must be a finite number, got {value}")
        return float(value)
    return value


def _unknown(key: str, known: Iterable[str], section: str, where: str) -> InputError:
    near = difflib.get_close_matches(key, list(known), n=1, cutoff=0.5)
    hint = f"; did you mean {section}{near[0]}?" if near else f"; known: {', '.join(known)}"
    return InputError(f"{where}: unknown key {section}{key}{hint}")


def build(cls: type, table: Mapping[str, Any], where: str, base: Any = None, section: str = "",
          also: Iterable[str] = ()) -> Any:
    """The `cls` dataclass (`base`'s values, default `cls()`) with `table`'s keys over them; nested
    dataclass fields take sub-tables. Keys in `also` belong to someone else and are skipped."""
    if not isinstance(table, Mapping):
        raise InputError(f"{where}: {section.rstrip('.') or 'the file'} must be a table of keys, got a value")
    base = cls() if base is None else base
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    changes: dict[str, Any] = {}
    for key, value in table.items():
        if key in also:
            continue
        if key not in names:
            raise _unknown(key, names, section, where)
        tp = hints[key]
        if dataclasses.is_dataclass(tp):
            changes[key] = build(tp, value, where, getattr(base, key), f"{section}{key}.")  # type: ignore[arg-type]
        elif isinstance(value, Mapping):
            raise InputError(f"{where}: {section}{key} is a setting, not a table")
        else:
            changes[key] = _value(value, tp, f"{section}{key}", where)
    try:
        return dataclasses.replace(base, **changes)
    except InputError:
        raise
    except ValueError as error:  # the dataclass's own range checks
        raise InputError(f"{where}: {error}") from None


@cache
def field_comments(cls: type) -> dict[str, str]:
    """Each field's one-line comment in `cls`'s source: the comment ending its line, else the comment
    lines right above it."""
    source = textwrap.dedent(inspect.getsource(cls))
    comments = {tok.start[0]: tok.string.lstrip("#").strip()
                for tok in tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT}
    lines = source.splitlines()
    found: dict[str, str] = {}
    node = ast.parse(source).body[0]
    assert isinstance(node, ast.ClassDef)
    for stmt in node.body:
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
            line = stmt.lineno
            if line in comments:
                found[stmt.target.id] = comments[line]
                continue
            above: list[str] = []
            k = line - 1
            while k in comments and lines[k - 1].lstrip().startswith("#"):
                above.insert(0, comments[k])
                k -= 1
            if above:
                found[stmt.target.id] = " ".join(above)
    return found


def _toml_value(value: Any) -> str:
    if value is None or value is False:
        return "false"
    if value is True:
        return "true"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(value) if isinstance(value, str) else str(value)


def render(obj: Any, section: str = "") -> str:
    """`obj` (a dataclass) as TOML: its scalar fields, each with its comment, then a table per nested
    dataclass field."""
    comments = field_comments(type(obj))  # type: ignore[arg-type]
    scalars, tables = [], []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            tables.append(render(value, f"{section}.{f.name}" if section else f.name))
            continue
        line = f"{f.name} = {_toml_value(value)}"
        scalars.append(f"{line}  # {comments[f.name]}" if f.name in comments else line)
    head = [f"[{section}]"] if section and scalars else []
    return "\n\n".join(["\n".join(head + scalars)] * bool(scalars) + tables)


__all__ = ["CONFIG_LIMITS", "build", "field_comments", "parse_toml", "read_toml", "render"]
