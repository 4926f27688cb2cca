"""The guarded reader: a file's bytes (gunzipped when gzip), as UTF-8 text, as JSON or JSON Lines,
within `Limits`. Python's own `json` module does the parsing; what it would let through or raise
as something other than a user's error is caught here:

- a file or gzip content over `max_bytes` (a gzip bomb stops at the limit, not in memory);
- damaged or truncated gzip data (`zlib.error`, a missing end, a wrong checksum);
- bytes that are not UTF-8 (`UnicodeDecodeError`);
- JSON errors (with line and column), NaN and Infinity (not JSON), numbers beyond a float
  (`1e400` would become inf), integers of more than `max_int_digits` digits (Python refuses 4,300
  and more; a 400-digit one overflows float());
- lists and objects nested deeper than `max_depth` (`RecursionError` in the parser, or in any
  recursive code after it).
"""
from __future__ import annotations

import json
import math
import re
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

MiB = 2**20
GZIP_MAGIC = b"\x1f\x8b"


class InputError(ValueError):
    """A file from outside that cannot be used, in one line naming it and where in it."""


@dataclass(frozen=True)
class Limits:
    """What a file may hold. The defaults fit problem, plan and trajectory files with a wide margin
    (a trajectory of a long demo is under 1 MiB, 8 levels deep); `LARGE` fits models and results."""

    max_bytes: int = 64 * MiB  # the file, and its content after gunzip
    max_depth: int = 32  # lists and objects inside each other
    max_int_digits: int = 20  # an integer literal (2^63 has 19 digits)


LARGE = Limits(max_bytes=1024 * MiB)  # models directories (6.8 MB of bundled operators) and results (18 MB of rows)


class _BadNumber(Exception):
    """Raised by the parser's number hooks; turned into an InputError with the literal's place."""

    def __init__(self, literal: str, reason: str) -> None:
        super().__init__(literal)
        self.literal, self.reason = literal, reason


def read_bytes(path: str | Path, what: str, limits: Limits = Limits()) -> bytes:
    """The bytes of `path` (`what` it should be, e.g. "problem file", for the error when there is no
    such file), gunzipped when they are gzip (by the magic number, or a `.gz` name)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no {what} at {path}")
    size = path.stat().st_size
    if size > limits.max_bytes:
        raise InputError(f"{path}: {size:,} bytes; a {what} may have at most {limits.max_bytes:,}")
    try:
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"{path}: cannot be read ({error.strerror})") from None
    if data[:2] == GZIP_MAGIC or path.suffix == ".gz":
        data = _gunzip(data, str(path), limits.max_bytes)
    return data


def _gunzip(data: bytes, where: str, max_bytes: int) -> bytes:
    """The content of gzip data (one member or several), at most `max_bytes` of it."""
    out: list[bytes] = []
    total, rest = 0, data
    while rest:
        if rest[:2] != GZIP_MAGIC:
            raise InputError(f"{where}: not gzip data at byte {len(data) - len(rest)}")
        inflate = zlib.decompressobj(wbits=31)  # gzip header and trailer (CRC-32, length) checked
        try:
            chunk = inflate.decompress(rest, max_bytes + 1 - total)
        except zlib.error as error:
            raise InputError(f"{where}: damaged gzip data ({error})") from None
        total += len(chunk)
        if total > max_bytes:
            raise InputError(f"{where}: more than {max_bytes:,} bytes once gunzipped")
        if not inflate.eof:
            raise InputError(f"{where}: gzip data cut short (truncated)")
        out.append(chunk)
        rest = inflate.unused_data
    return b"".join(out)


def _text(data: bytes, where: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        column = error.start - (data.rfind(b"\n", 0, error.start) + 1) + 1
        raise InputError(f"{where}: not UTF-8 text (byte 0x{data[error.start]:02x} at line {line}, "
                         f"column {column})") from None


def _refuse_constant(text: str) -> float:
    raise _BadNumber(text, f"{text} is not a JSON number")


def _hooks(text: str, limits: Limits) -> dict[str, Any]:
    """json.loads keyword arguments that refuse what `Limits` and JSON refuse. Numbers are checked
    one by one (in Python) only when the text holds a long run of digits or a 3-digit exponent; other
    numbers are in range by their length, and the C parser reads them."""
    def parse_int(literal: str) -> int:
        if len(literal) - literal.startswith("-") > limits.max_int_digits:
            raise _BadNumber(literal, f"an integer of {len(literal.lstrip('-')):,} digits (at most "
                                      f"{limits.max_int_digits})")
        return int(literal)

    def parse_float(literal: str) -> float:
        value = float(literal)
        if not math.isfinite(value):
            raise _BadNumber(literal, f"the number {_short(literal)} is beyond a float's range")
        return value

    long_digits = "[0-9]{%d}" % (min(limits.max_int_digits, 300) + 1)
    if not (re.search(long_digits, text) or re.search("[eE][+-]?[0-9]{3}", text)):
        return {"parse_constant": _refuse_constant}
    return {"parse_int": parse_int, "parse_float": parse_float, "parse_constant": _refuse_constant}


def _short(text: str, keep: int = 24) -> str:
    return text if len(text) <= keep else f"{text[:keep // 2]}...{text[-keep // 2:]}"


def _position(text: str, offset: int) -> str:
    """Line and column of `offset` (the column alone in a text of one line: a line of JSON Lines)."""
    line, column = text.count("\n", 0, offset) + 1, offset - (text.rfind("\n", 0, offset) + 1) + 1
    return f"column {column}" if "\n" not in text else f"line {line}, column {column}"


def _literal_at(text: str, literal: str) -> str:
    """Where the number `literal` first stands in `text` (not inside a longer number)."""
    found = re.search(r"(?<![\w.+-])" + re.escape(literal) + r"(?![\w.])", text)
    return f" at {_position(text, found.start())}" if found else ""


def _deep_at(text: str, max_depth: int) -> str:
    """Where `text` first opens a list or object deeper than `max_depth` (strings skipped)."""
    depth, in_string, escaped = 0, False, False
    for offset, char in enumerate(text):
        if in_string:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            if depth > max_depth:
                return f" at {_position(text, offset)}"
        elif char in "]}":
            depth -= 1
    return ""


def _depth_exceeded(value: Any, max_depth: int) -> bool:
    """Whether lists and objects nest deeper than `max_depth` in a parsed value (level by level)."""
    level = [value] if isinstance(value, (list, dict)) else []
    for _ in range(max_depth):
        inner: list = []
        for item in level:
            inner += [c for c in (item.values() if type(item) is dict else item) if type(c) in (list, dict)]
        if not inner:
            return False
        level = inner
    return bool(level)


def parse_json(text: str, where: str, limits: Limits = Limits()) -> Any:
    """The JSON value of `text`; InputError naming `where` and the place otherwise."""
    try:
        value = json.loads(text, **_hooks(text, limits))
        too_deep = _depth_exceeded(value, limits.max_depth)
    except json.JSONDecodeError as error:
        raise InputError(f"{where}: not valid JSON: {error.msg} ({_position(text, error.pos)})") from None
    except _BadNumber as bad:
        raise InputError(f"{where}: {bad.reason}{_literal_at(text, bad.literal)}") from None
    except RecursionError:  # nested beyond the parser's reach: deeper than any limit
        too_deep = True
    if too_deep:
        raise InputError(f"{where}: lists and objects nested deeper than {limits.max_depth} levels"
                         f"{_deep_at(text, limits.max_depth)}")
    return value


def read_json(path: str | Path, what: str, limits: Limits = Limits()) -> Any:
    """The JSON value in the file `path` (plain or gzip); InputError (one line) otherwise."""
    return parse_json(_text(read_bytes(path, what, limits), str(path)), str(path), limits)


@dataclass(frozen=True)
class JsonLines:
    """A JSON Lines file: its values with their line numbers (blank lines left out); with `unfinished`
    (see `read_jsonl`) the bytes of content up to the end of the last newline, and the text after it
    with its line number."""

    values: list[tuple[int, Any]]
    end: int
    tail: str = ""
    tail_line: int = 0


def read_jsonl(path: str | Path, what: str, limits: Limits = Limits(), unfinished: bool = False) -> JsonLines:
    """The values of a JSON Lines file (plain or gzip), one per line. With `unfinished`, the text after
    the last newline (a line being appended, or cut short by a kill) is not parsed but returned as
    `tail`, for the caller to judge; otherwise it is a line like the others."""
    data = read_bytes(path, what, limits)
    text = _text(data, str(path))
    complete, newline, tail = text.rpartition("\n")
    if not unfinished:
        complete, tail = text, ""
    lines = complete.split("\n") if complete or newline else []
    values = [(number, parse_json(line, f"{path} line {number}", limits))
              for number, line in enumerate(lines, start=1) if line.strip()]
    return JsonLines(values, len(data) - len(tail.encode()), tail, len(lines) + 1)
