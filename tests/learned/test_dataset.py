"""Dataset shards: writer/reader round trip, resume, validation with file names, effect algebra."""
import json
import zipfile

import numpy as np
import pytest
import torch

from learned.dataset import DatasetWriter, ShardError, TransitionDataset, load_transitions, read_meta, shard_paths
from learned.effects import arm_displacement, arm_shift, effect_targets
from learned.synthetic import STATUS_CODES, apply_action, generate, write_synthetic_dataset


@pytest.fixture()
def data_dir(tmp_path):
    return write_synthetic_dataset(tmp_path / "ds", 200, seed=3, shard_size=64)


def test_round_trip_matches_generator(data_dir):
    ref = generate(200, seed=3)
    got = load_transitions(data_dir)
    assert [p.name for p in shard_paths(data_dir)] == [f"shard-{i:06d}.npz" for i in range(4)]
    assert not [p for p in data_dir.iterdir() if ".tmp" in p.name]
    for k, v in ref.arrays().items():
        assert got.arrays()[k].dtype == v.dtype, k
        np.testing.assert_array_equal(got.arrays()[k], v, err_msg=k)
    meta = read_meta(data_dir)
    assert meta["format"] == "tamp-transitions/1" and meta["n_max"] == 4 and meta["seed"] == 3
    assert meta["status_codes"] == STATUS_CODES and "numpy" in meta["versions"]
    # Some of each outcome, including blocks carried that were not the pick object.
    assert 0 < (got.status == STATUS_CODES["nothing_grasped"]).mean() < 0.6
    assert set(np.unique(got.n)) == {2, 3, 4}


def test_writer_resumes_and_refuses_other_world(data_dir):
    extra = generate(10, seed=9)
    with DatasetWriter(data_dir, n_max=4, seed=3, status_codes=STATUS_CODES,
                       world_config={"synthetic": True, "noise_m": 0.002}, shard_size=64) as w:
        assert w.num_samples == 200
        for s in range(len(extra)):
            n = int(extra.n[s])
            w.add(extra.X[s, :n], tuple(extra.action[s]), extra.X_next[s, :n],
                  int(extra.grasped[s]), int(extra.status[s]))
    assert shard_paths(data_dir)[-1].name == "shard-000004.npz"
    assert len(load_transitions(data_dir)) == 210
    with pytest.raises(ValueError, match="world_config"):
        DatasetWriter(data_dir, n_max=4, seed=3, status_codes=STATUS_CODES,
                      world_config={"synthetic": False})


def test_writer_rejects_invalid_samples(tmp_path):
    w = DatasetWriter(tmp_path / "d", n_max=3, seed=0, status_codes=STATUS_CODES, world_config={})
    X = np.array([[0.5, 0.0, 0.025, 1, 0], [0.6, 0.1, 0.025, 0, 1]])
    with pytest.raises(ValueError, match="status codes"):
        w.add(X, (0, 0, 1, 0), X, -1, 7)
    with pytest.raises(ValueError, match="out of range"):
        w.add(X, (0, 0, 2, 0), X, -1, 0)  # place index 2 does not exist for n=2
    with pytest.raises(ValueError, match="one-hot"):
        w.add(X[:, [0, 1, 2, 3, 3]], (0, 0, 1, 0), X[:, [0, 1, 2, 3, 3]], -1, 0)
    with pytest.raises(ValueError, match="n_max"):
        w.add(np.tile(X, (2, 1)), (0, 0, 1, 0), np.tile(X, (2, 1)), -1, 0)
    w.add(X, (0, 0, 1, 0), X, -1, 1)
    assert w.num_samples == 1 and w.flush().name == "shard-000000.npz"
    assert len(load_transitions(tmp_path / "d")) == 1


def test_truncated_shard_is_reported_by_name(data_dir):
    bad = shard_paths(data_dir)[2]
    bad.write_bytes(bad.read_bytes()[:1000])
    with pytest.raises(ShardError, match=bad.name) as err:
        load_transitions(data_dir)
    assert err.value.path == bad
    with pytest.warns(UserWarning, match=bad.name):
        partial = load_transitions(data_dir, skip_corrupt=True)
    assert partial.skipped == [str(bad)] and len(partial) == 200 - 64


def test_flipped_bytes_fail_the_crc(data_dir):
    bad = shard_paths(data_dir)[1]
    raw = bytearray(bad.read_bytes())
    with zipfile.ZipFile(bad) as z:  # corrupt the payload of X, not the zip structure
        info = z.getinfo("X.npy")
    pos = info.header_offset + 30 + len(info.filename) + 200
    raw[pos:pos + 8] = b"\x7f" * 8  # overwrite 8 bytes of X data
    bad.write_bytes(bytes(raw))
    with pytest.raises(ShardError, match=bad.name):
        load_transitions(data_dir)


def test_inconsistent_shard_content_is_reported(data_dir):
    bad = shard_paths(data_dir)[0]
    with np.load(bad) as z:
        arrays = {k: z[k] for k in z.files}
    s = int(np.flatnonzero(arrays["n"] < 4)[0])
    arrays["mask"][s, :] = True  # claims padded rows are objects
    np.savez(bad, **arrays)
    with pytest.raises(ShardError, match=f"{bad.name}: mask inconsistent"):
        load_transitions(data_dir)
    (data_dir / "meta.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="format"):
        load_transitions(data_dir)


def test_torch_dataset_items_and_loader(data_dir):
    ds = TransitionDataset(data_dir)
    item = ds[5]
    assert item["X"].shape == (4, 5) and item["mask"].dtype == torch.bool
    assert int(item["mask"].sum()) == int(item["n"])
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=16)))
    assert batch["X"].shape == (16, 4, 5) and batch["action"].shape == (16, 4)


def test_effect_reconstructs_next_state_exactly(data_dir):
    d = load_transitions(data_dir)
    t = d.tensors()
    X, Xn, A, M = t["X"].double(), t["X_next"].double(), t["action"], t["mask"]
    e = effect_targets(X, Xn, A, M)
    rebuilt = (X[..., :3] + e + arm_shift(X, A)) * M[..., None]
    torch.testing.assert_close(rebuilt, Xn[..., :3], rtol=0, atol=1e-12)
    # Successful moves: target of the picked block is small, its absolute move is not.
    ok = (d.status == 0) & (d.grasped == d.action[:, 0]) & (d.action[:, 0] != d.action[:, 2])
    rows = np.flatnonzero(ok)
    picked = e[rows, A[rows, 0], :2].norm(dim=-1)
    moved = (Xn - X)[rows, A[rows, 0], :2].norm(dim=-1)
    assert picked.max() < 0.02 and moved.mean() > 0.1


def test_arm_displacement_by_hand():
    # small cube at (0.5, 0, .025), bar at (0.7, 0.2, .025)
    X = np.array([[0.5, 0.0, 0.025, 1, 0], [0.7, 0.2, 0.025, 0, 1]])
    a = (1, -1, 0, 1)  # grasp the bar 7.5 cm below its centre, release 7.5 cm above the cube's
    arm = arm_displacement(torch.tensor(X)[None], torch.tensor([a]))[0].numpy()
    np.testing.assert_allclose(arm, [0.5 - 0.7, (0.0 + 0.075) - (0.2 - 0.075)])
    Xn, grasped, status = apply_action(X, a)
    assert grasped == 1 and status == 0  # keeps its offset to the gripper: centre not on the cube
    np.testing.assert_allclose(Xn[1, :3], [0.5, 0.2 + arm[1], 0.025])
    Xn, grasped, status = apply_action(X, (0, 0, 1, 1))  # cube onto the bar's +y end
    assert grasped == 0 and status == 0
    np.testing.assert_allclose(Xn[0, :3], [0.7, 0.275, 0.075])
    # a cube resting on the +y end of a bar
    Xs = np.array([[0.7, 0.275, 0.075, 1, 0], [0.7, 0.2, 0.025, 0, 1], [0.5, 0.1, 0.025, 1, 0]])
    Xn, grasped, status = apply_action(Xs, (1, -1, 1, -1))  # release where grasped
    np.testing.assert_allclose(Xn, Xs)
    Xn, grasped, status = apply_action(Xs, (1, 1, 2, 0))  # grasp at y .275: the cube on top
    assert grasped == 0
    np.testing.assert_allclose(Xn[0, :3], [0.5, 0.1, 0.075])  # now on the other cube
    Xn, grasped, status = apply_action(Xs, (1, -1, 2, 0))  # the bar at y .125, with the cube
    assert grasped == 1
    np.testing.assert_allclose(Xn[:2, :3], [[0.5, 0.25, 0.075], [0.5, 0.175, 0.025]])
    Xn, grasped, status = apply_action(X, (0, 1, 1, 0))  # beside the small cube: nothing
    assert grasped == -1 and status == STATUS_CODES["nothing_grasped"]
    np.testing.assert_array_equal(Xn, X)


def test_several_directories_load_as_one_dataset_padded_to_the_largest_scenes(tmp_path):
    """Data collected apart (2-4 blocks, then 5-6) trains together: concatenated in the order given,
    the smaller scenes padded with absent objects, each source recorded."""
    small = write_synthetic_dataset(tmp_path / "small", 120, seed=1, shard_size=50)
    large = write_synthetic_dataset(tmp_path / "large", 80, seed=2, shard_size=50, n_max=6, n_choices=(5, 6))
    a, b = load_transitions(small), load_transitions(large)
    both = load_transitions([small, large])
    assert len(both) == 200 and both.n_max == 6 and both.meta["n_max"] == 6
    np.testing.assert_array_equal(both.X[:120, :4], a.X)
    assert not both.mask[:120, 4:].any() and not both.X[:120, 4:].any()
    np.testing.assert_array_equal(both.X[120:], b.X)
    np.testing.assert_array_equal(both.action, np.concatenate([a.action, b.action]))
    assert set(np.unique(both.n)) == {2, 3, 4, 5, 6}
    assert [(s["path"], s["seed"], s["n_max"], s["samples"]) for s in both.meta["sources"]] == [
        (str(small), 1, 4, 120), (str(large), 2, 6, 80)]
    assert "seed" not in both.meta  # no single seed describes the whole
    assert len(load_transitions([small])) == 120


def test_several_directories_must_be_distinct_and_of_one_world(tmp_path):
    small = write_synthetic_dataset(tmp_path / "small", 60, seed=1)
    with pytest.raises(ValueError, match="given twice"):
        load_transitions([small, tmp_path / "small"])
    other = write_synthetic_dataset(tmp_path / "other", 60, seed=2)
    meta = json.loads((other / "meta.json").read_text())
    meta["world_config"]["noise_m"] = 0.01
    (other / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"other: its world_config differs .*small's"):
        load_transitions([small, other])
    with pytest.raises(ValueError, match="no dataset directory"):
        load_transitions([])


def test_datasets_that_differ_only_in_how_paths_were_simplified_combine(tmp_path):
    """Practice records its executed steps with simplified paths, the collection without: one world."""
    random = write_synthetic_dataset(tmp_path / "random", 60, seed=1)
    practice = write_synthetic_dataset(tmp_path / "practice", 40, seed=2)
    meta = json.loads((practice / "meta.json").read_text())
    meta["world_config"]["simplify_paths"] = True
    (practice / "meta.json").write_text(json.dumps(meta))
    assert len(load_transitions([random, practice])) == 100
