"""`tamp evaluate` and `tamp reproduce` (registered through the `tamp.commands` entry point)."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add this package's subcommands to the `tamp` parser."""
