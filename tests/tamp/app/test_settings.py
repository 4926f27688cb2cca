"""The configuration as data: `PlanConfig` and the evaluation's settings read from TOML files and presets,
printed back by `tamp config show`, and refused in one line when a file is damaged or mistaken. No Drake."""
from __future__ import annotations

import dataclasses
from dataclasses import replace

import pytest

from guarded import InputError
from guarded.config import field_comments
from tamp.app.cli import main
from tamp.app.settings import EvaluationSettings, Settings, load_settings, render_settings, settings_record
from tamp.errors import UserError
from tamp.planning.config import (
    PLAN_SECTIONS,
    KinematicsConfig,
    Level1Config,
    LoopConfig,
    PlanConfig,
    VerifyConfig,
    paper_config,
)
from tamp.planning.search import SearchConfig
from tamp.sim.perception_config import CameraConfig, DepthNoise, PerceptionConfig

PARTS = [f.name for f in dataclasses.fields(PlanConfig)]


def test_plan_config_is_composed_of_small_frozen_parts():
    assert PARTS == list(PLAN_SECTIONS) == ["level1", "verify", "search", "kinematics", "loop"]
    default = PlanConfig()
    for part in PARTS:
        value = getattr(default, part)
        assert dataclasses.is_dataclass(value) and type(value).__dataclass_params__.frozen  # type: ignore[attr-defined]
        assert len(dataclasses.fields(value)) <= 20  # each part fits on a screen
    with pytest.raises(dataclasses.FrozenInstanceError):
        default.level1.seed = 1  # type: ignore[misc]


def test_every_field_has_a_one_line_comment():
    for cls in (*(type(getattr(PlanConfig(), part)) for part in PARTS), EvaluationSettings, PerceptionConfig,
                CameraConfig, DepthNoise):
        comments = field_comments(cls)
        missing = [f.name for f in dataclasses.fields(cls) if not comments.get(f.name)]
        assert not missing, (cls.__name__, missing)
    assert all(len(line) <= 120 for line in render_settings(Settings()).splitlines())


def test_the_default_preset_is_the_code_defaults():
    assert load_settings() == load_settings("default") == Settings()


def test_the_paper_preset_is_algorithm_1():
    """The paper's Algorithm 1 with its settings, as `bilevel_alg1` plans: every extension of ours off."""
    d = PlanConfig()
    paper = replace(d, level1=replace(d.level1, focus_from=None, wait_beyond=None),
                    kinematics=replace(d.kinematics, feasibility=False),
                    search=replace(d.search, look_on=0, release_targets=False, max_doubt=None,
                                   stall=None, greedy_from=None, resolution=0.01))
    assert load_settings("paper").planner == paper == paper_config(d)
    # over another configuration, the paper's settings win and the rest stays
    mine = replace(d, level1=replace(d.level1, n_domains=7, serial=False))
    assert paper_config(mine).level1 == replace(paper.level1, n_domains=7, serial=False)


def test_config_show_reads_back_equal(tmp_path, capsys):
    for preset in ("default", "paper"):
        assert main(["config", "show", "--preset", preset]) == 0
        path = tmp_path / f"{preset}.toml"
        path.write_text(capsys.readouterr().out)
        assert load_settings(config=path) == load_settings(preset)
    # a file over a preset: the file's keys win
    mine = tmp_path / "mine.toml"
    mine.write_text("[search]\nstall = 300\ngreedy_from = false\n\n[loop]\nmax_actions = 5\n\n"
                    "[evaluation]\noracle_max_plans = 3\n")
    s = load_settings("paper", mine)
    assert s.planner.search.stall == 300 and s.planner.search.greedy_from is None
    assert s.planner.search.resolution == 0.01 and s.planner.loop.max_actions == 5
    assert s.evaluation.oracle_max_plans == 3
    assert main(["config", "show", "--preset", "paper", "--config", str(mine)]) == 0
    shown = capsys.readouterr().out
    assert "stall = 300  #" in shown and "greedy_from = false  #" in shown and "resolution = 0.01  #" in shown


def test_the_record_holds_every_field():
    record = settings_record(Settings())
    assert record["format"] == "tamp-config/1"
    assert record["search"] == dataclasses.asdict(SearchConfig()) and record["evaluation"] == {"oracle_max_plans": 20}
    assert set(record) == {"format", *PARTS, "evaluation", "perception"}
    assert record["perception"]["above"]["width"] == 640 and record["perception"]["noise"]["on"] is True


DAMAGED = [
    (b"[search\nstall = 3\n", "not TOML"),
    (b"[search]\nstal = 300\n", "unknown key search.stal; did you mean search.stall?"),
    (b"[serach]\nstall = 300\n", "unknown key serach; did you mean search?"),
    (b"[search]\nstall = \"300\"\n", "search.stall must be an integer, or false for off"),
    (b"[search]\nmax_doubt = true\n", "search.max_doubt must be a number, or false for off"),
    (b"[level1]\nserial = 1\n", "level1.serial must be true or false"),
    (b"[level1]\nn_domains = 0\n", "the number of sampled domains, must be in 1..10,000"),
    (b"[search]\nresolution = 0.5\n", "duplicate grid must be more than 0 and at most 5 cm"),
    (b"search = 3\n", "search must be a table of keys"),
    (b"[search.stall]\nx = 1\n", "search.stall is a setting, not a table"),
    (b"[loop]\nstop_margin = 0.06\n", "stop margin (0.06 m) must be below the success tolerance"),
    (b"[verify]\neps = inf\n", "verify.eps must be a finite number"),
    (b"\xff\xfe[search]\n", "not UTF-8"),
    (b"[evaluation]\noracle_max_plans = 0\n", "oracle_max_plans must be a positive integer"),
    (b"[" * 5000, "not TOML"),
]


@pytest.mark.parametrize("text, message", DAMAGED)
def test_a_damaged_or_mistaken_file_is_refused_in_one_line(tmp_path, capsys, text, message):
    path = tmp_path / "c.toml"
    path.write_bytes(text)
    with pytest.raises((InputError, UserError), match=message.replace("(", r"\(").replace(")", r"\)").replace(
            "?", r"\?").replace(".", r"\.")) as error:
        load_settings(config=path)
    assert str(path) in str(error.value) and "\n" not in str(error.value)
    assert main(["config", "show", "--config", str(path)]) == 2  # the command line: one line, exit 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message.split(" (")[0] in err


def test_a_missing_file_or_preset_is_refused(tmp_path, capsys):
    assert main(["config", "show", "--config", str(tmp_path / "none.toml")]) == 2
    assert "no configuration file at" in capsys.readouterr().err
    assert main(["config", "show", "--preset", "fast"]) == 2
    assert "no preset 'fast'; the presets are cameras, default, paper" in capsys.readouterr().err


def test_validation_lives_with_the_fields():
    for bad, field in ((lambda: Level1Config(backend="x"), "symbolic backend"),
                       (lambda: Level1Config(n_domains=0), "sampled domains"),
                       (lambda: Level1Config(budget=0), "Level1Config.budget"),
                       (lambda: VerifyConfig(eps=0.0), "VerifyConfig.eps"),
                       (lambda: VerifyConfig(tau_verify=-1.0), "VerifyConfig.tau_verify"),
                       (lambda: LoopConfig(stop_margin=-0.01), "LoopConfig.stop_margin"),
                       (lambda: LoopConfig(max_actions=0), "at least 1 action"),
                       (lambda: KinematicsConfig(max_refinements=0), "KinematicsConfig.max_refinements"),
                       (lambda: SearchConfig(resolution=0.0), "duplicate grid")):
        with pytest.raises(UserError, match=field):
            bad()
    assert PlanConfig().with_seed(7).level1 == Level1Config(seed=7)


def test_every_extension_of_the_ablation_bench_is_a_setting_it_switches():
    """bench/ablation.py switches each extension off by a configuration file: each must parse and change its key."""
    import importlib.util

    from guarded.config import parse_toml
    from tamp.planning.config import overlay
    from tests.paths import ROOT

    spec = importlib.util.spec_from_file_location("ablation", ROOT / "bench" / "ablation.py")
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    default = PlanConfig()
    for name, toml in bench.EXTENSIONS.items():
        part, key = name.split(".")
        off = overlay(default, parse_toml(toml, name), name)
        assert getattr(getattr(off, part), key) != getattr(getattr(default, part), key), name


def test_the_paper_preset_evaluates_every_method_without_kinematics():
    """`tamp evaluate --preset paper --methods bilevel` plans as `bilevel_alg1`: a method's kinematics in the loop
    (`Method.feasibility`) hold only where the configuration does not turn them off."""
    from evaluation.configuration import EvalConfig

    assert EvalConfig().plan_config(3, feasibility=True).kinematics.feasibility
    assert not EvalConfig().plan_config(3, feasibility=False).kinematics.feasibility
    paper = EvalConfig(planner=load_settings("paper").planner)
    assert not paper.plan_config(3, feasibility=True).kinematics.feasibility
    assert paper.plan_config(3).level1.seed == 3
