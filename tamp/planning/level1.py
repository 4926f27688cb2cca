"""Level 1 of Algorithm 1 (lines 4-14) and, beside it, our extensions to it.

    `level1` (lines 4-14):
      Sigma_init, Sigma_goal -> plans of N sampled domains, by frequency   lines 5-7    `symbolic_plans`
      for each plan, in decreasing order of probability                    line 9
          roll it out with the Dynamics Model: within tau of X_goal?       lines 10-11  `Verifier.check`
          the first verified plan is Level 1's                             line 12

Our extensions (`Level1Config`; `bilevel_alg1` turns them off): from `focus_from` objects on, only
misplaced blocks picked, Level 1 in the sub-scene the goal involves (`level1_scene`), else one block at a
time (`level1_serial`); kinematics (`feas`) before a verified plan is taken.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable, Sequence

import numpy as np

from tamp.planning.config import SUBSCENE_OBJECTS, Level1Config
from tamp.planning.kinematic_check import Feasibility, feasible_choice
from tamp.planning.models import Models
from tamp.planning.pruning import goal_oriented_actions, misplaced_objects
from tamp.planning.results import Candidate, Clock, Level1Result, reasons_json
from tamp.planning.search_trace import active
from tamp.planning.verify import Verification, VerifyConfig, verify, verify_many


# --- Algorithm 1, lines 4-14 -------------------------------------------------------------------
def level1(models: Models, X_init, X_goal, config: Level1Config, goal: VerifyConfig, clock: Clock,
           feas: Feasibility | None, release_targets: bool = True) -> Level1Result:
    """Level 1 of Algorithm 1 (lines 4-14): Sigma_init, Sigma_goal -> plans of N sampled domains, ranked
    by frequency -> the first plan whose Dynamics Model rollout ends within tau of X_goal (`chosen`).

    Our extensions: from config.focus_from objects on, Sigma is read on the sub-scene of the objects the
    goal involves (`level1_scene`, by the continuous search's pruning with `release_targets`; none when they
    are more than SUBSCENE_OBJECTS); and a verified plan must pass the kinematic check and refine (`feas`)."""
    record = Level1Result()
    with clock.stage("symbols"):
        objects = level1_scene(X_init, X_goal, config, goal, release_targets)  # None: every object, as the paper
    if objects is not None and len(objects) > SUBSCENE_OBJECTS:
        record.reasons.append(f"level 1: the goal involves {len(objects)} objects, more than the "
                              f"{SUBSCENE_OBJECTS} of the scenes it plans in")
        return record
    verifier = Verifier(models, X_init, X_goal, goal, clock, feas, record, config.wait_beyond)
    verifier.ranked = symbolic_plans(models, X_init, X_goal, config, goal, clock, record, objects=objects,  # 5-7
                                     decided=verifier.check_decided)
    verifier.run()  # line 9: in decreasing order of probability, lines 10-12
    verifier.finish()
    return record


def symbolic_problem(models: Models, X_init: np.ndarray, X_goal: np.ndarray, config: Level1Config,
                     goal: VerifyConfig, objects: tuple[int, ...] | None = None):
    """Sigma_init, Sigma_goal of the scene, or of the sub-scene of `objects` (`level1_scene`); from
    config.focus_from objects on, plans may pick up only the blocks off their goal."""
    from symbolic import make_problem

    assert models.symbolic is not None  # models.symbolic_planner() checked it
    X_init, X_goal = np.asarray(X_init), np.asarray(X_goal)
    scene = slice(None) if objects is None else list(objects)
    ui, ri = models.symbolic.symbols(X_init[scene])
    ug, rg = models.symbolic.symbols(X_goal[scene])
    movable = None
    if config.focused(len(X_init)):
        wrong = misplaced_objects(X_init, X_goal, goal.misplaced, goal.eps).tolist()
        movable = (wrong if objects is None else [objects.index(o) for o in wrong]) or None
    return make_problem(ui, ri, ug, rg, movable=movable)


def symbolic_plans(models: Models, X_init, X_goal, config: Level1Config, goal: VerifyConfig, clock: Clock,
                   record: Level1Result, probabilistic: bool = True, objects: tuple[int, ...] | None = None,
                   decided: Callable[[list[Candidate]], bool] | None = None) -> list[Candidate]:
    """Symbolic candidates, best first, their actions on the whole scene (planned in the sub-scene of
    `objects` if given); the planner's figures go to record.symbolic_stats, failures to record.reasons
    (prefixed 'level 1'). `decided` (python backend): asked, while the planner searches, about the head of
    the ranking that no later plan can overtake; True (one of them was taken) stops the search. The same
    Candidate object stands for a plan in every head and in the list returned."""
    with clock.stage("symbols"):
        try:
            planner = models.symbolic_planner(config.backend)
            problem = symbolic_problem(models, X_init, X_goal, config, goal, objects)
        except ValueError as error:
            record.reasons.append(f"level 1: {error}")
            return []

    made: dict[tuple, Candidate] = {}

    def candidate(p) -> Candidate:
        if p.actions not in made:
            made[p.actions] = Candidate(in_scene(p.actions, objects), p.count, p.probability, states=p.states,
                                        objects=objects)
        made[p.actions].probability = p.probability  # the share of the domains that have a plan so far
        return made[p.actions]

    if probabilistic:
        with clock.stage("symbolic"):
            out = planner.plan_probabilistic(problem, n_domains=config.n_domains, seed=config.seed,
                                             budget=config.budget,
                                             decided=None if decided is None else
                                             lambda head: decided([candidate(p) for p in head]))
        record.symbolic_stats = {"n_domains": out.n_domains, "unique_plans": len(out.plans),
                                 "outcomes": dict(out.statuses), "expanded": out.expanded,
                                 "generated": out.generated, "movable": problem.movable,
                                 "objects": None if objects is None else list(objects),
                                 "timings": {k: round(v, 6) for k, v in out.timings.items()}}
        if not out.plans:
            record.reasons.append(f"level 1: no symbolic plan in any of the {out.n_domains} sampled domains "
                                  f"(outcomes: {dict(out.statuses)})")
        return [candidate(p) for p in out.plans]
    with clock.stage("symbolic"):
        out = planner.plan_deterministic(problem)
    record.symbolic_stats = {"outcome": out.status.value}
    if not out.solved:
        record.reasons.append(f"level 1: no plan in the deterministic domain ({out.status.value}: {out.message})")
        return []
    from symbolic import steps_to_actions

    assert models.domain is not None  # models.symbolic_planner() checked it
    actions = steps_to_actions(models.domain, out.plan, len(X_init) if objects is None else len(objects))
    states = None if out.states is None else tuple(out.states)  # python backend: the plan's symbolic states
    return [Candidate(in_scene(actions, objects), 1, 1.0, states=states, objects=objects)]


class Verifier:
    """Verification of Level 1's ranked plans (Alg. 1, lines 9-14), into `record`.

    - Verification starts while the symbolic search runs (`check_decided`): the ranking's head that no
      later plan can overtake is checked between the search's depth bounds, and a plan taken there ends
      the search. The plan taken is the full ranking's first verified plan, found sooner.
    - The ranked plans' rollouts are computed in growing chunks (1, 2, 4, ... plans), all prefixes
      of one length in one forward pass (`verify_many`): the same numbers as one plan at a time.
    - Kinematics (`feas`, our extension): a verified plan is taken only if it passes the check and refines; one
      predicted `wait_beyond` or more from the goal only if it passes the check (`take`).
    """

    def __init__(self, models: Models, X_init, X_goal, goal: VerifyConfig, clock: Clock,
                 feas: Feasibility | None, record: Level1Result, wait_beyond: float | None = None):
        self.X_init, self.X_goal, self.goal, self.wait_beyond = X_init, X_goal, goal, wait_beyond
        self.clock, self.feas, self.record = clock, feas, record
        self.ranked: list[Candidate] = []
        self.model = models.require_dynamics()
        self.checked: list[Candidate] = []  # verified so far, in rank order
        self.any_verified = False
        self._rollouts: dict[int, Verification] = {}
        self._done = 0  # ranked plans checked
        self._ended = False  # a plan taken, or no refinement left
        self.recording = active() is not None  # keep each rollout and kinematic verdict (the search record)

    def check_decided(self, head: list[Candidate]) -> bool:
        """Check the plans of `head`, the ranking's decided head while the symbolic search goes on (its order is
        final: `symbolic_plans`); True when one is taken (or no refinement is left): the search may stop."""
        self.ranked = head
        return self.run()

    def run(self) -> bool:
        """Check the ranked plans not checked yet, in order, until one is taken (Alg. 1, line 12) or no
        full refinement is left; True when no more need checking."""
        while not self._ended and self._done < len(self.ranked):
            with self.clock.stage("verify"):
                self.check(self._done)
            self._ended = self.record.chosen is not None or \
                self.refinements_used_up()
        return self._ended

    def refinements_used_up(self) -> bool:
        """True (and the reason recorded) when no plan is chosen and no full refinement is left."""
        if self.feas is None or self.feas.refinements_left > 0 or self.record.chosen is not None:
            return False
        self.record.reasons.append(f"level 1: refinement budget ({self.feas.config.max_refinements}) used up")
        return True

    def _rollout(self, i: int) -> Verification:
        if i not in self._rollouts:
            chunk = self.ranked[i: i + max(1, len(self._rollouts))]
            for j, v in enumerate(verify_many(self.model, self.X_init, self.X_goal, [c.actions for c in chunk],
                                              self.goal.tau_verify)):
                self._rollouts[i + j] = v
        return self._rollouts[i]

    def check(self, i: int) -> None:
        """Verify ranked plan i; take it if it verifies (and passes the kinematic check and refines)."""
        candidate, v = self.ranked[i], self._rollout(i)
        self._done += 1
        candidate.error, candidate.verified = v.error, v.verified
        self.checked.append(candidate)
        self.any_verified = self.any_verified or v.verified
        if self.record.chosen is None and v.verified:
            take(self.record, v, self.feas, self.wait_beyond)
        if self.recording:
            kept(candidate, v, self.feas)

    def finish(self) -> None:
        """Record the candidates (checked ones, then the rest) and, without a chosen plan, why."""
        record, feas, ranked = self.record, self.feas, self.ranked
        record.candidates = self.checked + ranked[self._done:]
        if record.chosen is not None or not ranked:
            return
        if self.any_verified and feas is not None:
            record.reasons.append(f"level 1: no verified plan was kinematically feasible "
                                  f"(rejected: {reasons_json(feas.rejected[1])})")
            return
        best = min(c.error for c in self.checked if c.error is not None)
        record.reasons.append(f"level 1: none of the {len(ranked)} symbolic plans verified (best predicted error "
                              f"{best * 100:.1f} cm, tau {self.goal.tau_verify * 100:g} cm)")


def take(record: Level1Result, v: Verification, feas: Feasibility | None, wait_beyond: float | None) -> None:
    """Level 1's choice of the verified plan `v` (`feasible_choice`) into `record`. A plan predicted `wait_beyond`
    metres or more from the goal waits for Level 2 (`bilevel.level1_waits`) and is taken after the kinematic check
    alone (record.refine_later): it is refined only if Level 2 finds no plan, not in every call that searches."""
    later = wait_beyond is not None and v.error >= wait_beyond
    record.chosen = feasible_choice([v], feas, refine=not later)
    record.refine_later = later and record.chosen is not None and feas is not None and bool(v.actions)


def kept(candidate: Candidate, v: Verification, feas: Feasibility | None) -> None:
    """The search record's view of a checked candidate: its rollout, and each action's kinematic verdict."""
    candidate.predicted = v.trajectory
    candidate.kinematics = ("unchecked",) * len(v.actions) if feas is None else feas.verdicts(v.trajectory, v.actions)


def verify_candidate(models: Models, X_init, X_goal, candidate: Candidate, goal: VerifyConfig) -> Verification:
    """Verify one candidate alone (its error and verdict recorded on it); the baselines report it."""
    v = verify(models.require_dynamics(), X_init, X_goal, candidate.actions, goal.tau_verify)
    candidate.error, candidate.verified = v.error, v.verified
    if active() is not None:
        kept(candidate, v, None)
    return v


# --- our extensions: the goal's sub-scene, one block at a time ---------------------------------
def level1_scene(X_init: np.ndarray, X_goal: np.ndarray, config: Level1Config, goal: VerifyConfig,
                 release_targets: bool = True) -> tuple[int, ...] | None:
    """The objects Level 1 plans over (our extension); None: every object.

    From config.focus_from objects on: the objects of the continuous search's pruned actions in X_init
    (`pruning.goal_oriented_actions`, with or without `release_targets`), i.e. the blocks off their goal
    and, for each, the objects it would be placed on. The Symbolic Model then sees a scene of the size it
    was trained on, and the symbols of blocks that play no part cannot make Sigma_goal unreachable; the
    Dynamics Model verifies the plans in the whole scene. With more than SUBSCENE_OBJECTS, Level 1 plans
    only one block at a time (`level1_serial`)."""
    if not config.focused(len(X_init)):
        return None
    actions = goal_oriented_actions(np.asarray(X_init), np.asarray(X_goal), goal.misplaced, goal.eps,
                                    release_targets)
    return tuple(int(o) for o in np.unique(actions[:, [0, 2]]))


def in_scene(actions, objects: tuple[int, ...] | None) -> tuple[tuple[int, int, int, int], ...]:
    """Actions on a sub-scene's objects (indices into `objects`) as actions on the whole scene."""
    if objects is None:
        return tuple((int(i), int(g), int(j), int(r)) for i, g, j, r in actions)
    return tuple((objects[i], int(g), objects[j], int(r)) for i, g, j, r in actions)


def level1_serial(models: Models, X_init, X_goal, config: Level1Config, goal: VerifyConfig, clock: Clock,
                  feas: Feasibility | None, record: Level1Result, release_targets: bool = True) -> None:
    """Level 1 one misplaced block at a time (our extension, `Level1Config.serial`), into `record` (Level 1's,
    which gave no plan): its chosen plan, the joined plan as a candidate, why not.

    Stage by stage, from the state the plan so far is predicted to reach: for the misplaced blocks
    left, lowest goal first (a support before what stands on it), Level 1 plans to put that block at
    its goal and leave the others where they are (its sub-scene: the block and the objects it would
    be placed on, `level1_scene`); the first block with a plan predicted within goal.eps of that
    sub-goal is the stage's. The plans are joined and verified against X_goal in the whole scene,
    then checked and refined as one. No plan (with the reason) when a stage places no block or the
    joined plan does not verify. Each stage plans in a scene of two or three objects, where the
    symbols the models learned on 2-4 blocks are reliable, however many objects the whole goal involves.
    All stages together generate at most config.budget symbolic states, less what Level 1's search in the whole
    scene (`record`'s) generated: one budget bounds Level 1's symbolic search in a planning call."""
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    left = sorted(misplaced_objects(X_init, X_goal, goal.misplaced, goal.eps).tolist(),
                  key=lambda i: (X_goal[i, 2], i))
    if len(left) < 2:
        return  # one block: the sub-scene plan above was this plan
    X = X_init
    actions: list[tuple[int, int, int, int]] = []
    stages: list[int] = []  # the blocks placed, in order
    budget = None if config.budget is None else config.budget - record.symbolic_stats.get("generated", 0)
    while left:
        for block in left:
            if budget is not None and budget <= 0:
                record.reasons.append(f"level 1, one block at a time: its budget ({config.budget:,} symbolic states, "
                                      f"the whole scene's search included) spent after {len(stages)} placed ({stages})")
                record.symbolic_stats["serial"] = {"placed": stages, "left": left}
                return
            sub_goal = X.copy()
            sub_goal[block, :3] = X_goal[block, :3]
            stage = level1(models, X, sub_goal, config if budget is None else replace(config, budget=budget), goal,
                           clock, None, release_targets)  # time counted
            if budget is not None:
                budget -= stage.symbolic_stats.get("generated", 0)
            v = stage.chosen
            if v is not None and v.error < goal.eps:
                break
        else:
            record.reasons.append(f"level 1, one block at a time: no plan places any of blocks {left} after "
                                  f"{len(stages)} placed ({stages})")
            record.symbolic_stats["serial"] = {"placed": stages, "left": left}
            return
        stages.append(block)
        left.remove(block)
        actions += v.actions
        X = v.trajectory[-1]
    with clock.stage("verify"):
        whole = verify(models.require_dynamics(), X_init, X_goal, actions, goal.tau_verify)
    record.symbolic_stats["serial"] = {"placed": stages, "left": [], "error_m": round(whole.error, 6)}
    joined = Candidate(whole.actions, 0, 0.0, whole.error, whole.verified, stages=tuple(stages))
    record.candidates.append(joined)
    if not whole.verified:
        record.reasons.append(f"level 1, one block at a time: the joined plan is predicted {whole.error * 100:.1f} "
                              f"cm from the goal (tau {goal.tau_verify * 100:g} cm)")
        return
    take(record, whole, feas, config.wait_beyond)
    if active() is not None:
        kept(joined, whole, feas)
    if record.chosen is None:
        record.reasons.append("level 1, one block at a time: the joined plan is not kinematically feasible")


__all__: Sequence[str] = ["Verifier", "in_scene", "level1", "level1_scene", "level1_serial", "symbolic_plans",
                          "symbolic_problem", "verify_candidate"]
