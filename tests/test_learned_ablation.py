"""Activation ablation (Table I): runs per activation on a shared held-out test split, report files."""
import json

import numpy as np
import pytest
import torch

from learned import ModelConfig, TrainConfig, ablate_activations
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
