"""The search view: one self-contained HTML page of a search record (`tamp plan --search`), for studying what the
planner considered in each round of the closed loop and why it dropped the rest: Level 1's ranked symbolic plans,
Level 2's tree, the scenes they predict, and the refinement of the chosen plan into motion.

The page works offline: its style and script are inline (`search_view.css`, `search_view.js` beside this module),
the record is embedded as JSON, and its Content-Security-Policy lets it load nothing from anywhere. Level 2's tree
puts a node's children in the page only when the node is expanded, so a 1,500-node tree opens as fast as a small
one. `tamp view --search FILE` writes it.
"""
from __future__ import annotations

import html
import os
from importlib import resources
from pathlib import Path
from typing import Any

from guarded.output import dumps
from tamp.records import atomic_write_text

DATA_ID = "tamp-search-data"  # the <script type="application/json"> element that holds the record
_CSP = ("default-src 'none'; style-src 'unsafe-inline'; script-src 'unsafe-inline'; img-src data:; "
        "base-uri 'none'; form-action 'none'")
# In a JSON string these four stay JSON and cannot end the <script> element, open a comment or start an entity.
_ESCAPES = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026", "\u2028": "\\u2028", "\u2029": "\\u2029"}


def embedded_json(value: Any, where: str = "the search view") -> str:
    """`value` as strict JSON that is safe inside a <script> element: no `</script>`, `<!--` or `&` survives."""
    return "".join(_ESCAPES.get(c, c) for c in dumps(value, where, separators=(",", ":")))


def _asset(name: str) -> str:
    return resources.files("tamp.app").joinpath(name).read_text(encoding="utf-8")


def replay_href(record: dict[str, Any], out: Path) -> str | None:
    """The record's Meshcat replay (`replay`: a path as `tamp plan --replay` was given it, or absent) as a link
    relative to the page at `out`, or None when the record names no replay."""
    replay = record.get("replay")
    if not isinstance(replay, str) or not replay:
        return None
    target = Path(replay).resolve()
    relative = os.path.relpath(target, Path(out).resolve().parent)
    return Path(relative).as_posix()


def page(record: dict[str, Any], replay: str | None = None) -> str:
    """The page's HTML: the record embedded, `replay` (a link to its Meshcat replay) when given."""
    problem = record.get("problem") or {}
    name = problem.get("name") if isinstance(problem, dict) else None
    title = f"Search: {name}" if name else "Search"
    data = {"record": record, "replay": replay}
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<meta http-equiv=\"Content-Security-Policy\" content=\"{_CSP}\">\n"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
        "<link rel=\"icon\" href=\"data:,\">\n"
        f"<title>{html.escape(title)}</title>\n<style>\n{_asset('search_view.css')}</style>\n</head>\n<body>\n"
        "<noscript>This page draws the search with JavaScript; enable it to see the search.</noscript>\n"
        "<div id=\"app\"></div>\n"
        f"<script type=\"application/json\" id=\"{DATA_ID}\">{embedded_json(data)}</script>\n"
        f"<script>\n{_asset('search_view.js')}</script>\n</body>\n</html>\n"
    )


def write_search_view(record: dict[str, Any], out: Path) -> Path:
    """Write the search view of `record` to `out` (atomically; the folders it needs are made); returns `out`."""
    return atomic_write_text(out, page(record, replay_href(record, out)))


def summary(record: dict[str, Any]) -> str:
    """One line on what the record holds: its rounds, Level 1's candidates and Level 2's nodes."""
    rounds = record.get("rounds") or []
    candidates = sum(len((r.get("level1") or {}).get("candidates") or []) for r in rounds)
    nodes = sum(len((r.get("level2") or {}).get("nodes") or []) for r in rounds)
    executed = sum(1 for r in rounds if r.get("executed"))
    return (f"{len(rounds)} round(s), {executed} executed step(s); Level 1: {candidates} candidate plan(s); "
            f"Level 2: {nodes:,} node(s)")
