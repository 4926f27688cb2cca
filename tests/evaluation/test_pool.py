"""`tamp pool`: several evaluations as one results directory, one run per problem set."""
from __future__ import annotations

import gzip
import json

from evaluation.compare import compare_numbers, load_rows
from tamp.app.cli import main

META = {"format": "tamp-evaluation/1", "model_files": {"dynamics.pt": "ab12"}, "config": {"eps_m": 0.05},
        "methods": ["cfs", "bilevel"], "n_problems": 2, "runs": [{"workers": 2}]}


def row(problem, method, success, run=0, n=5):
    return {"problem": problem, "run": run, "method": method, "n": n, "k": 1, "success": success,
            "solved": success, "outcome": "success" if success else "no_plan", "planning_time_s": 0.1}


def write(directory, rows, meta=META, packed=False, **changes):
    directory.mkdir()
    (directory / "meta.json").write_text(json.dumps({**meta, **changes}))
    text = "".join(json.dumps(r) + "\n" for r in rows)
    if packed:
        with gzip.open(directory / "rows.jsonl.gz", "wt") as f:
            f.write(text)
    else:
        (directory / "rows.jsonl").write_text(text)
    return directory


def test_pooled_sets_become_runs_with_distinct_names_and_report_together(tmp_path, capsys):
    a = write(tmp_path / "seed21", [row("n5-k1-000", "cfs", True), row("n5-k1-000", "bilevel", False)],
              problems="s21.jsonl")
    b = write(tmp_path / "seed33-45", [row("r0-n5-k1-000", "cfs", False, run=0),
                                       row("r1-n5-k1-000", "cfs", True, run=1)], packed=True,
              problems="s3345.jsonl", methods=["cfs"])
    out = tmp_path / "pooled"
    assert main(["pool", str(out), str(a), str(b)]) == 0
    assert "seed33-45: 2 rows, run 0 -> 1, 1 -> 2" in capsys.readouterr().out
    rows = load_rows(out)
    assert [(r["problem"], r["run"], r["method"], r["success"]) for r in rows] == [
        ("r0-n5-k1-000", 0, "cfs", True), ("r0-n5-k1-000", 0, "bilevel", False),
        ("r1-n5-k1-000", 1, "cfs", False), ("r2-n5-k1-000", 2, "cfs", True)]
    meta = json.loads((out / "meta.json").read_text())
    assert meta["problems"] == ["s21.jsonl", "s3345.jsonl"] and meta["n_problems"] == 4
    assert meta["methods"] == ["cfs", "bilevel"] and "runs" not in meta
    assert meta["pooled"][1]["runs"] == {"0": 1, "1": 2}
    assert main(["report", str(out)]) == 0  # every table over the three runs
    assert "| runs | 3 |" in (out / "report.md").read_text()

    # the same sets pooled again pair with this one, problem by problem
    again = tmp_path / "again"
    assert main(["pool", str(again), str(a), str(b)]) == 0
    assert compare_numbers(load_rows(out), load_rows(again))["pairs"] == 4


def test_pooling_refuses_other_models_a_repeated_set_and_existing_rows(tmp_path, capsys):
    a = write(tmp_path / "a", [row("n5-k1-000", "cfs", True)])
    other = write(tmp_path / "other", [row("n5-k1-000", "cfs", True)], model_files={"dynamics.pt": "ff00"})
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "rows.jsonl").write_text(json.dumps(row("n5-k1-000", "cfs", True)) + "\n")
    cases = [([str(a), str(other)], "differ in meta.json 'model_files'"),
             ([str(a), str(tmp_path / "a" / ".")], "given twice"),
             ([str(a)], "at least two"),
             ([str(a), str(bare)], "no meta.json"),
             ([str(a), str(tmp_path / "missing")], "no results directory")]
    for sources, message in cases:
        assert main(["pool", str(tmp_path / "out"), *sources]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (sources, err)
    assert not (tmp_path / "out" / "rows.jsonl").exists()
    b = write(tmp_path / "b", [row("n5-k1-000", "cfs", False)])
    assert main(["pool", str(tmp_path / "out"), str(a), str(b)]) == 0
    before = (tmp_path / "out" / "rows.jsonl").read_text()
    assert main(["pool", str(tmp_path / "out"), str(b), str(a)]) == 2
    assert "already holds" in capsys.readouterr().err
    assert (tmp_path / "out" / "rows.jsonl").read_text() == before
