"""`tamp collect` / `tamp dataset-stats`: resumable after kill -9, identical whatever the workers or
backend, corrupt shards named and re-collected, clear user errors, outcome classes."""
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from learned.dataset import load_transitions, shard_paths
from tamp.app.cli import main
from tamp.app.collect import CollectConfig
from tamp.app.dataset_stats import classify

# 58 samples = 8 scenes of 8 actions (the last one trimmed to 2) in 4 shards of 2 scenes (the last one trimmed to
# 10 samples). Long scenes: few block-type layouts, whose Drake plants each collecting process builds.
PARAMS = ["--samples", "58", "--objects", "2,3", "--actions-per-scene", "8", "--scenes-per-shard", "2",
          "--seed", "1", "--quiet"]
N_SHARDS = 4


def collect_cli(out: Path, *extra: str) -> list[str]:
    return ["collect", *PARAMS, "--out", str(out), *extra]


def arrays(directory: Path) -> dict[str, np.ndarray]:
    return load_transitions(directory).arrays()


def assert_same_dataset(a: Path, b: Path) -> None:
    A, B = arrays(a), arrays(b)
    for key in A:
        np.testing.assert_array_equal(A[key], B[key], err_msg=key)
    assert (a / "meta.json").read_text() == (b / "meta.json").read_text()
    assert [p.name for p in shard_paths(a)] == [p.name for p in shard_paths(b)]


def inodes(directory: Path) -> dict[str, int]:
    return {p.name: p.stat().st_ino for p in shard_paths(directory)}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """An uninterrupted run with one worker (in this process)."""
    out = tmp_path_factory.mktemp("ref") / "ds"
    assert main(collect_cli(out, "--workers", "1")) == 0
    return out


@pytest.mark.sim
@pytest.mark.slow
def test_reference_layout_and_content(reference):
    data = load_transitions(reference)
    assert len(data) == 58
    sizes = [int(np.load(p)["n"].shape[0]) for p in shard_paths(reference)]
    assert sizes == [16] * 3 + [10]
    assert set(np.unique(data.n)) == {2, 3} and data.n_max == 3
    # Chained: within a scene each action starts from the previous outcome.
    for s in range(len(data) - 1):
        if (s + 1) % 8:
            np.testing.assert_array_equal(data.X[s + 1], data.X_next[s])
    # Failures change nothing; every status is represented by a valid code.
    failed = data.status != 0
    assert failed.any() and (~failed).any()
    np.testing.assert_array_equal(data.X[failed], data.X_next[failed])
    assert np.all(data.grasped[failed] == -1)
    cfg = CollectConfig(samples=58, objects=(3, 2), actions_per_scene=8, scenes_per_shard=2)
    assert (cfg.n_scenes, cfg.n_shards, cfg.shard_samples(3), cfg.scene_samples(7)) == (8, 4, 10, 2)


@pytest.mark.sim
@pytest.mark.slow
def test_workers_1_and_2_give_the_same_dataset(reference, tmp_path):
    assert main(collect_cli(tmp_path / "w2", "--workers", "2")) == 0
    assert_same_dataset(reference, tmp_path / "w2")


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.sim
@pytest.mark.slow
def test_kill_9_mid_way_then_resume_equals_uninterrupted_run(reference, tmp_path, capsys):
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "tamp.app.cli", *collect_cli(out, "--workers", "1")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not (out.exists() and any(p.name.startswith("shard-") for p in out.iterdir())):
        assert proc.poll() is None, proc.stderr.read().decode()
        assert time.monotonic() < deadline, "no shard within 60 s"
        time.sleep(0.01)
    workers = _children(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stderr.close()
    before = inodes(out)
    assert 1 <= len(before) < N_SHARDS, "the run finished before it was killed; nothing was tested"
    # Orphaned pool workers notice their parent is gone and exit.
    deadline = time.monotonic() + 10
    while any(Path(f"/proc/{pid}").exists() for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(Path(f"/proc/{pid}").exists() for pid in workers), "pool workers outlived the collector"

    assert main(collect_cli(out, "--workers", "1")) == 0
    report = capsys.readouterr().out
    assert f"{N_SHARDS - len(before)} written now, {len(before)} already there" in report
    assert_same_dataset(reference, out)
    assert {k: v for k, v in inodes(out).items() if k in before} == before  # kept, not recomputed
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


@pytest.mark.sim
@pytest.mark.slow
def test_ray_backend_gives_the_same_dataset(reference, tmp_path):
    pytest.importorskip("ray", reason="ray is not installed (optional extra: pip install ray)")
    out = tmp_path / "ray"
    run = subprocess.run([sys.executable, "-m", "tamp.app.cli",
                          *collect_cli(out, "--backend", "ray", "--workers", "1")],
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr
    assert_same_dataset(reference, out)


@pytest.mark.sim
@pytest.mark.slow
def test_corrupt_and_truncated_shards_are_named_skipped_and_recollected(reference, tmp_path, capsys):
    out = tmp_path / "damaged"
    shutil.copytree(reference, out)
    truncated, corrupt = out / "shard-000001.npz", out / "shard-000002.npz"
    truncated.write_bytes(truncated.read_bytes()[:300])
    with np.load(corrupt) as z:  # a readable zip whose content is inconsistent
        bad = dict(z)
    bad["mask"] = ~bad["mask"]
    with open(corrupt, "wb") as f:
        np.savez(f, **bad)
    untouched = {k: v for k, v in inodes(out).items() if k not in (truncated.name, corrupt.name)}

    assert main(["dataset-stats", str(out), "--png", str(tmp_path / "h.png")]) == 0
    captured = capsys.readouterr()
    for name in (truncated.name, corrupt.name):
        assert f"skipping corrupt shard {name}" in captured.err
        assert f"skipped corrupt shard {name}" in captured.out
    assert "# " + str(out) + ": 26 samples" in captured.out  # 58 - 2 x 16 readable

    assert main(collect_cli(out, "--workers", "1")) == 0
    captured = capsys.readouterr()
    for name in (truncated.name, corrupt.name):
        assert f"corrupt shard {name}" in captured.err and "re-collected" in captured.err
    assert "2 written now, 2 already there, 2 corrupt re-collected" in captured.out
    assert_same_dataset(reference, out)
    assert {k: v for k, v in inodes(out).items() if k in untouched} == untouched


@pytest.mark.parametrize("argv, message", [
    (["collect", "--samples", "10", "--objects", "2,9"], "object counts must be in 1..8, got 9"),
    (["collect", "--samples", "0"], "--samples must be a positive integer, got 0"),
    (["collect", "--samples", "10", "--address", "auto"], "--address joins a Ray cluster; use it with --backend ray"),
])
def test_bad_arguments_exit_2_with_one_line(argv, message, tmp_path, capsys):
    assert main([*argv, "--out", str(tmp_path / "d"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()


@pytest.mark.sim
def test_existing_directory_with_other_parameters_is_refused(reference, tmp_path, capsys):
    out = tmp_path / "other"
    shutil.copytree(reference, out)
    before = inodes(out)
    args = collect_cli(out, "--workers", "1")
    args[args.index("--seed") + 1] = "4"
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "other parameters (seed 1 -> 4)" in err and len(err.strip().splitlines()) == 1
    assert inodes(out) == before
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("not a dataset")
    assert main(collect_cli(tmp_path / "notes")) == 2
    assert "is not empty and has no meta.json" in capsys.readouterr().err


def _moved(directory: Path) -> np.ndarray:
    data = arrays(directory)
    return np.abs(data["X_next"][..., :3] - data["X"][..., :3]).max(axis=(1, 2)) > 0.01


@pytest.mark.sim
@pytest.mark.slow
def test_graspable_sampling_grasps_something_and_combines_with_uniform_data(reference, tmp_path, capsys):
    out = tmp_path / "graspable"
    assert main(collect_cli(out, "--workers", "1", "--sampling", "graspable")) == 0
    data = load_transitions(out)
    codes = data.meta["status_codes"]
    assert len(data) == 58 and not np.any(data.status == codes["nothing_grasped"])
    assert np.mean(_moved(out)) > np.mean(_moved(reference)) + 0.1
    assert data.meta["collection"]["sampling"] == "graspable"
    assert "sampling" not in load_transitions(reference).meta["collection"]  # the paper's, as before
    assert len(load_transitions([reference, out])) == 116  # the same world: they train together
    capsys.readouterr()
    assert main(collect_cli(out, "--workers", "1")) == 2  # resuming it as uniform data is refused
    assert "other parameters" in capsys.readouterr().err


@pytest.mark.sim
def test_dataset_stats_table_and_png(reference, tmp_path, capsys):
    png = tmp_path / "stats.png"
    assert main(["dataset-stats", str(reference), "--png", str(png)]) == 0
    out = capsys.readouterr().out
    data = load_transitions(reference)
    for n in (2, 3):
        assert f"| {n} | {int((data.n == n).sum())} |" in out
    failed = int((data.status != 0).sum())
    rows = [line for line in out.splitlines() if "_failure" in line or "nothing_grasped" in line]
    assert sum(int(line.split("|")[2]) for line in rows) == failed
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def _block(x, y, z, large=False):
    return [x, y, z, 0.0, 1.0] if large else [x, y, z, 1.0, 0.0]


@pytest.mark.parametrize("large, after, grasped, status, expected", [
    (False, [_block(0.5, 0.0, 0.025), _block(0.5, 0.0, 0.075)], 1, "ok", "stacked"),
    (True, [_block(0.5, 0.0, 0.025), _block(0.5, 0.1, 0.075, large=True)], 1, "ok", "stacked"),  # bar across
    (False, [_block(0.5, 0.0, 0.025), _block(0.7, 0.1, 0.025)], 1, "ok", "moved"),
    (True, [_block(0.5, 0.0, 0.025), _block(0.7, 0.2, 0.125, large=True)], 1, "ok", "toppled"),  # on end
    (False, [_block(0.5, 0.0, 0.025), _block(0.56, 0.0, 0.045)], 1, "ok", "toppled"),  # leaning on 0
    (False, [_block(0.5, 0.0, 0.025), _block(0.7, 0.2, 0.025)], -1, "nothing_grasped", "nothing_grasped"),
])
def test_outcome_classes(large, after, grasped, status, expected):
    X = np.array([_block(0.5, 0.0, 0.025), _block(0.7, 0.2, 0.025, large=large)])
    assert classify(X, np.array(after), grasped, status) == expected
    assert classify(X, X.copy(), grasped, "ok") == "unchanged"


def test_ray_backend_without_ray_says_how_to_install(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    assert main(collect_cli(tmp_path / "d", "--backend", "ray")) == 2
    err = capsys.readouterr().err
    assert "pip install" in err and "ray" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()
