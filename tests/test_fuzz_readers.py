"""Every reader of a file from outside, fed mutated copies of a valid file (hypothesis): it returns, or
refuses with a one-line user error naming the file; never another exception (a traceback for the user)
or a warning, and nothing is written when it refuses.

Mutations: a value anywhere in the document replaced by another JSON value (numbers beyond float and
int64, deep lists, strings where numbers belong, ...), a field deleted, bytes flipped, inserted, deleted
or cut off, a number replaced by thousands of digits, a run of open brackets inserted, the whole
gzipped. TAMP_FUZZ_EXAMPLES sets the cases per reader (default 300, derandomized so that `make test`
is repeatable; any other value draws new cases each run):

    TAMP_FUZZ_EXAMPLES=10000 .venv/bin/python -m pytest -q tests/test_fuzz_readers.py
"""
from __future__ import annotations

import gzip
import json
import os
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tamp.errors import is_user_error

EXAMPLES = int(os.environ.get("TAMP_FUZZ_EXAMPLES", "300"))
FUZZ = settings(max_examples=EXAMPLES, derandomize="TAMP_FUZZ_EXAMPLES" not in os.environ, deadline=None,
                database=None, suppress_health_check=list(HealthCheck))
INIT = [[0.60, 0.15, 0.025, 1, 0], [0.70, -0.10, 0.025, 0, 1]]
GOAL = [[0.70, -0.10, 0.075, 1, 0], [0.70, -0.10, 0.025, 0, 1]]

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-10**400, max_value=10**400) | st.text(max_size=8)
    | st.floats(allow_nan=False, allow_infinity=False) | st.sampled_from([0, 1, -1, 99, 2**63, 1e308, "close"]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12)


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path into a JSON document (keys and indices), the root included."""
    out = [prefix]
    if isinstance(doc, dict):
        for key, value in doc.items():
            out += _paths(value, prefix + (key,))
    elif isinstance(doc, list):
        for i, value in enumerate(doc[:6]):  # the first items of long lists: enough places, bounded time
            out += _paths(value, prefix + (i,))
    return out


@st.composite
def mutated(draw, base: bytes, gz: bool = False) -> bytes:
    """A mutation of the valid file `base` (JSON text or JSON Lines); with `gz`, of the gzip of it (the
    text mutated, then compressed; or the compressed bytes mutated)."""
    if gz:
        if draw(st.booleans()):
            return gzip.compress(draw(mutated(base)))
        return _raw(draw, gzip.compress(base), cut=draw(st.booleans()))
    kind = draw(st.sampled_from(["value", "delete", "bytes", "cut", "digits", "brackets", "gzip"]))
    if kind in ("value", "delete"):
        lines = base.decode().splitlines()
        line = draw(st.integers(0, len(lines) - 1))
        doc = json.loads(lines[line])
        path = draw(st.sampled_from(_paths(doc)))
        if not path:
            doc = draw(JSON)
        else:
            parent = doc
            for key in path[:-1]:
                parent = parent[key]
            if kind == "delete":
                del parent[path[-1]]
            else:
                parent[path[-1]] = draw(JSON)
        lines[line] = json.dumps(doc)
        return ("\n".join(lines) + "\n").encode()
    if kind in ("bytes", "cut"):
        return _raw(draw, base, cut=kind == "cut")
    if kind == "digits":  # a number literal becomes thousands of digits
        text = base.decode()
        starts = [i for i, c in enumerate(text) if c.isdigit() and (i == 0 or not text[i - 1].isalnum())]
        at = draw(st.sampled_from(starts)) if starts else 0
        return (text[:at] + "9" * draw(st.sampled_from([21, 400, 5000])) + text[at:]).encode()
    if kind == "brackets":
        at = draw(st.integers(0, len(base)))
        return base[:at] + b"[" * draw(st.sampled_from([33, 1000, 100_000])) + base[at:]
    return gzip.compress(draw(mutated(base)))


def _raw(draw, base: bytes, cut: bool = False) -> bytes:
    """`base` cut short, or with a few bytes flipped, inserted or deleted."""
    if cut:
        return base[:draw(st.integers(0, len(base)))]
    data = bytearray(base)
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(data)))
        op = draw(st.sampled_from(["flip", "insert", "delete"]))
        if op == "flip" and at < len(data):
            data[at] ^= draw(st.integers(1, 255))
        elif op == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=4))
        else:
            del data[at:at + draw(st.integers(1, 8))]
    return bytes(data)


def _fuzz(reader: Callable[[Path], Any], base: bytes, path: Path, after: Callable[[], None] | None = None,
          gz: bool = False, names: Path | None = None):
    """The property on one reader: returns, or one-line user error naming `names` (default: `path`);
    `after` checks on refusal. `base`: the valid file's text (gzipped for the reader with `gz`)."""
    @FUZZ
    @given(data=mutated(base, gz))
    def run(data: bytes) -> None:
        path.write_bytes(data)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # a warning would be a second line for the user
                reader(path)
        except Exception as error:  # noqa: BLE001 - the property: which exceptions, and how they read
            assert is_user_error(error), f"{type(error).__name__}: {error}"
            message = str(error)
            assert "\n" not in message and str(names or path) in message, message
            if after is not None:
                after()

    run()


# --- the readers --------------------------------------------------------------------------------------

def test_problem_files(tmp_path):
    from tamp.app.problem import load_problem

    base = json.dumps({"X_init": INIT, "X_goal": GOAL, "k": 1, "seed": 7, "actions": [[0, 0, 1, 0]]}).encode()
    _fuzz(load_problem, base, tmp_path / "p.json")


def test_problem_sets(tmp_path):
    from tamp.app.problem import read_problem_set

    lines = [json.dumps({"name": f"n2-k1-{i:03d}", "X_init": INIT, "X_goal": GOAL, "k": 1, "seed": i,
                         "protocol": "strict", "moved": 1}) for i in range(3)]
    _fuzz(read_problem_set, ("\n".join(lines) + "\n").encode(), tmp_path / "set.jsonl")


def test_plan_files(tmp_path):
    from tamp.app.plan_file import load_plan_file

    _fuzz(load_plan_file, json.dumps({"X": INIT, "actions": [[0, 0, 1, 0], [0, 0, 0, 1]]}).encode(),
          tmp_path / "plan.json")


@pytest.mark.parametrize("name", ["operators.json", "operators.json.gz"])
def test_operators_files(tmp_path, name):
    from symbolic import load_domain, load_operators
    from symbolic.operators import to_json
    from symbolic.structs import OperatorSet
    from tamp.planning.models import pretrained_dir

    ops = load_domain(pretrained_dir() / "paper" / "domain")  # read once per test process (tests/conftest.py)
    small = json.dumps(to_json(OperatorSet(ops.operators[:6], ops.n_unary, ops.n_relations))).encode()
    _fuzz(load_operators, small, tmp_path / name, gz=name.endswith(".gz"))


def test_dataset_meta(tmp_path):
    from learned.dataset import FORMAT, read_meta

    meta = {"format": FORMAT, "n_max": 4, "world_config": {"dt": 0.002}, "seed": 0, "status_codes": {"ok": 0},
            "shard_size": 1000, "collection": {"objects": [2, 3], "shards": 1}}
    _fuzz(lambda path: read_meta(path.parent), json.dumps(meta).encode(), tmp_path / "meta.json")


def test_symbols_tables(tmp_path):
    from learned.interpret import read_symbols
    from tamp.planning.models import pretrained_dir

    table = json.loads((pretrained_dir() / "symbols.json").read_text())[:2]
    _fuzz(read_symbols, json.dumps(table).encode(), tmp_path / "symbols.json")


def test_table_one(tmp_path):
    from learned.ablation import read_table

    table = {"epochs": 3, "seed": 0, "num_train_val": 80, "num_test": 20, "zero_effect_cm": 4.0, "config": {},
             "training": {}, "activations": {"sigmoid": {"runs_cm": [1.0, 1.2], "val_cm": [1.1, 1.3], "epochs": [3, 3],
                                                         "run_ids": [0, 1], "in_progress": [{"run": 2}]}}}
    _fuzz(read_table, json.dumps(table).encode(), tmp_path / "ablation.json")


def _rows() -> list[dict]:
    return [{"problem": f"n2-k1-{i:03d}", "method": m, "n": 2, "k": 1, "run": 0, "solved": True, "success": i % 2 == 0,
             "outcome": "success" if i % 2 == 0 else "wrong_plan", "planning_time_s": 0.1, "level": 1,
             "refined": True, "refine_failure": None, "refine_time_s": [0.2]}
            for i in range(2) for m in ("cfs", "bilevel")]


def test_result_rows(tmp_path):
    from evaluation.report.rows import load_rows

    _fuzz(load_rows, "".join(json.dumps(r) + "\n" for r in _rows()).encode(), tmp_path / "rows.jsonl")


def test_gzipped_rows_of_a_comparison(tmp_path):
    from evaluation.compare import load_rows

    base = "".join(json.dumps(r) + "\n" for r in _rows()).encode()
    _fuzz(lambda path: load_rows(path.parent), base, tmp_path / "rows.jsonl.gz", gz=True)


def test_the_meta_file_of_a_resumed_evaluation(tmp_path):
    """`tamp evaluate` into a results directory compares its meta.json; a refused one is left as it was."""
    from evaluation.run import FORMAT, _prepare

    meta = {"format": FORMAT, "models_dir": "m", "model_files": {"dynamics.pt": "ab"}, "problems": "p",
            "problems_sha256": "cd", "n_problems": 2, "config": {"fidelity": "fast"}, "methods": ["cfs"],
            "versions": {"python": "3.11"}, "started": "now", "runs": []}
    path = tmp_path / "meta.json"
    written: dict[str, bytes] = {}

    def read(p: Path) -> None:
        written["before"] = p.read_bytes()
        _prepare(tmp_path, dict(meta))

    def unchanged() -> None:
        assert path.read_bytes() == written["before"] and sorted(tmp_path.iterdir()) == [path]

    _fuzz(read, json.dumps(meta).encode(), path, after=unchanged, names=tmp_path)  # a mismatch names the directory


@pytest.mark.sim
def test_trajectory_files(tmp_path):
    from tamp.app.runner import execute_plan, executed_trajectory
    from tamp.sim.trajectory_file import read_trajectory, write_trajectory

    ex = execute_plan([(0, 0, 1, 0)], np.array(INIT, float), np.array(GOAL, float), "fast")
    base = write_trajectory(tmp_path / "valid.json", executed_trajectory(ex, "fuzz")).read_bytes()
    _fuzz(read_trajectory, base, tmp_path / "t.json")


def test_search_records(tmp_path):
    from tamp.app.search_record import read_search_record, write_search_record

    node = {"id": 0, "parent": None, "order": 0, "action": None, "g": 0, "h": 0.5, "X": [[0.6, 0.15, 0.025]] * 2,
            "verdict": "ok", "reason": None}
    leaf = {**node, "id": 1, "parent": 0, "order": None, "action": [0, 0, 1, 0], "g": 1, "X": None,
            "verdict": "no_grasp", "reason": "rejected"}
    candidate = {"rank": 1, "actions": [[0, 0, 1, 0]], "count": 3, "probability": 1.0, "error_m": 0.01,
                 "verified": True, "chosen": True, "facts": [["o0 on o1"]], "predicted": [[[0.6, 0.15, 0.025]] * 2],
                 "kinematics": [{"verdict": "ok"}]}
    round_ = {"index": 0, "X_observed": INIT, "origin": "planned", "why": "level 1", "method": "bilevel", "level": 1,
              "plan": [[0, 0, 1, 0]], "timings_s": {"total": 0.1}, "reasons": [],
              "level1": {"candidates": [candidate], "stats": {}},
              "level2": {"status": "solved", "expanded": 1, "generated": 1, "truncated": False, "nodes": [node, leaf],
                         "path": [0]},
              "refinements": [{"level": 1, "plan": [[0, 0, 1, 0]], "outcome": "refined",
                               "actions": [{"ik_branch": "up", "planner": "direct", "time_s": 0.1, "failure": None}]}],
              "executed": {"action": [0, 0, 1, 0], "predicted": [[0.6, 0.15, 0.025]] * 2,
                           "observed": [[0.6, 0.15, 0.025]] * 2, "miss_m": 0.0}}
    record = {"format": "tamp-search-record", "version": 1, "config": {}, "symbols": {"names": {"u0": "on o1"}},
              "problem": {"name": None, "X_init": INIT, "X_goal": GOAL}, "rounds": [round_]}
    write_search_record(record, tmp_path / "valid.json")
    _fuzz(read_search_record, (tmp_path / "valid.json").read_bytes(), tmp_path / "s.json")
