"""Nothing lost, whatever the disk, the folder or the model (issue 81): outputs never destroy what the tool did
not make, never half-write, and a run that fails leaves the disk as it found it.

The full-disk cases mount a small tmpfs (root only; skipped elsewhere); the writers' own cases fail the write
path with ENOSPC by hand. The commands that need the simulator are in tests/tamp/app/test_outputs.py."""
from __future__ import annotations

import errno
import math
import os
import shutil
import subprocess
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import guarded
from guarded import OutputError, append_line, atomic_write, atomic_write_json, dumps, read_json, read_jsonl
from tamp.app.cli import build_parser, main
from tamp.errors import UserError
from tamp.planning.models import pretrained_dir
from tamp.records import exclusive, made_by_tool, output_dir


def tree(root: Path) -> list[tuple[str, bytes | None]]:
    """Every path under `root` with its content (None for folders): what "as it found it" compares."""
    return sorted((str(p.relative_to(root)), None if p.is_dir() else p.read_bytes()) for p in root.rglob("*"))


# --------------------------------------------------------------------------- a full file system

@pytest.fixture
def full_disk(tmp_path):
    """A folder on a tmpfs of 256 kB filled to the last byte (ENOSPC on the next write)."""
    with tmpfs(tmp_path / "full") as mount:
        fill(mount)
        yield mount


@contextmanager
def tmpfs(mount: Path, options: str = "size=256k"):
    """A tmpfs mounted at the new folder `mount` for the block (the test is skipped without root)."""
    mount.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mount)],
                                           capture_output=True).returncode != 0:
        pytest.skip("mounting a tmpfs needs root")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def fill(mount: Path) -> None:
    """Fill the file system of `mount` to the last byte (ENOSPC on the next write)."""
    with open(mount / ".filler", "wb", buffering=0) as f:
        try:
            while f.write(b"\0" * 4096):
                pass
        except OSError as error:
            assert error.errno == errno.ENOSPC


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from learned.synthetic import write_synthetic_dataset

    return write_synthetic_dataset(tmp_path_factory.mktemp("data") / "d", 200, seed=0)


@pytest.fixture(scope="module")
def problem_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("problem") / "p.json"
    line = (Path(__file__).parent / "data" / "tail-problems.jsonl").read_text().splitlines()[0]
    path.write_text(line + "\n")
    return path


@pytest.fixture(scope="module")
def small_models(tmp_path_factory) -> Path:
    """The bundled networks with the first 6 operators of their domain: what `tamp pddl` writes stays small."""
    from symbolic import load_domain
    from symbolic.operators import to_json
    from symbolic.structs import OperatorSet

    models = tmp_path_factory.mktemp("models")
    for name in ("symbolic.pt", "dynamics.pt"):
        shutil.copy(pretrained_dir() / name, models / name)
    ops = load_domain(pretrained_dir() / "domain")
    atomic_write_json(models / "domain" / "operators.json",
                      to_json(OperatorSet(ops.operators[:6], ops.n_unary, ops.n_relations)))
    return models


def refused_on_full_disk(capsys, full: Path, argv: list[str]) -> str:
    """Run `argv` with its output on the full disk: exit 2, one line naming a path on it, and the disk's folder
    as it was (no file, folder, temporary or lock left)."""
    before = tree(full)
    assert main(argv) == 2
    err = capsys.readouterr().err
    (line,) = [line for line in err.splitlines() if f"tamp {argv[0]}: error:" in line]  # beside progress bars
    assert line.endswith("No space left on device") and f"cannot write {full}" in line, err
    assert "Traceback" not in err
    assert tree(full) == before
    return line


def test_full_disk_pddl(capsys, full_disk, problem_file, small_models):
    models = ["--models", str(small_models)]
    refused_on_full_disk(capsys, full_disk, ["pddl", *models, "--out", str(full_disk / "pddl")])
    refused_on_full_disk(capsys, full_disk, ["pddl", *models, "--out", str(full_disk / "pddl"), "--problem",
                                             str(problem_file), "--sampled", "2"])


def test_full_disk_dataset_stats(capsys, full_disk, dataset):
    refused_on_full_disk(capsys, full_disk, ["dataset-stats", str(dataset), "--png", str(full_disk / "s.png")])


def test_full_disk_train(capsys, full_disk, dataset):
    refused_on_full_disk(capsys, full_disk, ["train", "--data", str(dataset), "--out", str(full_disk / "m.pt"),
                                             "--epochs", "1"])


def test_full_disk_domain(capsys, full_disk, dataset):
    refused_on_full_disk(capsys, full_disk, ["domain", "--model", str(pretrained_dir() / "symbolic.pt"), "--data",
                                             str(dataset), "--out", str(full_disk / "dom")])


def test_full_disk_symbols(capsys, full_disk, dataset):
    refused_on_full_disk(capsys, full_disk, ["symbols", "--model", str(pretrained_dir() / "symbolic.pt"), "--data",
                                             str(dataset), "--json", str(full_disk / "s.json")])


def test_full_disk_ablate(capsys, full_disk, dataset):
    refused_on_full_disk(capsys, full_disk, ["ablate-activations", "--data", str(dataset), "--out-dir",
                                             str(full_disk / "ab"), "--runs", "1", "--epochs", "1"])


# --------------------------------------------------------------------------- writers that fail half way

class HalfWriter:
    """A binary file whose writes stop after `room` bytes with ENOSPC (a disk filling up under a write)."""

    def __init__(self, f, room: int) -> None:
        self.f, self.room = f, room

    def write(self, data) -> int:
        data = bytes(data)
        if len(data) > self.room:
            self.f.write(data[:self.room])
            self.f.flush()
            self.room = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.f.close()


def failing_open(room: int):
    real = open

    def fake(path, mode="r", *args, **kwargs):
        f = real(path, mode, *args, **kwargs)
        return HalfWriter(f, room) if any(c in mode for c in "wa") else f
    return fake


def written_on_a_small_disk(monkeypatch, room: int, write: Callable[[], object], path: Path) -> bool:
    """Run `write` with every file it opens for writing full after `room` bytes (ENOSPC): whether it wrote. A
    write that did not fit is one error naming `path`."""
    monkeypatch.setattr("builtins.open", failing_open(room))
    try:
        write()
        return True
    except OutputError as error:
        assert str(error) == f"cannot write {path}: No space left on device"
        return False
    finally:
        monkeypatch.undo()


JSON = st.recursive(st.none() | st.booleans() | st.integers(-2**53, 2**53) | st.text(max_size=20)
                    | st.floats(allow_nan=False, allow_infinity=False, width=64),
                    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
                    max_leaves=30)
CASES = settings(max_examples=int(os.environ.get("TAMP_FUZZ_EXAMPLES", "60")), deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])


@CASES
@given(value=JSON)
def test_what_is_written_is_read_back_equal(tmp_path, value):
    path = atomic_write_json(tmp_path / "sub" / "v.json", value)
    assert read_json(path, "file") == value
    assert sorted(p.name for p in path.parent.iterdir()) == ["v.json"]  # no temporary left


@CASES
@given(old=JSON, new=JSON, room=st.integers(0, 200))
def test_an_interrupted_write_leaves_the_old_file_and_nothing_else(tmp_path, monkeypatch, old, new, room):
    folder = tmp_path / f"w{room}"
    path = atomic_write_json(folder / "v.json", old)
    text = dumps(new) + "\n"
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            f.write(text.encode())

    wrote = written_on_a_small_disk(monkeypatch, room, lambda: atomic_write(path, write), path)
    assert sorted(p.name for p in folder.iterdir()) == ["v.json"]
    assert read_json(path, "file") == (new if wrote else old)


def test_an_unmakeable_or_read_only_path_is_one_line_naming_it(tmp_path):
    (tmp_path / "a-file").write_text("x")
    with pytest.raises(OutputError, match=r"cannot write .*a-file/sub/v\.json: Not a directory"):
        atomic_write_json(tmp_path / "a-file" / "sub" / "v.json", 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


def test_a_read_only_file_system_is_one_line_naming_the_path(tmp_path):
    with tmpfs(tmp_path / "ro", "size=64k,ro") as mount:
        with pytest.raises(OutputError, match=rf"cannot write {mount}/new/v\.json: Read-only file system"):
            atomic_write_json(mount / "new" / "v.json", 1)
        assert main(["pddl", "--out", str(mount / "pddl")]) == 2


@CASES
@given(rows=st.lists(st.dictionaries(st.text(max_size=6), JSON, max_size=4), min_size=1, max_size=6),
       room=st.integers(0, 100))
def test_rows_appended_read_back_and_a_full_disk_cuts_back_to_the_last_line(tmp_path, monkeypatch, rows, room):
    path = tmp_path / f"rows{room}.jsonl"
    path.unlink(missing_ok=True)
    for row in rows[:-1]:
        append_line(path, dumps(row) + "\n")
    before = path.read_bytes() if path.exists() else b""
    monkeypatch.setattr("builtins.open", failing_open(room))
    line = dumps(rows[-1]) + "\n"
    try:
        append_line(path, line)
        full = False
    except OutputError:
        full = True
    finally:
        monkeypatch.undo()
    assert full == (len(line.encode()) > room)
    assert path.read_bytes() == (before if full else before + line.encode())
    assert [r for _, r in read_jsonl(path, "rows").values] == (rows[:-1] if full else rows)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, [1.0, {"x": math.nan}]])
def test_no_number_that_is_not_json_is_written(tmp_path, bad):
    with pytest.raises(OutputError, match="not JSON"):
        atomic_write_json(tmp_path / "v.json", {"v": bad})
    assert not list(tmp_path.iterdir())


def test_a_row_holding_nan_is_written_as_an_error_row(tmp_path):
    from evaluation.run import read_rows, row_line

    path = tmp_path / "rows.jsonl"
    append_line(path, row_line({"problem": "p", "method": "cfs", "planning_time_s": math.nan, "plan": [[0, 0, 1, 0]],
                                "final_error_m": [math.inf], "outcome": "failed", "success": True}))
    (row,) = read_rows(path)
    assert row["outcome"] == "error" and row["success"] is False and row["plan"] == [[0, 0, 1, 0]]
    assert row["planning_time_s"] is None and row["final_error_m"] is None
    assert "planning_time_s" in row["error"] and "final_error_m" in row["error"]


# --------------------------------------------------------------------------- folders the tool did not make

def test_a_foreign_folder_is_not_written_into_and_a_failed_claim_leaves_nothing(tmp_path):
    user = tmp_path / "user"
    user.mkdir()
    (user / "thesis.tex").write_text("mine")
    with pytest.raises(UserError, match="did not make"):
        with output_dir(user, "--out"):
            pass
    assert tree(user) == [("thesis.tex", b"mine")]
    with output_dir(user, "--out", into_existing=True):  # told to
        pass
    new = tmp_path / "a" / "b"
    with pytest.raises(RuntimeError):
        with output_dir(new, "--out"), exclusive(new, ".lock", "test"):
            (new / "deep" / "er").mkdir(parents=True)
            raise RuntimeError("failed")
    assert not (tmp_path / "a").exists()
    with output_dir(new, "--out"), exclusive(new, ".lock", "test"):
        pass
    assert made_by_tool(new) and sorted(p.name for p in new.iterdir()) == [guarded.MARKER]  # the lock released


def test_the_lock_is_one_writer_at_a_time_and_removed(tmp_path):
    with exclusive(tmp_path, ".lock", "tamp test"):
        with pytest.raises(UserError, match="another tamp test is writing"):
            with exclusive(tmp_path, ".lock", "tamp test"):
                pass
    assert not (tmp_path / ".lock").exists()


def test_practice_never_replaces_a_models_folder_of_the_users(tmp_path, dataset):
    from evaluation.practice import PracticeConfig, link_models, practise

    out = tmp_path / "out"
    (out / "models").mkdir(parents=True)
    (out / "models" / "mine.pt").write_text("the user's")
    (out / "practice.json").write_text("{}")  # even in a folder that looks like a practice
    before = tree(out)
    with pytest.raises(UserError, match="did not make"):
        practise(pretrained_dir(), [dataset], out, PracticeConfig(rounds=1, per_cell=1, objects=(2,)), progress=False)
    with pytest.raises(UserError, match="did not make"):
        link_models(out / "models", pretrained_dir())
    assert tree(out) == before
    (out / "models" / "mine.pt").unlink()
    (out / "models").rmdir()
    link_models(out / "models", pretrained_dir())  # a link of its own it replaces
    link_models(out / "models", pretrained_dir() / "paper")
    assert (out / "models").resolve() == (pretrained_dir() / "paper").resolve()


@pytest.mark.parametrize("flags", [["--objects", "9"], ["--objects", "2,2"], ["--objects", "0"]])
def test_practice_checks_its_flags_before_writing_anything(tmp_path, capsys, dataset, flags):
    out = tmp_path / "practice"
    assert main(["practice", "--data", str(dataset), "--out", str(out), "--quiet", *flags]) == 2
    assert "--objects" in capsys.readouterr().err
    assert not out.exists()


def test_practice_refuses_a_foreign_nonempty_out_before_writing(tmp_path, capsys, dataset):
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["practice", "--data", str(dataset), "--out", str(tmp_path), "--quiet", "--rounds", "1"]) == 2
    assert "did not make" in capsys.readouterr().err
    assert tree(tmp_path) == [("notes.txt", b"mine")]


# --------------------------------------------------------------------------- outputs after checks

def test_pddl_checks_the_models_before_writing(tmp_path, capsys, problem_file):
    models = tmp_path / "models"
    shutil.copytree(pretrained_dir() / "domain", models / "domain")  # a domain, but no networks
    out = tmp_path / "out"
    assert main(["pddl", "--models", str(models), "--problem", str(problem_file), "--out", str(out)]) == 2
    assert "symbolic.pt" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models"]


def test_an_output_files_folder_is_made_only_when_it_is_written(tmp_path):
    from tamp.app.args import check_output_file

    check_output_file(tmp_path / "new" / "deeper" / "r.html", "--replay")
    assert not (tmp_path / "new").exists()


# --------------------------------------------------------------------------- models checked when loaded

def damaged(tmp_path: Path, name: str, change) -> Path:
    """A copy of the bundled models whose `name` network has `change(state_dict)` applied."""
    models = tmp_path / "models"
    shutil.copytree(pretrained_dir(), models, ignore=shutil.ignore_patterns(
        "paper", "pairwise", "spatial", "regions", "random", "practised"))
    payload = torch.load(models / name, weights_only=True)
    state = payload["state_dict"] if "state_dict" in payload else payload["members"][0]["state_dict"]
    change(state)
    torch.save(payload, models / name)
    return models


def first_weight(state: dict) -> torch.Tensor:
    return next(v for k, v in state.items() if k.endswith("weight"))


@pytest.mark.parametrize("name", ["dynamics.pt", "symbolic.pt"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_weights_are_refused_naming_the_file(tmp_path, name, value):
    from tamp.planning.models import load_models

    models = damaged(tmp_path, name, lambda s: first_weight(s).view(-1)[0].fill_(value))
    with pytest.raises(ValueError, match=rf"{models / name}: the model's weights are not finite"):
        load_models(models)


def test_weights_that_overflow_on_a_probe_scene_are_refused(tmp_path):
    from tamp.planning.models import load_models

    def overflow(state: dict) -> None:
        for k, v in state.items():
            if k.endswith("weight") and v.is_floating_point():
                v.fill_(1e30)

    models = damaged(tmp_path, "dynamics.pt", overflow)
    with pytest.raises(ValueError, match=rf"{models / 'dynamics.pt'}: the model predicts non-finite"):
        load_models(models)


def test_a_model_with_nan_weights_is_refused_before_any_output(tmp_path, capsys, problem_file):
    models = damaged(tmp_path, "dynamics.pt", lambda s: first_weight(s).fill_(math.nan))
    out = tmp_path / "pddl"
    assert main(["pddl", "--models", str(models), "--problem", str(problem_file), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "dynamics.pt" in err and "not finite" in err
    assert not out.exists()


# --------------------------------------------------------------------------- bounds

def test_every_count_flag_states_its_limit_and_refuses_beyond_it(capsys):
    from tamp.app.args import Count

    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    checked = 0
    for name, command in commands.items():
        for action in command._actions:
            if isinstance(action.type, Count):
                assert f"{action.type.limit:,}" in action.help, (name, action.option_strings)
                with pytest.raises(argparse_error()):
                    action.type(str(action.type.limit + 1))
                assert action.type(str(action.type.limit)) == action.type.limit
                checked += 1
    assert checked >= 30


def argparse_error():
    import argparse

    return argparse.ArgumentTypeError


def test_a_huge_count_flag_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["problems", "--out", "x.jsonl", "--per-cell", str(10**12)])
    assert exit_.value.code == 2 and "1..100,000" in capsys.readouterr().err


def test_a_huge_number_of_sampled_domains_is_refused(tmp_path, capsys):
    from tamp.inputs import MAX_DOMAINS
    from tamp.planning.config import Level1Config

    with pytest.raises(UserError, match="n_domains"):
        Level1Config(n_domains=10**12)
    config = tmp_path / "c.toml"
    config.write_text(f"[level1]\nn_domains = {MAX_DOMAINS + 1}\n")
    assert main(["config", "show", "--config", str(config)]) == 2
    assert "n_domains" in capsys.readouterr().err


def test_max_k_of_the_parser_is_the_problems():
    from tamp.app import args, problem

    assert args.MAX_K == problem.MAX_K


@pytest.mark.parametrize("flag", ["--samples", "--actions-per-scene", "--scenes-per-shard"])
def test_collect_sizes_are_bounded_and_say_so(tmp_path, capsys, flag):
    values = {"--samples": "10", "--actions-per-scene": "10", "--scenes-per-shard": "20", flag: str(10**15)}
    argv = ["collect", *(x for item in values.items() for x in item), "--out", str(tmp_path / "d"), "--quiet"]
    assert main(argv) == 2
    assert f"{flag} must be at most" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
    commands = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    (action,) = [a for a in commands["collect"]._actions if flag in a.option_strings]
    assert "at most" in action.help


def test_pddl_never_replaces_a_sampled_folder_it_did_not_make(tmp_path, capsys, small_models):
    models = ["--models", str(small_models)]
    out = tmp_path / "pd"
    (out / "sampled").mkdir(parents=True)
    (out / "sampled" / "notes.txt").write_text("mine")
    (out / "domain.pddl").write_text("an old export")  # looks like an export, but carries no marker
    before = tree(tmp_path)
    assert main(["pddl", *models, "--out", str(out), "--sampled", "2"]) == 2
    assert "did not make" in capsys.readouterr().err
    assert tree(tmp_path) == before
    fresh = tmp_path / "fresh"
    assert main(["pddl", *models, "--out", str(fresh), "--sampled", "2"]) == 0
    assert main(["pddl", *models, "--out", str(fresh), "--sampled", "3"]) == 0  # its own sampled/ it replaces
    assert len(list((fresh / "sampled").glob("domain_*.pddl"))) == 3 and made_by_tool(fresh)
    assert not [p for p in tmp_path.iterdir() if "staging" in p.name]
