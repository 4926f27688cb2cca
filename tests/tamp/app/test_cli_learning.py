"""CLI commands that train models and learn domains: argument checks and a tiny end-to-end run."""
import json

import pytest

import learned
from learned.model import POSITION_AXES
from tamp.app.cli import main
from tamp.app.commands_learning import BOTTLENECKS, RELATION_ENCODERS
from tamp.app.commands_learning import POSITION_AXES as CLI_POSITION_AXES


def test_bottleneck_choices_match_the_model():
    assert tuple(BOTTLENECKS) == tuple(learned.ACTIVATIONS)
    assert tuple(RELATION_ENCODERS) == tuple(learned.RELATIONS)
    assert tuple(CLI_POSITION_AXES) == tuple(POSITION_AXES)


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


def test_pairwise_relations_and_the_type_symbol_reach_the_domain_and_tamp_symbols(tiny_dataset, tmp_path, capsys):
    model = tmp_path / "symbolic.pt"
    assert main(["train", "--data", str(tiny_dataset), "--bottleneck", "gumbel_sigmoid", "--d-z", "1", "--heads",
                 "2", "--relations", "pairwise", "--type-symbol", "--bit-usage", "0.1", "--epochs", "2",
                 "--out", str(model)]) == 0
    config = learned.load_model(model).config
    assert (config.relations, config.type_symbol, config.n_unary) == ("pairwise", True, 2)
    out = tmp_path / "domain"
    assert main(["domain", "--model", str(model), "--data", str(tiny_dataset), "--out", str(out),
                 "--involved-only"]) == 0
    assert json.loads((out / "stats.json").read_text())["n_unary"] == 2  # the learned bit and the type
    capsys.readouterr()
    assert main(["domain", "--model", str(model), "--data", str(tiny_dataset), "--out", str(tmp_path / "general"),
                 "--involved-only", "--general-bystanders"]) == 0
    general = json.loads((tmp_path / "general" / "stats.json").read_text())
    assert general["general_bystanders"] and general["n_operators"] <= json.loads((out / "stats.json").read_text())[
        "n_operators"]
    assert f"({general['n_general']} general)" in capsys.readouterr().out
    assert main(["symbols", "--model", str(model), "--data", str(tiny_dataset), "--max-scenes", "200"]) == 0
    printed = capsys.readouterr().out
    assert "1 learned unary bit(s) and the given type as u1, K = 2 pairwise relation(s)" in printed
    assert "near-constant bits" in printed and "goals whose symbols" not in printed  # no problem set given


def test_domain_core_from_all_adds_operators_and_needs_involved_only(tiny_dataset, tmp_path, capsys):
    model = tmp_path / "symbolic.pt"
    assert main(["train", "--data", str(tiny_dataset), "--bottleneck", "gumbel_sigmoid", "--d-z", "1", "--heads",
                 "2", "--epochs", "2", "--out", str(model)]) == 0
    counts = {}
    for extra in ([], ["--core-from-all"]):
        out = tmp_path / ("core" if extra else "plain")
        assert main(["domain", "--model", str(model), "--data", str(tiny_dataset), "--out", str(out),
                     "--involved-only", *extra]) == 0
        stats = json.loads((out / "stats.json").read_text())
        assert stats["core_from_all"] is bool(extra)
        counts[bool(extra)] = stats["train_transitions"]
    assert counts[True] > counts[False]  # transitions that changed a third object teach their pair's operator too
    capsys.readouterr()
    assert main(["domain", "--model", str(model), "--data", str(tiny_dataset), "--out", str(tmp_path / "x"),
                 "--core-from-all"]) == 2
    err = capsys.readouterr().err
    assert "--core-from-all needs --involved-only" in err and "Traceback" not in err


def test_train_missing_dataset_is_a_clear_error(tmp_path, capsys):
    assert main(["train", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "m.pt")]) == 2
    err = capsys.readouterr().err
    assert "nope" in err and "Traceback" not in err


@pytest.mark.parametrize("flag,loss", [(["--offset-from-relations"], "--offset-loss"),
                                       (["--position-axes", "x"], "--position-loss")])
def test_a_loss_option_without_its_loss_is_a_clear_error(tiny_dataset, tmp_path, capsys, flag, loss):
    assert main(["train", "--data", str(tiny_dataset), "--out", str(tmp_path / "m.pt"), *flag]) == 2
    err = capsys.readouterr().err
    assert loss in err and flag[0] in err and "Traceback" not in err and not (tmp_path / "m.pt").exists()


def test_domain_with_a_corrupt_model_is_a_clear_error(tiny_dataset, tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    assert main(["domain", "--model", str(bad), "--data", str(tiny_dataset), "--out", str(tmp_path / "d")]) == 2
    assert "bad.pt" in capsys.readouterr().err


def test_train_defaults_match_the_train_settings():
    """tamp/app/commands_learning.py spells the fast training defaults out (no torch import for --help);
    they must agree."""
    from learned import TrainConfig
    from tamp.app.cli import build_parser
    from tamp.app.commands_learning import TRAIN_PATIENCE, _train_config

    for command in (["train", "--out", "m.pt"], ["ablate-activations"]):
        args = build_parser().parse_args([*command, "--data", "d"])
        assert (args.batch_size, args.lr, args.precision, args.patience) == (1024, None, None, TRAIN_PATIENCE)
        assert _train_config(args) == TrainConfig.fast(epochs=args.epochs)
    assert TrainConfig.fast().patience_epochs == TRAIN_PATIENCE


def test_train_prints_why_it_stopped_and_resumes_a_time_limited_run(tiny_dataset, tmp_path, capsys):
    model = tmp_path / "m.pt"
    base = ["train", "--data", str(tiny_dataset), "--out", str(model), "--epochs", "3", "--batch-size", "64",
            "--lr", "1e-3", "--patience", "5", "--precision", "float32"]
    assert main(base + ["--time-limit-min", "1e-9"]) == 0
    out = capsys.readouterr().out
    assert "stopped: time_limit after 1 epochs (batch 64, lr 0.001, float32)" in out and "--resume" in out
    assert main(base + ["--resume"]) == 0
    assert "stopped: max_epochs after 3 epochs" in capsys.readouterr().out


@pytest.mark.parametrize("flag,value", [("--batch-size", "0"), ("--lr", "-1"), ("--lr", "nan"), ("--patience", "-2"),
                                        ("--precision", "float16"), ("--time-limit-min", "0"),
                                        ("--bit-usage", "-1"), ("--relations", "dense"), ("--offset-radius-cm", "0")])
def test_train_bad_settings_are_one_line_errors(tmp_path, capsys, flag, value):
    with pytest.raises(SystemExit) as e:
        main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "m.pt"), flag, value])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert flag in err[-1] and "Traceback" not in "\n".join(err)


def test_ablation_summary_of_an_empty_folder_is_a_clear_error(tiny_dataset, tmp_path, capsys):
    assert main(["ablate-activations", "--data", str(tiny_dataset), "--out-dir", str(tmp_path / "none"),
                 "--summarize"]) == 2
    err = capsys.readouterr().err
    assert "--summarize" in err and "no Table I run has begun" in err and "Traceback" not in err


def test_finishing_a_file_that_is_not_a_table_is_a_clear_error(tiny_dataset, tmp_path, capsys):
    base = ["ablate-activations", "--data", str(tiny_dataset), "--out-dir", str(tmp_path / "out"), "--finish"]
    (tmp_path / "rows.json").write_text('{"activations": {}}')
    assert main(base + [str(tmp_path / "rows.json")]) == 2
    err = capsys.readouterr().err
    assert "--finish" in err and "a Table I of" in err and "missing field 'epochs'" in err and "Traceback" not in err
    assert main(base + [str(tmp_path / "missing.json")]) == 2
    assert "no Table I JSON at" in capsys.readouterr().err
    assert main(base + [str(tmp_path / "rows.json"), "--resume"]) == 2
    assert "without --resume" in capsys.readouterr().err


def test_train_on_two_datasets_then_fine_tune_on_more_blocks(tiny_dataset, tmp_path, capsys):
    """The way to models for 6 blocks: a dataset of 2-4 and one of 5-6 blocks, trained on together;
    --init fine-tunes a model, keeping its network, and the object limit becomes the data's."""
    from learned.synthetic import write_synthetic_dataset

    more = write_synthetic_dataset(tmp_path / "more", 200, seed=5, n_max=6, n_choices=(5, 6))
    base = ["--epochs", "1", "--batch-size", "64", "--precision", "float32"]
    small = tmp_path / "small.pt"
    assert main(["train", "--data", str(tiny_dataset), "--bottleneck", "gumbel_sigmoid", "--d-z", "2",
                 "--out", str(small), *base]) == 0
    assert learned.load_model(small).config.n_max == 4
    tuned = tmp_path / "tuned.pt"
    assert main(["train", "--data", str(tiny_dataset), str(more), "--init", str(small), "--out", str(tuned),
                 *base]) == 0
    config = learned.load_model(tuned).config
    assert (config.n_max, config.activation, config.d_z) == (6, "gumbel_sigmoid", 2)
    assert main(["domain", "--model", str(tuned), "--data", str(tiny_dataset), str(more),
                 "--out", str(tmp_path / "domain")]) == 0
    assert "operators from 800 transitions" in capsys.readouterr().out
    assert main(["train", "--data", str(more), "--init", str(small), "--bottleneck", "sigmoid",
                 "--out", str(tmp_path / "x.pt"), *base]) == 2
    err = capsys.readouterr().err
    assert "small.pt" in err and "activation 'sigmoid' (its 'gumbel_sigmoid')" in err and "Traceback" not in err


def test_train_an_ensemble_with_practice_data_then_plan_with_it(tiny_dataset, tmp_path, capsys):
    """`tamp train --ensemble`: members with spread heads in one file, which a models directory takes as its
    Dynamics Model; the ensemble's own flags are refused without it."""
    from learned.ensemble import EffectEnsemble, load_dynamics
    from learned.synthetic import write_synthetic_dataset

    practice = write_synthetic_dataset(tmp_path / "practice", 60, seed=7)
    out = tmp_path / "m" / "dynamics.pt"
    base = ["--epochs", "1", "--batch-size", "64", "--precision", "float32"]
    assert main(["train", "--data", str(tiny_dataset), "--extra-data", str(practice), "--ensemble", "2",
                 "--out", str(out), *base]) == 0
    printed = capsys.readouterr().out
    assert "member 1:" in printed and "inside their 95 % ellipsoid" in printed and "ensemble of 2" in printed
    model = load_dynamics(out)
    assert isinstance(model, EffectEnsemble) and len(model) == 2 and model.config.spread
    assert sorted(p.name for p in out.parent.iterdir()) == ["dynamics.pt"]  # the members' own files removed
    for flags, said in ((["--extra-data", str(practice)], "give --ensemble too"),
                        (["--ensemble", "2", "--bottleneck", "gumbel_sigmoid"], "Dynamics Model"),
                        (["--ensemble", "2", "--extra-data", str(practice), "--extra-share", "0"], "--extra-share")):
        assert main(["train", "--data", str(tiny_dataset), "--out", str(tmp_path / "x.pt"), *flags, *base]) == 2
        assert said in capsys.readouterr().err


def test_fine_tune_a_dynamics_model_into_the_whole_action_encoding(tiny_dataset, tmp_path, capsys):
    """--whole-action widens a paper-encoded network (single or ensemble); a network with the whole action
    keeps it when fine-tuned again without the flag."""
    from learned.ensemble import load_dynamics

    base = ["--epochs", "1", "--batch-size", "64", "--precision", "float32"]
    paper, whole = tmp_path / "paper.pt", tmp_path / "whole.pt"
    assert main(["train", "--data", str(tiny_dataset), "--bottleneck", "sigmoid", "--out", str(paper), *base]) == 0
    assert not learned.load_model(paper).config.whole_action
    assert main(["train", "--data", str(tiny_dataset), "--init", str(paper), "--whole-action",
                 "--out", str(whole), *base]) == 0
    assert learned.load_model(whole).config.whole_action
    again = tmp_path / "again.pt"
    assert main(["train", "--data", str(tiny_dataset), "--init", str(whole), "--out", str(again), *base]) == 0
    assert learned.load_model(again).config.whole_action
    ensemble = tmp_path / "e" / "dynamics.pt"
    assert main(["train", "--data", str(tiny_dataset), "--init", str(paper), "--whole-action", "--ensemble", "2",
                 "--out", str(ensemble), *base]) == 0
    assert load_dynamics(ensemble).config.whole_action
    capsys.readouterr()


def test_a_dynamics_model_with_relative_messages_trains_and_a_symbolic_one_is_refused(tiny_dataset, tmp_path,
                                                                                      capsys):
    base = ["--epochs", "1", "--batch-size", "64", "--precision", "float32"]
    model = tmp_path / "dynamics.pt"
    assert main(["train", "--data", str(tiny_dataset), "--whole-action", "--relative-messages", "--out", str(model),
                 *base]) == 0
    assert learned.load_model(model).config.relative_messages
    again = tmp_path / "again.pt"  # fine-tuned, it keeps its messages
    assert main(["train", "--data", str(tiny_dataset), "--init", str(model), "--out", str(again), *base]) == 0
    assert learned.load_model(again).config.relative_messages
    capsys.readouterr()
    assert main(["train", "--data", str(tiny_dataset), "--relative-messages", "--bottleneck", "gumbel_sigmoid",
                 "--out", str(tmp_path / "symbolic.pt"), *base]) == 2
    err = capsys.readouterr().err
    assert "Dynamics Model option" in err and "Traceback" not in err and not (tmp_path / "symbolic.pt").exists()


def test_hidden_width_and_layers_are_the_networks_and_init_keeps_its_own(tiny_dataset, tmp_path, capsys):
    model = tmp_path / "dynamics.pt"
    assert main(["train", "--data", str(tiny_dataset), "--hidden", "24", "--layers", "1", "--epochs", "1",
                 "--out", str(model)]) == 0
    config = learned.load_model(model).config  # rebuilt from its settings, its weights loaded into it
    assert (config.hidden, config.layers) == (24, 1)
    capsys.readouterr()
    assert main(["train", "--data", str(tiny_dataset), "--init", str(model), "--hidden", "32", "--epochs", "1",
                 "--out", str(tmp_path / "wider.pt")]) == 2
    err = capsys.readouterr().err
    assert "hidden 32 (its 24)" in err and "Traceback" not in err
