"""`tamp compare`: two results directories paired per (problem, run, method)."""
from __future__ import annotations

import gzip
import json

import pytest
from scipy import stats

from evaluation.compare import compare_markdown, compare_numbers, load_rows


def row(problem, method, n, success, t, run=0):
    return {"problem": problem, "run": run, "method": method, "n": n, "success": success, "planning_time_s": t}


BEFORE = [row("n5-k1-000", "cfs", 5, True, 0.1), row("n5-k2-000", "cfs", 5, False, 9.0),
          row("n5-k3-000", "cfs", 5, True, 0.3), row("n6-k1-000", "cfs", 6, True, 0.2),
          row("n5-k1-000", "bilevel", 5, True, 0.05), row("n9-k9-999", "cfs", 5, True, 1.0)]  # last: before only
AFTER = [row("n5-k1-000", "cfs", 5, True, 0.1), row("n5-k2-000", "cfs", 5, True, 0.5),
         row("n5-k3-000", "cfs", 5, False, 0.4), row("n6-k1-000", "cfs", 6, True, 0.3),
         row("n5-k1-000", "bilevel", 5, True, 0.04), row("n5-k1-000", "bilevel_replan", 5, True, 0.2)]


def test_the_cells_pair_problems_and_name_what_was_gained_and_lost():
    numbers = compare_numbers(BEFORE, AFTER)
    assert numbers["pairs"] == 5 and numbers["only_before"] == 1 and numbers["only_after"] == 1
    assert numbers["errors"] == 0
    assert list(numbers["methods"]) == ["cfs", "bilevel"]  # bilevel_replan has no 'before'
    five = numbers["methods"]["cfs"][5]
    assert five["problems"] == 3 and five["success_before_pct"] == pytest.approx(200 / 3)
    assert five["success_after_pct"] == pytest.approx(200 / 3)
    assert five["gained"] == ["n5-k2-000"] and five["lost"] == ["n5-k3-000"]
    assert five["p"] == pytest.approx(stats.ttest_rel([1, 0, 1], [1, 1, 0]).pvalue)
    assert five["time_before_median_s"] == pytest.approx(0.3) and five["time_after_mean_s"] == pytest.approx(1.0 / 3)
    every = numbers["methods"]["cfs"]["all"]
    assert every["problems"] == 4 and every["gained"] == ["n5-k2-000"]
    assert numbers["methods"]["bilevel"][5]["p"] is None  # one pair: no test
    assert compare_numbers(BEFORE, BEFORE)["methods"]["cfs"][5]["p"] == "identical"
    text = compare_markdown(numbers, "old", "new")
    assert "| `cfs` | 5 | 3 | 66.7 -> 66.7 |" in text and "1: n5-k2-000" in text and "(run" not in text


def test_a_crashed_row_is_counted_and_left_out():
    crashed = dict(row("n5-k3-000", "cfs", 5, False, 0.0), outcome="error")
    after = [r for r in AFTER if (r["problem"], r["method"]) != ("n5-k3-000", "cfs")] + [crashed]
    numbers = compare_numbers(BEFORE, after)
    five = numbers["methods"]["cfs"][5]
    assert numbers["errors"] == 1 and five["problems"] == 2 and five["lost"] == []  # a crash is not "lost"
    assert "1 with an error row" in compare_markdown(numbers, "a", "b")


def test_rows_pair_by_run_too():
    # `tamp problems --runs` names problems r{run}-...; rows of one name in two runs are two problems
    before = [row("n5-k1-000", "cfs", 5, True, 0.1, run=0), row("n5-k1-000", "cfs", 5, False, 0.1, run=1)]
    after = [row("n5-k1-000", "cfs", 5, True, 0.1, run=0), row("n5-k1-000", "cfs", 5, True, 0.1, run=1)]
    cell = compare_numbers(before, after)["methods"]["cfs"][5]
    assert cell["problems"] == 2 and cell["success_before_pct"] == 50.0 and cell["success_after_pct"] == 100.0


def test_the_command_reads_shipped_gzip_rows_and_refuses_unrelated_directories(tmp_path, capsys):
    from tamp.app.cli import main

    old, new, other = tmp_path / "old", tmp_path / "new", tmp_path / "other"
    for d in (old, new, other):
        d.mkdir()
    with gzip.open(old / "rows.jsonl.gz", "wt") as f:
        f.writelines(json.dumps(r) + "\n" for r in BEFORE)
    (new / "rows.jsonl").write_text("".join(json.dumps(r) + "\n" for r in AFTER))
    (other / "rows.jsonl").write_text(json.dumps(row("x", "cfs", 2, True, 0.1)) + "\n")
    assert load_rows(old) == BEFORE
    assert main(["compare", str(old), str(new)]) == 0
    assert "n5-k3-000" in capsys.readouterr().out
    out = tmp_path / "cmp.md"
    assert main(["compare", str(old), str(new), "--out", str(out)]) == 0
    assert out.read_text().startswith("# Before and after")
    assert main(["compare", str(old), str(other)]) == 2
    assert "share no (problem, run, method) row" in capsys.readouterr().err
    assert main(["compare", str(old), str(tmp_path / "missing")]) == 2
    assert main(["compare", str(old), str(tmp_path)]) == 2  # a directory without rows
    assert "no rows.jsonl" in capsys.readouterr().err
