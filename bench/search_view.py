"""How fast the search view (`tamp view --search`) opens a large Level 2 tree in headless Chromium.

    .venv/bin/python bench/search_view.py [--record RECORD.json ...] [--repeats 5]

Writes the view of synthetic records (tests/tamp/app/search_records.py) with a tree of 15 nodes (the baseline),
1,500 nodes (the target: at most 1 s) and 6,000 nodes (about what 1,500 expansions generate), and of each
--record given, then opens each page `--repeats` times in Debian's Chromium (headless, a fresh tab each time) and
prints the medians of:

- render: from the start of the navigation to the end of the page's script, the tree drawn (the page's own
  `performance.now()`, which counts from the navigation's start: reading the file, parsing the HTML and the JSON);
- painted: the same to the next frame after it;
- expand all: a click on "expand all" until every node's row is in the page and laid out;
- filter: choosing "only the rejected successors" until its rows are laid out.

The ratio is each page's render against the 15-node baseline, measured in the same run.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tamp.app.search_view import write_search_view
from tests.browser import CHROMIUM, Browser
from tests.tamp.app.search_records import search_record

TIMED = """(async () => {
  const frame = () => new Promise(r => requestAnimationFrame(() => setTimeout(r, 0)));
  const t0 = performance.now();
  document.getElementById('expand-all').click();
  document.getElementById('tree').getBoundingClientRect();
  await frame();
  const expand = performance.now() - t0, rows = document.querySelectorAll('#tree .row').length;
  const f = document.getElementById('filter'), t1 = performance.now();
  f.value = 'rejected'; f.dispatchEvent(new Event('change'));
  document.getElementById('tree').getBoundingClientRect();
  await frame();
  return {expand: expand, rows: rows, filter: performance.now() - t1};
})()"""


def measure(browser: Browser, page: Path, repeats: int) -> dict[str, float]:
    runs = []
    for _ in range(repeats):
        browser.open(page)
        browser.eval("new Promise(r => requestAnimationFrame(() => setTimeout(r, 0)))")
        times = browser.eval("window.tampSearchView")
        runs.append({"render": times["renderMs"], "painted": times["paintedMs"], **browser.eval(TIMED)})
        if browser.errors():
            raise SystemExit(f"{page}: console errors: {browser.errors()}")
    return {key: statistics.median(run[key] for run in runs) for key in runs[0]}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--record", type=Path, action="append", default=[], help="a search record to time as well")
    p.add_argument("--repeats", type=int, default=5, help="page loads per page (default 5)")
    args = p.parse_args()
    if CHROMIUM is None:
        raise SystemExit("needs Debian's chromium (apt-get install chromium)")
    folder = Path(tempfile.mkdtemp(prefix="tamp-search-view-"))
    pages = {}
    for n in (15, 1500, 6000):
        pages[f"synthetic, {n:,} nodes"] = write_search_view(search_record(n_nodes=n, rounds=1), folder / f"{n}.html")
    for k, record in enumerate(args.record):
        pages[record.name] = write_search_view(json.loads(record.read_text()), folder / f"record{k}.html")
    with Browser() as browser:
        results = {name: measure(browser, page, args.repeats) for name, page in pages.items()}
    base = results["synthetic, 15 nodes"]["render"]
    print(f"Chromium {CHROMIUM}, median of {args.repeats} loads (ms)")
    print(f"{'page':28s} {'size kB':>8s} {'render':>8s} {'painted':>8s} {'ratio':>6s} {'expand all':>11s} "
          f"{'rows':>6s} {'filter':>7s}")
    for name, r in results.items():
        print(f"{name:28s} {pages[name].stat().st_size / 1e3:8.0f} {r['render']:8.0f} {r['painted']:8.0f} "
              f"{r['render'] / base:6.2f} {r['expand']:11.0f} {r['rows']:6.0f} {r['filter']:7.0f}")
    worst = results["synthetic, 1,500 nodes"]["painted"]
    print(f"1,500 nodes: painted in {worst:.0f} ms ({'within' if worst <= 1000 else 'OVER'} the 1 s target)")
    return 0 if worst <= 1000 else 1


if __name__ == "__main__":
    sys.exit(main())
