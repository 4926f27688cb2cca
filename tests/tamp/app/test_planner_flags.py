"""The planner's flags and its configuration agree: every field of each part of `PlanConfig` has a flag
(`PLANNER_FLAGS`) or is listed as deliberately not exposed (`NOT_EXPOSED`), and each flag's default is
the field's default. No Drake."""
from __future__ import annotations

import argparse
import dataclasses

import pytest

from tamp.app.planner_flags import AUTO_FLAGS, NOT_EXPOSED, PLANNER_FLAGS, add_planner_arguments, planner_config
from tamp.errors import UserError
from tamp.planning.config import KinematicsConfig, Level1Config, LoopConfig, PlanConfig, VerifyConfig
from tamp.planning.search import SearchConfig

PARTS = [f.name for f in dataclasses.fields(PlanConfig)]


def parser(feasibility: bool = True) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    add_planner_arguments(p, feasibility=feasibility)
    return p


def test_plan_config_is_composed_of_small_frozen_parts():
    assert PARTS == ["level1", "verify", "search", "kinematics", "loop"]
    default = PlanConfig()
    for part in PARTS:
        value = getattr(default, part)
        assert dataclasses.is_dataclass(value) and type(value).__dataclass_params__.frozen  # type: ignore[attr-defined]
        assert len(dataclasses.fields(value)) <= 20  # each part fits on a screen
    with pytest.raises(dataclasses.FrozenInstanceError):
        default.level1.seed = 1  # type: ignore[misc]


def test_every_field_has_a_flag_or_is_listed_as_not_exposed():
    assert set(PLANNER_FLAGS) == set(NOT_EXPOSED) == set(PARTS)
    default = PlanConfig()
    for part in PARTS:
        names = {f.name for f in dataclasses.fields(getattr(default, part))}
        flagged, hidden = set(PLANNER_FLAGS[part]), set(NOT_EXPOSED[part])
        assert not flagged & hidden, (part, flagged & hidden)
        assert flagged | hidden == names, (part, names ^ (flagged | hidden))


@pytest.mark.parametrize("feasibility", [True, False])
def test_each_flag_default_is_the_field_default(feasibility):
    p, default = parser(feasibility), PlanConfig()
    dests = {a.dest for a in p._actions}
    for part, flags in PLANNER_FLAGS.items():
        for name, dest in flags.items():
            if dest == "feasibility" and not feasibility:  # `tamp evaluate` sets it per method
                assert dest not in dests
                continue
            assert dest in dests, (part, name, dest)
            if dest in AUTO_FLAGS:  # None: the field's default, or what the run's faults imply
                assert p.get_default(dest) is None, dest
                continue
            assert p.get_default(dest) == getattr(getattr(default, part), name), (part, name, dest)
    assert planner_config(p.parse_args([])) == default


def test_flags_set_their_fields():
    args = ["--n-domains", "7", "--symbolic-backend", "fd", "--symbolic-time-limit", "3", "--level1-budget", "9",
            "--focus-from", "3", "--level1-focus-budget", "8", "--level1-objects", "3", "--no-level1-serial",
            "--level1-confident", "0.07", "--no-level1-cut", "--no-keep-plan", "--on-course", "0.02",
            "--max-actions", "5", "--no-widen", "--max-expansions", "11", "--confident", "0.03", "--look-on", "2",
            "--max-fragility", "0.5", "--paper-pruning", "--time-limit", "4", "--stall", "50", "--greedy-stall", "70",
            "--no-feasibility"]
    cfg = planner_config(parser().parse_args(args))
    assert cfg == PlanConfig(
        level1=Level1Config(n_domains=7, backend="fd", symbolic_time_limit=3.0, budget=9, focus_from=3, focus_budget=8,
                            objects=3, serial=False, wait_beyond=0.07, cut=False),
        verify=VerifyConfig(confident=0.03),
        search=SearchConfig(max_expansions=11, look_on=2, max_fragility=0.5, release_targets=False,
                            time_limit=4.0, stall=50, greedy_stall=70),
        kinematics=KinematicsConfig(feasibility=False),
        loop=LoopConfig(keep_plan=False, on_course=0.02, max_actions=5, widen=False))
    off = planner_config(parser().parse_args(["--no-level1-objects", "--no-on-course", "--no-fragility", "--no-stall",
                                                   "--no-greedy-stall"]))
    assert off.level1.objects is None and off.loop.on_course is None and off.search.max_fragility is None
    assert off.search.stall is None and off.search.greedy_stall is None


def test_validation_lives_with_the_fields():
    for bad, field in ((lambda: Level1Config(backend="x"), "symbolic backend"),
                       (lambda: Level1Config(n_domains=0), "sampled domains"),
                       (lambda: Level1Config(budget=0), "Level1Config.budget"),
                       (lambda: VerifyConfig(eps=0.0), "VerifyConfig.eps"),
                       (lambda: VerifyConfig(tau_verify=-1.0), "VerifyConfig.tau_verify"),
                       (lambda: LoopConfig(on_course=0.0), "LoopConfig.on_course"),
                       (lambda: LoopConfig(remember=0.0), "LoopConfig.remember"),
                       (lambda: LoopConfig(remember_alike=0), "LoopConfig.remember_alike"),
                       (lambda: SearchConfig(resolution=0.0), "duplicate grid")):
        with pytest.raises(UserError, match=field):
            bad()
    assert PlanConfig().with_seed(7).level1 == Level1Config(seed=7)


def test_the_defining_settings_of_a_results_directory_are_unchanged():
    """`EvalConfig.defining()` holds every setting rows depend on, with the keys it had with the flat PlanConfig
    (the closed loop's `keep_plan` and `on_course` are not in "loop"); the search's stall cut and its default
    time limit (none) are part of it, so a directory of rows planned without them is not resumed with them."""
    from evaluation.configuration import IMPLICIT_LOOP, EvalConfig

    default = {"eps_m": 0.05, "fidelity": "fast", "keep_plan": True, "level1_budget": 100000,
               "level1_confident_m": 0.05, "level1_cut": True, "level1_focus_budget": 25000, "level1_focus_from": 5,
               "level1_objects": 4, "level1_serial": True, "level1_time_budget_s": None, "n_domains": 100,
               "on_course_m": 0.015, "oracle_max_plans": 20, "search_confident_m": 0.035, "search_look_on": 30,
               "search_max_expansions": 1500, "search_max_fragility": 0.3, "search_noise_m": 0.005,
               "search_release_targets": True, "search_time_limit_s": None, "search_stall": None,
               "search_greedy_from": 5, "search_greedy_h_unit_m": 0.5,
               "search_greedy_per_misplaced": 0.3, "search_greedy_stall": 800, "loop_greedy_search_budget": 1500,
               "symbolic_backend": "python", "search_resolution_m": 0.02, "search_clear_blockers": True,
               "tau_verify_m": 0.07,
               "loop": {"max_actions": 30, "widen": True, "widen_expansions": 400, "search_budget": 3000,
                        "greedy_search_budget": 1500, "stall": 300, "progress": 0.02, "revisit": 0.01,
                        "remember": 0.02, "remember_alike": 2}}
    assert EvalConfig().defining() == default
    # a directory made before the loop remembered its misses plans as with --no-remember
    forgetful = EvalConfig(planner=PlanConfig(loop=LoopConfig(remember=None))).defining()
    assert forgetful == {**default, "loop": {k: v for k, v in default["loop"].items()
                                             if k not in ("remember", "remember_alike")}}
    # a directory made with the loop's settings of before (no "loop" entry) is not resumed with today's
    made_before = EvalConfig(planner=PlanConfig(loop=LoopConfig(**IMPLICIT_LOOP, remember=None))).defining()
    assert "loop" not in made_before and made_before != default
    kept = EvalConfig(planner=PlanConfig(loop=LoopConfig(keep_plan=False, on_course=None))).defining()
    assert kept == {**default, "keep_plan": False, "on_course_m": None}
    short = EvalConfig(planner=PlanConfig(loop=LoopConfig(max_actions=5))).defining()
    assert short["loop"] == {**default["loop"], "max_actions": 5}
    wander = EvalConfig(planner=PlanConfig(loop=LoopConfig(commit=False))).defining()
    assert wander == {**default, "loop_commit": False}
    # a directory made on the 1 cm duplicate grid of before has no "search_resolution_m"
    fine = EvalConfig(planner=PlanConfig(search=SearchConfig(resolution=0.01))).defining()
    assert fine == {k: v for k, v in default.items() if k != "search_resolution_m"}
    # nor one made when the search offered goal-oriented actions alone
    alone = EvalConfig(planner=PlanConfig(search=SearchConfig(clear_blockers=False))).defining()
    assert alone == {k: v for k, v in default.items() if k != "search_clear_blockers"}
    slow = EvalConfig(planner=PlanConfig(level1=Level1Config(symbolic_time_limit=3.0))).defining()
    assert slow == {**default, "symbolic_time_limit_s": 3.0}
    assert EvalConfig().plan_config(5, False) == PlanConfig(level1=Level1Config(seed=5),
                                                            kinematics=KinematicsConfig(feasibility=False))
