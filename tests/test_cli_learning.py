"""CLI commands that train models and learn domains: argument checks and a tiny end-to-end run."""
import json

import pytest

import learned
from tamp.app.cli import BOTTLENECKS, main


def test_bottleneck_choices_match_the_model():
    assert tuple(BOTTLENECKS) == tuple(learned.ACTIVATIONS)


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    """A small synthetic dataset in the on-disk format (no Drake needed)."""
    from learned.synthetic import write_synthetic_dataset

    out = tmp_path_factory.mktemp("data")
    write_synthetic_dataset(out, num_samples=600, seed=0)
    return out


@pytest.mark.slow
def test_train_then_domain_end_to_end(tiny_dataset, tmp_path, capsys):
    model = tmp_path / "symbolic.pt"
    assert main(["train", "--data", str(tiny_dataset), "--bottleneck", "gumbel_sigmoid", "--epochs", "2",
                 "--out", str(model)]) == 0
    assert model.is_file() and "best validation effect error" in capsys.readouterr().out
    out = tmp_path / "domain"
    assert main(["domain", "--model", str(model), "--data", str(tiny_dataset), "--out", str(out)]) == 0
    stats = json.loads((out / "stats.json").read_text())
    assert stats["n_operators"] > 0
    for name in ("domain.pddl", "domain.ppddl", "operators.json"):
        assert (out / name).stat().st_size > 0
    assert "operators from 600 transitions" in capsys.readouterr().out


def test_train_missing_dataset_is_a_clear_error(tmp_path, capsys):
    assert main(["train", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "m.pt")]) == 2
    err = capsys.readouterr().err
    assert "nope" in err and "Traceback" not in err


def test_domain_with_a_corrupt_model_is_a_clear_error(tiny_dataset, tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    assert main(["domain", "--model", str(bad), "--data", str(tiny_dataset), "--out", str(tmp_path / "d")]) == 2
    assert "bad.pt" in capsys.readouterr().err
