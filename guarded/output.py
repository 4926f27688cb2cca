"""Files the tool writes: atomic (a temporary name beside the target, fsync, rename), strict JSON, and every
failure of the disk (full, read-only, a path that cannot be made) one `OutputError` naming the path.

Standard library only, so every package (`tamp`, `learned`, `symbolic`, `evaluation`) writes through it. A
directory the tool creates carries `MARKER`: the tool removes or replaces only what carries it.
"""
from __future__ import annotations

import errno
import json
import os
from pathlib import Path
from typing import IO, Any, Callable

MARKER = ".tamp-output"  # in every directory the tool made: what it may remove or replace


class OutputError(ValueError):
    """A file or directory could not be written (the disk is full, read-only, a path cannot be made), in one
    line naming the path. A ValueError, so that the command line says it as a user error."""


def output_error(path: str | Path, error: OSError) -> OutputError:
    """The one-line OutputError of `error`, met while writing `path`."""
    return OutputError(f"cannot write {path}: {error.strerror or error or type(error).__name__}")


def make_dirs(path: str | Path, target: str | Path | None = None) -> list[Path]:
    """Create the folder `path` and its missing parents; returns the folders created (outermost first), for
    `remove_made` on failure. OutputError naming `target` (default `path`: what was to be written) if one
    cannot be made."""
    path = Path(path)
    name = path if target is None else target
    missing = []
    probe = path
    while not probe.exists() and probe != probe.parent:
        missing.append(probe)
        probe = probe.parent
    made: list[Path] = []
    try:
        for folder in reversed(missing):
            folder.mkdir()
            made.append(folder)
    except FileExistsError:
        if not path.is_dir():
            remove_made(made)
            raise OutputError(f"cannot write {name}: {probe} is not a folder") from None
    except OSError as error:
        remove_made(made)
        raise output_error(name, error) from None
    if not path.is_dir():
        raise OutputError(f"cannot write {name}: {path} is not a folder")
    return made


def remove_made(made: list[Path]) -> None:
    """Remove the folders `make_dirs` created, innermost first, where they are still empty."""
    for folder in reversed(made):
        try:
            folder.rmdir()
        except OSError:
            return


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call `write(tmp)` on a temporary file beside `path`, then rename it over `path`: a reader (or a run
    killed half way) never sees a half-written file. Creates missing parent folders; on any failure removes
    the temporary file and the folders it made, and a disk's failure is an OutputError naming `path`."""
    path = Path(path)
    made = make_dirs(path.parent, path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as error:
        _unlink(tmp)
        remove_made(made)
        raise output_error(path, error) from None
    except BaseException:
        _unlink(tmp)
        remove_made(made)
        raise
    _fsync_dir(path.parent)
    return path


def atomic_write_bytes(path: str | Path, data: bytes | bytearray | memoryview) -> Path:
    """Write `data` to `path` atomically (flushed to disk before the rename)."""
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            f.write(data)
            _sync(f)

    return atomic_write(path, write)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write `text` to `path` atomically (UTF-8, flushed to disk before the rename)."""
    return atomic_write_bytes(path, text.encode())


def dumps(value: Any, where: str = "", **kwargs: Any) -> str:
    """`json.dumps` that refuses NaN and infinity (not JSON: the tool's readers refuse them) with an OutputError
    (naming `where`, the file it was for)."""
    try:
        return json.dumps(value, allow_nan=False, **kwargs)
    except ValueError:
        raise OutputError(f"cannot write {where or 'a JSON file'}: the data holds a number that is not JSON (NaN or "
                          "infinity)") from None


def atomic_write_json(path: str | Path, value: Any, **kwargs: Any) -> Path:
    """Write `value` as strict JSON (`dumps`, a final newline) to `path`, atomically."""
    return atomic_write_text(path, dumps(value, str(path), **kwargs) + "\n")


def append_line(path: str | Path, line: str) -> None:
    """Append `line` (ending in a newline) to the JSON Lines file at `path`, on disk when this returns; on a
    disk's failure the file is cut back to where it ended and OutputError names `path`."""
    data = line.encode()
    with open(path, "ab", buffering=0) as f:
        start = f.seek(0, os.SEEK_END)
        try:
            view = memoryview(data)
            while view:
                written = f.write(view)
                if not written:
                    raise OSError(errno.EIO, "the file took no more bytes")
                view = view[written:]
        except OSError as error:
            try:
                os.truncate(path, start)
            except OSError:
                pass
            raise output_error(path, error) from None


def _sync(f: IO[Any]) -> None:
    f.flush()
    os.fsync(f.fileno())


def _unlink(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


def _fsync_dir(directory: Path) -> None:
    """fsync a directory so a rename in it is durable (best effort: not every file system allows it)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
