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

from tamp.errors import UserError

# the packages whose versions results depend on (read from metadata: nothing is imported)
PACKAGES = ("bilevel-tamp", "drake", "ompl", "ur-analytic-ik", "torch", "numpy")


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call `write(tmp)` on a temporary file beside `path`, then rename it over `path`: a reader (or a
    run killed half way) never sees a half-written file. Creates missing parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write `text` to `path` atomically (flushed to disk before the rename)."""
    def write(tmp: Path) -> None:
        with open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())

    return atomic_write(path, write)


@contextmanager
def exclusive(directory: Path, lock_name: str, what: str) -> Iterator[None]:
    """Hold `directory/lock_name` for the block; UserError if another process holds it (`what` names
    that process's command, e.g. "tamp collect"). The lock dies with its process (flock)."""
    with open(Path(directory) / lock_name, "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UserError(f"another {what} is writing to {directory}") from None
        yield


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
