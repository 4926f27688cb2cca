"""`tamp reproduce`'s train stage: a wall-clock cap never finishes the stage; a rerun resumes the models."""
import json
from concurrent.futures import ThreadPoolExecutor

import pytest
import torch

import evaluation.reproduce as rep
from learned.synthetic import write_synthetic_dataset
from learned.train import last_path

SPEC = rep.ModelSpec("dynamics.pt", "sigmoid", 2, 2)


def _scale(**kw) -> rep.Scale:
    return rep.Scale(**{**dict(samples=300, epochs=2, train_time_limit_s=None, ablation_runs=1, ablation_epochs=1,
                               per_cell=1, search_time_limit_s=1.0, models=(SPEC,), domains={}), **kw})


def test_train_job_records_the_stop_and_resumes_a_time_limited_model(tmp_path):
    data = write_synthetic_dataset(tmp_path / "data", num_samples=300, seed=0)
    scale = _scale(train_time_limit_s=1e-9, batch_size=64, lr=2e-4, patience_epochs=10)
    first = rep._train_job(str(data), str(tmp_path / "models"), SPEC, scale)
    assert (first["finished"], first["stop"], first["epochs"]) == (False, "time_limit", 1)
    second = rep._train_job(str(data), str(tmp_path / "models"), SPEC, scale)  # resumes from the last checkpoint
    assert (second["finished"], second["stop"], second["epochs"]) == (True, "max_epochs", 2)
    assert last_path(tmp_path / "models" / "dynamics.pt").is_file()


def test_an_unfinished_model_leaves_the_train_stage_open(tmp_path, monkeypatch):
    """The stage's decision, with its one job run in this process (the ablation cells' test below runs the
    jobs in spawned workers)."""
    out = tmp_path / "repro"
    write_synthetic_dataset(out / "data", num_samples=300, seed=0)
    monkeypatch.setitem(rep.SCALES, "quick", _scale(train_time_limit_s=1e-9, ablation_runs=0))
    monkeypatch.setattr(rep, "ProcessPoolExecutor", lambda max_workers, mp_context: ThreadPoolExecutor(max_workers))
    rep.Stages(out, "quick", rep.SCALES["quick"]).finish("collect", 0.0)
    with pytest.raises(rep.TrainingUnfinished, match="dynamics.pt stopped at the time limit"):
        rep.reproduce(out, "quick", workers=1)
    assert set(json.loads((out / "stages.json").read_text())["finished"]) == {"collect"}


def test_the_legacy_training_settings_stay_out_of_stages_json(tmp_path):
    """Reproductions begun before batch size, precision and patience were Scale fields stay resumable."""
    (tmp_path / "a").mkdir()
    rep.Stages(tmp_path / "a", "quick", _scale())
    config = json.loads((tmp_path / "a" / "stages.json").read_text())["setup"]["config"]
    assert not set(rep.LEGACY_SCALE) & set(config)
    (tmp_path / "b").mkdir()
    rep.Stages(tmp_path / "b", "quick", _scale(batch_size=1024, patience_epochs=100))
    config = json.loads((tmp_path / "b" / "stages.json").read_text())["setup"]["config"]
    assert (config["batch_size"], config["patience_epochs"]) == (1024, 100) and "precision" not in config


def test_the_ablation_cells_make_table_i_and_a_finished_cell_is_not_trained_again(tmp_path, monkeypatch):
    """Table I's (activation, run) cells are separate jobs of the train stage; the stage writes the table from
    them, and a rerun of a cell that finished reads its model back instead of training it."""
    out = tmp_path / "repro"
    write_synthetic_dataset(out / "data", num_samples=300, seed=0)
    monkeypatch.setitem(rep.SCALES, "quick", _scale(ablation_runs=2, models=()))  # the cells alone
    monkeypatch.setattr(rep, "_evaluate_stages", lambda *args, **kwargs: out / "not evaluated")
    rep.Stages(out, "quick", rep.SCALES["quick"]).finish("collect", 0.0)
    rep.reproduce(out, "quick", workers=1)
    table = json.loads((out / "ablation" / "ablation.json").read_text())
    assert list(table["activations"]) == ["gumbel_sigmoid", "tanh", "none", "sigmoid"] and table["runs"] == 2
    assert all(len(row["runs_cm"]) == 2 for row in table["activations"].values())
    last = last_path(out / "ablation" / "models" / "tanh-run1.pt")
    before = torch.load(last, weights_only=True)
    cell = rep._ablation_job(str(out / "data"), str(out / "ablation"), rep.SCALES["quick"], "tanh", 1)
    assert cell["finished"] and cell["test_cm"] == table["activations"]["tanh"]["runs_cm"][1]
    after = torch.load(last, weights_only=True)  # read back, not trained again: same steps, same weights
    assert after["train"]["step"] == before["train"]["step"] and cell["epochs"] == 1
    assert all(torch.equal(after["state_dict"][k], v) for k, v in before["state_dict"].items())
    stages = json.loads((out / "stages.json").read_text())
    assert "train" in stages["finished"] and stages["finished"]["train"]["results"][-1]["model"] == "ablation"
