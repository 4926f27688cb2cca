"""What the `tamp` commands take: argparse types for numbers and output paths that check before any
work is done (a bad value is a one-line error). Shared by every command, `evaluation`'s included."""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from tamp.errors import UserError
from tamp.inputs import MAX_DOMAINS, SEED_LIMIT  # noqa: F401 (MAX_DOMAINS: the bound of --sampled)
from tamp.planning.validate import MAX_OBJECTS  # noqa: F401 (the bound of the count flags of objects)


def _number(text: str, parse, ok, expected: str):
    """argparse type helper: `parse(text)` if it succeeds and satisfies `ok`, else an error naming `expected`."""
    try:
        value = parse(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
    if not ok(value):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return value


COUNT_LIMIT = 1_000_000  # a count flag's largest value unless it has its own: what memory and a run's lifetime hold
WORKERS_LIMIT = 1024  # worker processes or Ray actors: each holds a world (hundreds of MB) or a network
MAX_K = 100  # goal-generating actions of a problem (`tamp.app.problem.MAX_K`, which imports more than a parser needs)


class Count:
    """argparse type: an integer in [low, limit]. The machine holds no more than `limit` (lists, processes or
    tensors of that length); `tamp.app.cli.build_parser` states the limit in every such flag's help."""

    def __init__(self, low: int, limit: int = COUNT_LIMIT) -> None:
        self.low, self.limit = low, limit
        self.__name__ = f"an integer in {low}..{limit:,}"  # argparse names the type so in its messages

    def __call__(self, text: str) -> int:
        return _number(text, int, lambda v: self.low <= v <= self.limit, f"an integer in {self.low}..{self.limit:,}")

    def __repr__(self) -> str:
        return f"Count({self.low}, {self.limit})"


positive_int = Count(1)  # argparse type: an integer in 1..COUNT_LIMIT (`Count(1, N)` for another limit)
non_negative_int = Count(0)  # argparse type: an integer in 0..COUNT_LIMIT


def int_list(text: str) -> tuple[int, ...]:
    """argparse type: comma-separated integers, e.g. 2,3,4."""
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected integers like 1,2,3, got {text!r}") from None


def object_count(text: str) -> int:
    """argparse type: a number of objects >= 2 (a block and an object to place it on)."""
    return _number(text, int, lambda v: v >= 2, "an integer >= 2")


def seed(text: str) -> int:
    """argparse type: a seed, an integer in [0, 2^63) (`tamp.inputs.SEED_LIMIT`), as problem files take them."""
    return _number(text, int, lambda v: 0 <= v < SEED_LIMIT, "an integer in [0, 2^63)")


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (nan and inf refused)."""
    return _number(text, float, lambda v: math.isfinite(v) and v > 0, "a finite number > 0")


# name -> folder under tamp/pretrained/
BUNDLED_MODELS = {"pretrained": "", "paper": "paper", "pairwise": "pairwise", "spatial": "spatial",
                  "regions": "regions", "random": "random", "practised": "practised"}
MODELS_HELP = ("a models directory (symbolic.pt, dynamics.pt, domain/), or a bundled set: pretrained, paper, "
               "pairwise, spatial, regions, random or practised (tamp/pretrained/PROVENANCE.md says what each is)")


def models_directory(text: str) -> Path:
    """argparse type: a models directory, or the name of a bundled set (`BUNDLED_MODELS`) when no such
    path exists here."""
    path = Path(text)
    if not path.exists() and text in BUNDLED_MODELS:
        from tamp.planning.models import pretrained_dir

        return pretrained_dir() / BUNDLED_MODELS[text]
    return path


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    return _number(text, float, lambda v: math.isfinite(v) and v >= 0, "a finite number >= 0")


def metres_below(limit: float):
    """argparse type: a distance in metres, 0 <= d < `limit`."""
    def parse(text: str) -> float:
        return _number(text, float, lambda v: 0 <= v < limit, f"a distance in metres, 0 <= d < {limit:g}")
    return parse


def fraction(text: str) -> float:
    """argparse type: a number in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text!r}")
    return value


def probability(text: str) -> float:
    """argparse type: a number in [0, 1]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}")
    return value


def _writable_folder(folder: Path, flag: str, target: Path) -> None:
    """The nearest existing folder of `folder` (itself or an ancestor) must be a writable folder."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise UserError(f"{flag} {target}: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {target}: {existing} is not writable")


def check_output_file(path: str | Path, flag: str = "--out") -> Path:
    """Check before any work that the output file `path` can be written (not a folder, its folder
    writable or makeable); nothing is created (its missing folders are made when it is written, so a run
    that fails first leaves none). ValueError naming the flag otherwise."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{flag} {path}: is a folder; give a file path")
    if path.exists() and not os.access(path, os.W_OK):
        raise UserError(f"{flag} {path}: the file is not writable")
    _writable_folder(path.parent, flag, path)
    return path


def check_output_dir(path: str | Path, flag: str = "--out") -> Path:
    """Check before any work that the output folder `path` is a folder or can be made one, writable;
    nothing is created. ValueError naming the flag otherwise."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{flag} {path}: exists and is not a folder")
    _writable_folder(path, flag, path)
    return path


def _html_path(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in (".html", ".htm"):
        raise argparse.ArgumentTypeError(f"the replay is an HTML file; give a path ending in .html, got {text!r}")
    return path


def json_path(text: str) -> Path:
    """argparse type: a path ending in .json."""
    path = Path(text)
    if path.suffix.lower() != ".json":
        raise argparse.ArgumentTypeError(f"expected a JSON file path ending in .json, got {text!r}")
    return path
