"""Search record files: written atomically, read back through the guarded reader and the schema; damaged,
truncated, nested-bomb and other-version records refused in one line; `--search` checked before any work.
Stub models: no Drake, no torch."""
from __future__ import annotations

import json

import numpy as np
import pytest

from guarded import InputError
from learned.interpret import BitNames
from tamp.app.cli import main
from tamp.app.search_record import SearchRecording, read_search_record, write_search_record
from tamp.errors import is_user_error
from tamp.planning.closed_loop import plan_closed_loop
from tamp.planning.config import Level1Config, PlanConfig
from tamp.planning.models import Models
from tamp.planning.search_trace import recording
from tests.planning_stubs import StubModel, two_block_domain, world_step
from tests.test_no_data_loss import written_on_a_small_disk

X_INIT = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
GOAL = world_step(X_INIT, (0, 0, 1, 1))  # block 0 released beside B: Level 2's


@pytest.fixture(scope="module")
def record() -> dict:
    """The record of a closed loop on the stub world (every round, with its executed step)."""
    stub = StubModel()
    models = Models(dynamics=stub, symbolic=stub, domain=two_block_domain())
    search = SearchRecording({"name": "toy", "X_init": X_INIT, "X_goal": GOAL}, {"planner": "stub"},
                             BitNames({"u0": ("on the table", False)}))
    world = [X_INIT]

    def step(action) -> np.ndarray:
        world.append(world_step(world[-1], action))
        search.executed(action, world[-1])
        return world[-1]

    with recording(search.recorder):
        plan_closed_loop("bilevel", models, X_INIT, GOAL, step, None, PlanConfig(level1=Level1Config(n_domains=50)),
                         on_round=lambda r, result: search.planned(result))
    return search.document()


def test_a_record_round_trips_through_the_guarded_reader(record, tmp_path):
    path = tmp_path / "search.json"
    write_search_record(record, path)
    back = read_search_record(path)
    assert back == json.loads(json.dumps(record))
    assert back["format"] == "tamp-search-record" and back["version"] == 1
    assert back["symbols"]["names"] == {"u0": "on the table"} and back["problem"]["name"] == "toy"
    first = back["rounds"][0]
    assert first["level2"]["path"] and first["executed"]["action"] == first["plan"][0]
    assert "\n" not in path.read_text().rstrip("\n")  # compact: one line


def _refused(path, match: str) -> str:
    with pytest.raises(Exception) as info:
        read_search_record(path)
    message = str(info.value)
    assert is_user_error(info.value) and "\n" not in message and str(path) in message and match in message, message
    return message


def test_damaged_truncated_nested_and_other_version_records_are_refused_in_one_line(record, tmp_path):
    path = tmp_path / "search.json"
    text = json.dumps(record)
    path.write_text(text.replace('"rounds"', '"rounds" "'))
    _refused(path, "not valid JSON")
    path.write_text(text[:len(text) // 2])  # cut short, as by a full disk or a kill
    _refused(path, "not valid JSON")
    path.write_text('{"format": "tamp-search-record", "version": 1, "rounds": ' + "[" * 100_000 + "]" * 100_000 + "}")
    _refused(path, "nested deeper than")
    path.write_text(json.dumps({**record, "version": 2}))
    _refused(path, "search record version 2; this tamp reads version 1")
    path.write_text(json.dumps({**record, "format": "tamp-trajectory"}))
    _refused(path, "not a tamp search record")
    bad = json.loads(text)
    bad["rounds"][0]["level2"]["nodes"][0]["h"] = "far"
    path.write_text(json.dumps(bad))
    _refused(path, "rounds[0].level2.nodes[0].h: expected a number")
    bad = json.loads(text)
    del bad["rounds"][0]["level1"]["candidates"]
    path.write_text(json.dumps(bad))
    _refused(path, "missing field 'candidates'")
    with pytest.raises(InputError, match="no search record at"):
        read_search_record(tmp_path / "missing.json")


def test_a_record_that_does_not_fit_is_not_written(record, tmp_path, monkeypatch):
    path = tmp_path / "search.json"
    bad = {**record, "rounds": [{**record["rounds"][0], "origin": "guessed"}]}
    with pytest.raises(InputError, match="being written"):  # checked as it will read back, before writing
        write_search_record(bad, path)
    assert not path.exists()
    assert not written_on_a_small_disk(monkeypatch, 100, lambda: write_search_record(record, path), path)
    assert list(tmp_path.iterdir()) == []


def test_the_search_flag_is_checked_before_any_work(tmp_path, capsys):
    problem = tmp_path / "p.json"
    problem.write_text(json.dumps({"X_init": X_INIT.tolist(), "X_goal": GOAL.tolist()}))
    (tmp_path / "taken.json").mkdir()
    assert main(["plan", "--problem", str(problem), "--search", str(tmp_path / "taken.json"), "--execute", "none"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--search" in err and "folder" in err
    with pytest.raises(SystemExit) as info:
        main(["plan", "--problem", str(problem), "--search", str(tmp_path / "s.txt")])
    assert info.value.code == 2 and "ending in .json" in capsys.readouterr().err


@pytest.mark.sim
@pytest.mark.slow
def test_tamp_plan_writes_the_record_of_every_round_of_its_closed_loop(tmp_path, capsys):
    from tests.paths import ROOT

    problems, path = ROOT / "results/problems/strict-n2-4-s781.jsonl.gz", tmp_path / "out/search.json"
    code = main(["plan", "--problem", str(problems), "--name", "n3-k4-000", "--replan", "--search", str(path)])
    out = capsys.readouterr().out
    record = read_search_record(path)
    assert code in (0, 1) and f"search record written to {path}" in out
    rounds = record["rounds"]
    assert len(rounds) == out.count("\nround ") + out.startswith("round ") >= 1
    assert record["problem"]["name"] == "n3-k4-000" and record["symbols"]["names"]
    first = rounds[0]
    assert first["level"] == 1 and sum(c["chosen"] for c in first["level1"]["candidates"]) == 1
    chosen = next(c for c in first["level1"]["candidates"] if c["chosen"])
    assert chosen["facts"] and all(k["verdict"] == "ok" for k in chosen["kinematics"])  # checked and refined
    assert first["refinements"] and first["refinements"][-1]["outcome"] == "refined"
    assert all(a["ik_branch"] for a in first["refinements"][-1]["actions"])
    executed = [r["executed"] for r in rounds if r["executed"] is not None]
    assert executed and all(e["miss_m"] >= 0 for e in executed)
    view = path.with_name("search.html")  # the view beside the record, with the record embedded
    assert f"its view to {view}" in out and '"tamp-search-record"' in view.read_text()
