"""The planner's flags, shared by `tamp plan` and `tamp evaluate`: one flag per `PlanConfig` field a user
sets (`PLANNER_FLAGS`), the rest deliberately left to code (`NOT_EXPOSED`; a test checks that every field
is one or the other), and `planner_config`, which reads them back."""
from __future__ import annotations

import argparse
import dataclasses

from tamp.app.args import fraction, non_negative_float, non_negative_int, object_count, positive_float, positive_int
from tamp.planning.config import SYMBOLIC_BACKENDS, PlanConfig


def add_planner_arguments(p: argparse.ArgumentParser, feasibility: bool = True) -> None:
    """The planner's flags, the same for `tamp plan` and `tamp evaluate`; `planner_config` reads them.
    `feasibility`: offer --no-feasibility (evaluate chooses it per method instead)."""
    default = PlanConfig()
    p.add_argument("--n-domains", type=positive_int, default=default.level1.n_domains,
                   help=f"N sampled symbolic domains (default {default.level1.n_domains})")
    p.add_argument("--symbolic-backend", dest="symbolic_backend", choices=tuple(SYMBOLIC_BACKENDS),
                   default=default.level1.backend, help=backend_help(default.level1.backend))
    p.add_argument("--symbolic-time-limit", type=positive_float, default=default.level1.symbolic_time_limit,
                   help="wall-clock limit per symbolic planner call, s "
                   f"(default {default.level1.symbolic_time_limit:g}; "
                   "Fast Downward needs more at 4 objects)")
    p.add_argument("--level1-budget", type=positive_int, default=default.level1.budget,
                   help="symbolic states Level 1's search (one for all N domains) may generate per planning call "
                   f"(default {default.level1.budget}: at most about 0.2-0.3 s); deterministic, whatever the machine's "
                   "load")
    p.add_argument("--focus-from", type=positive_int, default=default.level1.focus_from, metavar="N",
                   help="with N or more blocks, Level 1's symbolic plans pick up only the blocks off their goal "
                   "(farther than the success tolerance in x, y), as the continuous search's pruning does: the "
                   "symbolic search then grows with the blocks to move, not all of them "
                   f"(default {default.level1.focus_from}; "
                   "`bilevel_alg1`, the paper's Algorithm 1, never restricts)")
    p.add_argument("--level1-focus-budget", type=positive_int, default=default.level1.focus_budget,
                   metavar="STATES",
                   help="with --focus-from blocks or more, Level 1's budget instead of --level1-budget (default "
                   f"{default.level1.focus_budget}: about 40-60 ms; there the learned symbols rarely give a verified "
                   "plan beyond a few thousand states, and a search that ends at its budget only delays the "
                   "continuous search; the --level1-budget value gives one budget at any number of blocks)")
    p.add_argument("--level1-objects", type=object_count, default=default.level1.objects, metavar="N",
                   help="with --focus-from blocks or more, Level 1 plans in the scene of the objects the goal involves "
                   "(the blocks off their goal and those the continuous search would place them on), which the "
                   "Symbolic Model reads as a scene of the size it was trained on, and verifies its plans in the "
                   "whole scene; when more than N objects are involved it plans one block at a time "
                   "(--no-level1-serial: the continuous search plans at once) "
                   f"(default {default.level1.objects}: the bundled models' 2-4 block training scenes; "
                   "`bilevel_alg1` always plans in the whole scene)")
    p.add_argument("--no-level1-objects", dest="level1_objects", action="store_const", const=None,
                   help="Level 1 plans in the whole scene at any number of blocks")
    p.add_argument("--no-level1-serial", dest="level1_serial", action="store_false",
                   help="with --focus-from blocks or more, when Level 1 gives no verified plan it does not plan one "
                   "misplaced block at a time (default: it does, lowest goal first, each block in the scene of the "
                   "objects it would be placed on, and verifies the joined plan in the whole scene)")
    p.add_argument("--level1-confident", type=positive_float, default=default.level1.wait_beyond, metavar="METRES",
                   help="a verified Level-1 plan predicted farther than this from the goal (worst block) is kept "
                   "while the continuous search looks for a plan, and returned only if it finds none (default "
                   f"{default.level1.wait_beyond:g} m, the success tolerance; the paper takes every plan verified "
                   f"within tau = {default.verify.tau_verify:g} m: give that value for its rule; `bilevel_alg1` always "
                   "does)")
    p.add_argument("--no-level1-settle", dest="level1_settle", action="store_false",
                   help="let the symbolic search finish before verifying any plan, so the candidates list every plan "
                   "of the N domains (default: a plan is verified once its place in the ranking is final and the "
                   "search ends when one is taken; the plan is the same)")
    p.add_argument("--no-level1-cut", dest="level1_cut", action="store_false",
                   help="return a verified Level-1 plan as verified (default: it ends at its first action predicted "
                   "to bring every block within --confident of the goal, and an action whose block the next one "
                   "picks again is dropped when the shorter plan is predicted as close; `bilevel_alg1` never "
                   "shortens)")
    p.add_argument("--no-keep-plan", dest="keep_plan", action="store_false",
                   help="with --replan (bilevel_replan), plan again in every round, as the paper does (default, for "
                   "bilevel and cfs: keep the rest of the last plan while it refines and ends within --confident of "
                   "the goal, as predicted when the plan is on course (--on-course), else rolled out from the "
                   "observed state; bilevel_alg1 and the symbolic baselines always plan again)")
    p.add_argument("--on-course", type=positive_float, default=default.loop.on_course, metavar="METRES",
                   help="with the kept plan (--replan): when every block of the observed state is within this "
                   "distance of where the last plan predicted it, the plan's own prediction of the rest decides "
                   "whether it is kept, not a new rollout from the observed state: the world did what the plan "
                   "expected, and the model's rollouts swing under millimetre changes "
                   f"(default {default.loop.on_course:g} m)")
    p.add_argument("--no-on-course", dest="on_course", action="store_const", const=None,
                   help="keep the rest of the last plan only by its rollout from the observed state, however close the "
                   "blocks are to the plan's own prediction")
    p.add_argument("--no-commit", dest="commit", action="store_false",
                   help="the closed loop (--replan; bilevel_loop) replaces a kept plan whose end is predicted beyond "
                   "--confident (but within the success tolerance) by any new plan predicted closer (default: only by "
                   "one predicted within --confident; trading a plan on course for one a few millimetres closer let "
                   "the loop wander between near-equal plans)")
    p.add_argument("--max-actions", type=positive_int, default=default.loop.max_actions,
                   help="the closed loop (--replan; bilevel_loop) gives up after sending this many actions to the "
                   f"world (default {default.loop.max_actions}: a goal of up to 5 random actions, with room to "
                   "recover from misses)")
    p.add_argument("--stop-margin", type=non_negative_float, default=None, metavar="METRES",
                   help="the closed loop that does not know k (bilevel_loop) stops only this far inside the success "
                   "tolerance; within the tolerance but short of that it takes one more step only if a plan is "
                   "predicted within --confident, so that noisy observations that put the blocks within the "
                   "tolerance while they are not do not end it (default 0: exact observations; with --noise SIGMA, "
                   "SIGMA)")
    p.add_argument("--looks", type=non_negative_int, default=None, metavar="N",
                   help="the closed loop that does not know k (bilevel_loop) observes the scene again up to N times "
                   "after a round without a plan before it stops: a noisy observation may put neighbours into each "
                   "other, so that the kinematic check rejects every action, where the next one does not (default 0: "
                   "exact observations; with --noise, 2)")
    p.add_argument("--remember", type=positive_float, default=default.loop.remember, metavar="METRES",
                   help="the closed loop that does not know k (bilevel_loop) remembers an action that lands this far "
                   "from the Dynamics Model's prediction; once the world has done it twice alike, the loop predicts "
                   "it as the world did it from states whose other blocks lie this close, until the world does "
                   f"otherwise there (default {default.loop.remember:g} m: the loop stops trying a move the world "
                   "keeps undoing, such as a cube on the low end of a tilted bar)")
    p.add_argument("--no-remember", dest="remember", action="store_const", const=None,
                   help="the closed loop plans every round with the Dynamics Model alone, whatever it has seen")
    p.add_argument("--loop-search-budget", type=positive_int, default=default.loop.search_budget, metavar="EXPANSIONS",
                   help="the closed loop (--replan; bilevel_loop) gives up when its rounds' continuous searches have "
                   f"spent this many expansions (default {default.loop.search_budget}: twice one search's budget, "
                   "so that a loop whose rounds keep failing ends in about the time of two failed searches)")
    p.add_argument("--loop-greedy-budget", dest="loop_greedy_search_budget", type=positive_int,
                   default=default.loop.greedy_search_budget, metavar="EXPANSIONS",
                   help="from --greedy-from blocks on, --loop-search-budget is this instead (default "
                   f"{default.loop.greedy_search_budget}: there loops that reach the goal spend at most about 600)")
    p.add_argument("--loop-stall", type=positive_int, default=default.loop.stall, metavar="EXPANSIONS",
                   help="the closed loop (--replan; bilevel_loop) ends a round's continuous search after this many "
                   "expansions without a state closer to the goal, instead of --stall and --greedy-stall: a "
                   f"round that fails still has a widened search and the next round (default {default.loop.stall})")
    p.add_argument("--no-widen", dest="widen", action="store_false",
                   help="the closed loop stops at a round without a plan (default: it first searches again over "
                   "all 9 n^2 actions, which can move a block out of the way, unstack, or move a block already "
                   "at its goal)")
    p.add_argument("--max-expansions", type=positive_int, default=default.search.max_expansions,
                   help="continuous search node limit per planning call: it decides when the search gives up, "
                   f"whatever the machine's load (default {default.search.max_expansions}, about 4 s at 4 objects)")
    p.add_argument("--confident", type=positive_float, default=default.verify.confident, metavar="METRES",
                   help="the continuous search ends at a goal state whose every object is predicted within this "
                   f"distance of its goal (default {default.verify.confident:g} m); a goal state within the success "
                   f"tolerance ({default.verify.eps:g} m) but not this close is kept while it looks on")
    p.add_argument("--look-on", type=non_negative_int, default=default.search.look_on, metavar="EXPANSIONS",
                   help="expansions the continuous search spends looking for a goal state within --confident after "
                   f"finding one that is not (default {default.search.look_on}; 0 returns the first goal state)")
    p.add_argument("--max-fragility", type=fraction, default=default.search.max_fragility, metavar="FRACTION",
                   help="a plan (the continuous search's goal state, a verified Level-1 plan) is taken at once only "
                   "if at most this fraction of its rollouts with the Dynamics Model's inputs perturbed by "
                   f"{default.search.noise * 1000:g} mm misses the goal (default {default.search.max_fragility:g}); "
                   "otherwise the search looks on as for a goal state beyond --confident, and Level 1's plan waits "
                   "for the continuous search as beyond --level1-confident")
    p.add_argument("--no-fragility", dest="max_fragility", action="store_const", const=None,
                   help="take plans by their predicted error alone (no perturbed rollouts)")
    p.add_argument("--max-doubt", type=positive_float, default=default.search.max_doubt, metavar="METRES",
                   help="with an ensemble Dynamics Model (tamp train --ensemble, tamp practice): a plan is taken at "
                   "once only if no step of it may miss by more than this, by the model's own 95 %% bound; otherwise "
                   "it waits as a fragile one does (default: off)")
    p.add_argument("--greedy-from", type=positive_int, default=default.search.greedy_from, metavar="N",
                   help="from N blocks on, the continuous search counts the distance to the goal in units of "
                   "--greedy-h-unit metres instead of metres, so that an action weighs less against the distance "
                   f"still to go (default: {default.search.greedy_from or 'off'})")
    p.add_argument("--no-greedy", dest="greedy_from", action="store_const", const=None,
                   help="the continuous search counts the distance to the goal in metres at any number of blocks")
    p.add_argument("--greedy-h-unit", type=positive_float, default=default.search.greedy_h_unit, metavar="METRES",
                   help=f"the unit of --greedy-from (default {default.search.greedy_h_unit})")
    p.add_argument("--greedy-per-misplaced", type=non_negative_float, default=default.search.greedy_per_misplaced,
                   metavar="UNITS", help="from --greedy-from blocks on, the distance to the goal also counts this many "
                   "units per block still off its goal: each needs an action (default "
                   f"{default.search.greedy_per_misplaced})")
    p.add_argument("--resolution", type=positive_float, default=default.search.resolution, metavar="METRES",
                   help="the continuous search treats states whose blocks lie in the same cells of a grid this fine as "
                   f"one (default {default.search.resolution:g}: the Dynamics Model is good to about a centimetre, so "
                   "finer cells spend the node budget on near-copies of one scene; bilevel_alg1 keeps 0.01)")
    p.add_argument("--paper-pruning", dest="release_targets", action="store_false",
                   help="the continuous search (cfs, and bilevel's Level 2) prunes actions by the paper's rule alone: "
                   "a misplaced block goes onto the object closest to its goal or onto itself (default: also onto "
                   "the object with an offset release point closest to its goal and, for a goal above the table, onto "
                   "the object it would rest on (the top of a stack, or a raised bar on whose end it rests), each "
                   "when that is another object; `bilevel_alg1` always uses the paper's rule)")
    p.add_argument("--no-clear-blockers", dest="clear_blockers", action="store_false",
                   help="the continuous search offers only the goal-oriented actions (default: when the kinematic "
                   "check rejects the action into a goal state, it also offers the moves of the blocks in that "
                   "action's way, a neighbour of the picked block or of its place, since a block already at its goal "
                   "may have to move first)")
    p.add_argument("--time-limit", type=positive_float, default=default.search.time_limit, metavar="SECONDS",
                   help="wall-clock bound on every planning call (each round of a closed loop is one): its continuous "
                   "searches end and no further plan is refined once it has run this long, and the result says so "
                   "(default: off, so that --max-expansions and --stall decide, whatever the machine's load)")
    p.add_argument("--stall", type=positive_int, default=default.search.stall, metavar="EXPANSIONS",
                   help="below --greedy-from blocks, the continuous search ends after this many expansions without a "
                   "state closer to the goal (default: off, the search runs to --max-expansions: most searches that "
                   "find a plan plateau for a few hundred expansions, a few for more)")
    p.add_argument("--no-stall", dest="stall", action="store_const", const=None,
                   help="below --greedy-from blocks, the continuous search runs to --max-expansions however long it "
                   "stays on a plateau")
    p.add_argument("--greedy-stall", type=positive_int, default=default.search.greedy_stall, metavar="EXPANSIONS",
                   help="from --greedy-from blocks on, the continuous search ends after this many expansions without a "
                   "state closer to the goal (the closed loop's rounds: --loop-stall): there a search finds its plan "
                   f"soon after its last progress or not at all (default {default.search.greedy_stall})")
    p.add_argument("--no-greedy-stall", dest="greedy_stall", action="store_const", const=None,
                   help="from --greedy-from blocks on, the continuous search runs to --max-expansions however long it "
                   "stays on a plateau")
    p.add_argument("--rest-within", type=positive_float, default=default.kinematics.rest_within, metavar="METRES",
                   help="the kinematic checks set a predicted block this close to resting on the table or on a block "
                   "down on it: the checks are exact to the millimetre, a predicted position is not (default "
                   f"{default.kinematics.rest_within})")
    p.add_argument("--no-rest-within", dest="rest_within", action="store_const", const=None,
                   help="the kinematic checks take every predicted block where the Dynamics Model puts it")
    if feasibility:
        p.add_argument("--no-feasibility", dest="feasibility", action="store_false",
                       help="cfs and bilevel without kinematics in the planning loop (no feasibility check of "
                       "actions on the predicted states, no refinement before a plan is returned)")


def backend_help(default: str) -> str:
    """The help of --symbolic-backend, from the registry of symbolic planners."""
    return "symbolic planner: " + ", ".join(f"{name} ({what}{', default' if name == default else ''})"
                                            for name, what in SYMBOLIC_BACKENDS.items())


# PlanConfig's fields that flags set: {part: {field: the flag's argparse dest}}; `planner_config` reads them
PLANNER_FLAGS: dict[str, dict[str, str]] = {
    "level1": {"n_domains": "n_domains", "backend": "symbolic_backend", "symbolic_time_limit": "symbolic_time_limit",
               "budget": "level1_budget", "focus_from": "focus_from", "focus_budget": "level1_focus_budget",
               "objects": "level1_objects", "serial": "level1_serial", "wait_beyond": "level1_confident",
               "cut": "level1_cut", "settle": "level1_settle"},
    "verify": {"confident": "confident"},
    "search": {"max_expansions": "max_expansions", "time_limit": "time_limit", "stall": "stall",
               "greedy_stall": "greedy_stall",
               "greedy_from": "greedy_from", "greedy_h_unit": "greedy_h_unit",
               "greedy_per_misplaced": "greedy_per_misplaced",
               "look_on": "look_on", "max_fragility": "max_fragility",
               "release_targets": "release_targets", "max_doubt": "max_doubt", "resolution": "resolution",
               "clear_blockers": "clear_blockers"},
    "kinematics": {"feasibility": "feasibility", "rest_within": "rest_within"},  # evaluate: feasibility per method
    "loop": {"keep_plan": "keep_plan", "on_course": "on_course", "commit": "commit", "max_actions": "max_actions",
             "widen": "widen",
             "search_budget": "loop_search_budget", "greedy_search_budget": "loop_greedy_search_budget",
             "stall": "loop_stall", "stop_margin": "stop_margin", "remember": "remember", "looks": "looks"},
}
# flags whose None means "the default, or what the run's faults imply" (`--noise` sets the stop margin and the looks)
AUTO_FLAGS = ("stop_margin", "looks")
# the fields deliberately without a flag (their defaults hold; tests and benchmarks set them in code)
NOT_EXPOSED = {"level1": ("seed", "time_budget", "verify_all", "alternatives", "alternatives_total", "nonempty"),
               "verify": ("tau_verify", "eps", "misplaced"), "kinematics": ("max_refinements",),
               "search": ("weight", "max_depth", "batched", "prune", "noise"),
               "loop": ("widen_expansions", "revisit", "progress", "remember_alike")}


def auto_given(args: argparse.Namespace) -> set[str]:
    """The LoopConfig fields of `AUTO_FLAGS` the user set (what the run's faults must not override)."""
    return {dest for dest in AUTO_FLAGS if getattr(args, dest, None) is not None}


def planner_config(args: argparse.Namespace) -> PlanConfig:
    """The PlanConfig of the flags of `add_planner_arguments` (seed 0: callers set the problem's)."""
    default = PlanConfig()
    return PlanConfig(**{part: dataclasses.replace(getattr(default, part), **{
        name: getattr(args, dest) for name, dest in flags.items()
        if hasattr(args, dest) and not (dest in AUTO_FLAGS and getattr(args, dest) is None)})
        for part, flags in PLANNER_FLAGS.items()})


# the closed loop's flags by LoopConfig field: both loops keep plans; the loop that does not know k (`tamp plan
# --replan` without --rounds, `bilevel_loop`) alone has a budget and widens
LOOP_FLAGS = {"keep_plan": "--no-keep-plan", "on_course": "--on-course/--no-on-course",
              "max_actions": "--max-actions", "search_budget": "--loop-search-budget",
              "greedy_search_budget": "--loop-greedy-budget", "widen": "--no-widen",
              "stall": "--loop-stall", "commit": "--no-commit", "stop_margin": "--stop-margin",
              "remember": "--remember/--no-remember", "looks": "--looks"}
UNTIL_GOAL_FIELDS = ("commit", "max_actions", "search_budget", "greedy_search_budget", "widen", "stall", "stop_margin",
                     "remember", "looks")


def loop_flags_given(config: PlanConfig, until_goal_only: bool = False) -> list[str]:
    """The closed-loop flags whose settings in `config` differ from the defaults (the flags a user gave),
    those of the loop that does not know k alone with `until_goal_only`; a command refuses them where no
    such loop runs."""
    default = PlanConfig().loop
    fields = UNTIL_GOAL_FIELDS if until_goal_only else tuple(LOOP_FLAGS)
    return [LOOP_FLAGS[f] for f in fields if getattr(config.loop, f) != getattr(default, f)]
