"""Where results are kept: atomic writes, one writer per output directory, and the package versions
a result depends on. Standard library only, so every layer (planning, sim, app) and `evaluation`
use the same few functions."""
from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Callable, Iterator

from guarded import output
from tamp.errors import UserError

# the packages whose versions results depend on (read from metadata: nothing is imported)
PACKAGES = ("bilevel-tamp", "drake", "ompl", "ur-analytic-ik", "torch", "numpy")


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call `write(tmp)` on a temporary file beside `path`, then rename it over `path`: a reader (or a run
    killed half way) never sees a half-written file. Creates missing parent folders; a full disk, a read-only
    folder or a path that cannot be made is a one-line error naming `path`, and leaves nothing behind."""
    return output.atomic_write(path, write)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write `text` to `path` atomically (flushed to disk before the rename)."""
    return output.atomic_write_text(path, text)


@contextmanager
def exclusive(directory: Path, lock_name: str, what: str) -> Iterator[None]:
    """Hold `directory/lock_name` for the block; UserError if another process holds it (`what` names
    that process's command, e.g. "tamp collect"). The lock dies with its process (flock); the block's end
    removes the lock file, whatever ended it."""
    path = Path(directory) / lock_name
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as error:
            raise output.output_error(path, error) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise UserError(f"another {what} is writing to {directory}") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:  # its holder removed it between our open and our lock: take a new one
            same = False
        if same:
            break
        os.close(fd)
    try:
        yield
    finally:
        try:
            path.unlink(missing_ok=True)
        finally:
            os.close(fd)


@contextmanager
def output_dir(path: str | Path, flag: str, own: tuple[str, ...] = (), into_existing: bool = False
               ) -> Iterator[Path]:
    """Claim the output folder `path` for the block: create it (with `MARKER`), or take one that carries the
    marker, is empty, or holds one of the command's own files `own` (made before markers existed). A folder
    with other content is refused unless `into_existing` (the user said so): the tool never writes among
    what it did not make unasked. If the block raises, the folders and marker this claim made are removed
    again where nothing else was written in them: a failed run leaves the disk as it found it."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{flag} {path}: exists and is not a folder")
    marker = path / output.MARKER
    if path.is_dir() and not marker.exists() and not into_existing:
        entries = [p.name for p in path.iterdir()]
        if entries and not any(name in entries for name in own):
            raise UserError(f"{flag} {path}: a folder the tool did not make, and not empty ({len(entries)} "
                            f"entr{'y' if len(entries) == 1 else 'ies'}, e.g. {sorted(entries)[0]}); give a new or "
                            "empty folder")
    try:
        made = output.make_dirs(path)
    except output.OutputError as error:
        raise UserError(f"{flag} {path}: {str(error).split(': ', 1)[-1]}") from None
    new_marker = not marker.exists()
    try:
        if new_marker:
            output.atomic_write_text(marker, "made by tamp: the tool may replace what this folder holds\n")
        yield path
    except BaseException:
        if made:  # a folder this claim made: the empty folders written under it go too (never a file)
            for folder in sorted((p for p in path.rglob("*") if p.is_dir() and not p.is_symlink()), reverse=True):
                try:
                    folder.rmdir()
                except OSError:
                    pass
        if new_marker:
            marker.unlink(missing_ok=True)
        output.remove_made(made)
        raise


def made_by_tool(path: str | Path) -> bool:
    """Whether the folder `path` carries the marker of a folder the tool made (it may remove or replace it)."""
    return (Path(path) / output.MARKER).is_file()


def source_commit() -> str:
    """The git commit of the code that runs (with "+changes" when the checkout has uncommitted changes to
    tracked files), or "unknown" outside a git checkout: each report records what made it."""
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if head.returncode != 0:
        return "unknown"
    return head.stdout.strip() + ("+changes" if dirty.stdout.strip() else "")


def package_versions() -> dict[str, str]:
    """Versions of Python and of PACKAGES."""
    out = {"python": sys.version.split()[0]}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out
