"""Activation ablation (Table I): runs per activation on a shared held-out test split, report files."""
import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from learned import ModelConfig, TrainConfig, ablate_activations, summarize_ablation_dir
from learned.ablation import ablation_run
from learned.synthetic import write_synthetic_dataset

torch.set_num_threads(1)


@pytest.mark.slow
def test_ablation_table_from_a_dataset_dir(tmp_path):
    data_dir = write_synthetic_dataset(tmp_path / "ds", 400, seed=4, shard_size=128)
    cfg = ModelConfig(hidden=16, d_msg=8, d_z=4, heads=2)
    res = ablate_activations(data_dir, runs=2, train=TrainConfig(epochs=50, max_steps=25, lr=1e-3), config=cfg,
                             test_fraction=0.25, out_dir=tmp_path / "out", progress=False)
    assert res["num_test"] == 100 and res["num_train_val"] == 300
    acts = res["activations"]
    assert list(acts) == ["gumbel_sigmoid", "tanh", "none", "sigmoid"]
    for a, row in acts.items():
        assert len(row["runs_cm"]) == 2 and row["runs_cm"][0] != row["runs_cm"][1]
        assert row["mean_cm"] == pytest.approx(np.mean(row["runs_cm"]))
        assert row["std_cm"] == pytest.approx(np.std(row["runs_cm"], ddof=1))
        assert 0 < row["mean_cm"] < 100
        assert (tmp_path / "out" / "models" / f"{a}-run1.pt").exists()
    md = (tmp_path / "out" / "ablation.md").read_text()
    for label in ("Gumbel-Sigmoid", "Tanh", "No activation", "Sigmoid"):
        assert label in md
    assert f"{acts['tanh']['mean_cm']:.2f} ± {acts['tanh']['std_cm']:.2f}" in md
    assert json.loads((tmp_path / "out" / "ablation.json").read_text()) == res


def test_unknown_activation_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="relu"):
        ablate_activations(tmp_path, runs=1, activations=["relu"])


def test_table_i_so_far_averages_the_finished_runs_and_lists_those_still_training(tmp_path):
    """An interrupted ablation can be summarized without training: finished runs make the means, a run
    stopped early is shown apart with its best model so far, and resuming it completes the table."""
    data_dir = write_synthetic_dataset(tmp_path / "ds", 300, seed=4, shard_size=128)
    cfg = ModelConfig(hidden=16, d_msg=8, d_z=4, heads=2)
    train, out = TrainConfig(epochs=3, lr=1e-3, patience_epochs=50), tmp_path / "out"
    done = [ablation_run(data_dir, "sigmoid", r, train, config=cfg, out_dir=out) for r in range(2)]
    stopped = ablation_run(data_dir, "tanh", 0, replace(train, time_limit_s=1e-9), config=cfg, out_dir=out)
    assert not stopped["finished"] and stopped["epochs"] == 1

    table = summarize_ablation_dir(data_dir, out, 2, activations=("tanh", "sigmoid"), train=train, config=cfg)
    sig, tanh = table["activations"]["sigmoid"], table["activations"]["tanh"]
    assert sig["runs_cm"] == pytest.approx([d["test_cm"] for d in done]) and sig["epochs"] == [3, 3]
    assert sig["mean_cm"] == pytest.approx(np.mean(sig["runs_cm"]))
    assert tanh["mean_cm"] is None and tanh["runs"] == 0
    assert tanh["in_progress"] == [{"run": 0, "epochs": 1, "test_cm": pytest.approx(stopped["test_cm"]),
                                    "val_cm": pytest.approx(stopped["val_cm"])}]
    assert table["runs"] == 2 and not table["complete"]
    assert table["trained"] == "trained to convergence (validation patience 50 epochs, at most 3; 3 epochs reached)"
    md = (out / "ablation.md").read_text()
    assert "run 0: still training, best model after 1 epochs" in md and "not in the means" in md
    assert "| — (0 runs) |" in md

    resumed = ablation_run(data_dir, "tanh", 0, train, config=cfg, out_dir=out, resume=True)
    table = summarize_ablation_dir(data_dir, out, 2, activations=("tanh", "sigmoid"), train=train, config=cfg)
    assert table["complete"] and table["activations"]["tanh"]["runs_cm"] == pytest.approx([resumed["test_cm"]])
    assert table["activations"]["tanh"]["epochs"] == [3]

    with pytest.raises(ValueError, match="sigmoid-run0.pt: trained with other settings"):
        summarize_ablation_dir(data_dir, out, 2, activations=("sigmoid",), train=replace(train, lr=1e-2), config=cfg)
    with pytest.raises(ValueError, match="no Table I run has begun"):
        summarize_ablation_dir(data_dir, tmp_path / "empty", 2, train=train, config=cfg)


def test_finishing_a_table_whose_models_are_gone_trains_only_its_missing_runs(tmp_path):
    """`tamp ablate-activations --finish`: a table written while a run was still training (its models
    since lost) is completed by training that run alone; the finished runs keep the table's figures, and
    the trained run is the one a full ablation would have made (same seed, same split)."""
    from learned.ablation import finish_ablation, read_table

    data_dir = write_synthetic_dataset(tmp_path / "ds", 300, seed=4, shard_size=128)
    cfg = ModelConfig(hidden=16, d_msg=8, d_z=4, heads=2)
    train = TrainConfig(epochs=3, lr=1e-3, patience_epochs=50)
    first = tmp_path / "first"
    for r in range(2):
        ablation_run(data_dir, "tanh", r, train, config=cfg, out_dir=first)
    ablation_run(data_dir, "sigmoid", 0, train, config=cfg, out_dir=first)
    ablation_run(data_dir, "sigmoid", 1, replace(train, time_limit_s=1e-9), config=cfg, out_dir=first)
    old = summarize_ablation_dir(data_dir, first, 2, activations=("tanh", "sigmoid"), train=train, config=cfg)
    assert not old["complete"] and old["activations"]["sigmoid"]["in_progress"][0]["run"] == 1
    table = read_table(first / "ablation.json")
    for row in table["activations"].values():  # as written before runs were numbered in the table
        del row["run_ids"]

    # --summarize before any training: the run still training keeps the table's entry
    so_far = finish_ablation(data_dir, table, tmp_path / "second", 2, train=train, config=cfg, summarize=True)
    assert not so_far["complete"] and so_far["activations"]["sigmoid"]["in_progress"] == \
        old["activations"]["sigmoid"]["in_progress"]
    done = finish_ablation(data_dir, table, tmp_path / "second", 2, train=train, config=cfg, progress=False)
    assert finish_ablation(data_dir, table, tmp_path / "second", 2, train=train, config=cfg,
                           summarize=True)["activations"] == done["activations"]  # read back, not retrained
    assert done["complete"] and not (tmp_path / "second" / "models" / "tanh-run0.pt").exists()
    assert done["activations"]["tanh"]["runs_cm"] == old["activations"]["tanh"]["runs_cm"]
    sig = done["activations"]["sigmoid"]
    assert sig["run_ids"] == [0, 1] and sig["runs_cm"][0] == old["activations"]["sigmoid"]["runs_cm"][0]
    alone = ablation_run(data_dir, "sigmoid", 1, train, config=cfg, out_dir=tmp_path / "alone")
    assert sig["runs_cm"][1] == pytest.approx(alone["test_cm"]) and sig["epochs"][1] == alone["epochs"] == 3
    assert json.loads((tmp_path / "second" / "ablation.json").read_text()) == done

    with pytest.raises(ValueError, match="lr"):  # other settings than the table's
        finish_ablation(data_dir, table, tmp_path / "third", 2, train=replace(train, lr=2e-3), config=cfg,
                        progress=False)
    other = write_synthetic_dataset(tmp_path / "ds2", 300, seed=5, shard_size=128)
    with pytest.raises(ValueError, match="zero-effect"):  # other data of the same size
        finish_ablation(other, table, tmp_path / "third", 2, train=train, config=cfg, progress=False)
