"""`tamp reproduce`'s train stage: a wall-clock cap never finishes the stage; a rerun resumes the models."""
import json

import pytest

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
    out = tmp_path / "repro"
    write_synthetic_dataset(out / "data", num_samples=300, seed=0)
    monkeypatch.setitem(rep.SCALES, "quick", _scale(train_time_limit_s=1e-9))
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
