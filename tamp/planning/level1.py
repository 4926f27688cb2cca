"""Level 1 of Algorithm 1 (lines 4-14) and, beside it, our extensions to it.

    `level1` (lines 4-14):
      Sigma_init, Sigma_goal -> plans of N sampled domains, by frequency   lines 5-7    `symbolic_plans`
      for each plan, in decreasing order of probability                    line 9
          roll it out with the Dynamics Model: within tau of X_goal?       lines 10-11  `Verifier.check`
          the first verified plan is Level 1's                             line 12

How it runs (`Level1Config.settle`, on for both planners): a ranked plan is verified as soon as the search
has settled its place in the ranking (`symbolic.search.settled_prefix`), and the search ends once one is
taken; the plan is the one line 9 would reach after the whole search, sooner.

Our extensions (`Level1Config`; `bilevel_alg1` turns them off): the plans through the same symbolic
states verified with each ranked plan (`alternatives`), and from `focus_from` objects on: only misplaced
blocks picked, Level 1 in the sub-scene the goal involves (`level1_scene`), else one block at a time
(`level1_serial`); kinematics (`feas`) before a verified plan is taken.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from tamp.planning.config import Level1Config
from tamp.planning.kinematic_check import Feasibility, feasible_choice
from tamp.planning.models import Models
from tamp.planning.pruning import goal_oriented_actions, misplaced_objects
from tamp.planning.results import Candidate, Clock, Level1Result, reasons_json
from tamp.planning.verify import (
    Verification,
    VerifyConfig,
    refine_skeleton,
    verify,
    verify_many,
)

ALTERNATIVES_TOTAL = 256  # look-alike alternatives verified per problem (later symbolic plans alone): bounds time


# --- Algorithm 1, lines 4-14 -------------------------------------------------------------------
def level1(models: Models, X_init, X_goal, config: Level1Config, goal: VerifyConfig, clock: Clock,
           feas: Feasibility | None, release_targets: bool = True) -> Level1Result:
    """Level 1 of Algorithm 1 (lines 4-14): Sigma_init, Sigma_goal -> plans of N sampled domains, ranked
    by frequency -> the first plan whose Dynamics Model rollout ends within tau of X_goal (`chosen`).

    The plans are verified as the search settles their place (config.settle, module docstring).
    Our extensions: from config.focus_from objects on, Sigma is read on the sub-scene of the objects the
    goal involves (`level1_scene`, by the continuous search's pruning with `release_targets`; none when they
    are more than config.objects); and in `Verifier.check`, a ranked plan is verified together with the plans
    through the same symbolic states (`config.alternatives`), and a verified plan must pass the kinematic
    check and refine (`feas`)."""
    record = Level1Result()
    with clock.stage("symbols"):
        objects = level1_scene(X_init, X_goal, config, goal, release_targets)  # None: every object, as the paper
    if objects is not None and config.objects is not None and len(objects) > config.objects:
        record.reasons.append(f"level 1: the goal involves {len(objects)} objects, more than the "
                              f"{config.objects} of the scenes it plans in (level1.objects)")
        return record
    verifier = Verifier(models, X_init, X_goal, config, goal, clock, feas, record)

    def verify_settled(plans: list[Candidate]) -> bool:
        """Plans whose place in the ranking is final, as the search settles them: verified now, and the
        search ends once one is taken (our speed-up, `Level1Config.settle`: Alg. 1's plan, sooner)."""
        verifier.ranked += plans
        return verifier.run()

    settle = verify_settled if config.settle else None
    verifier.ranked = symbolic_plans(models, X_init, X_goal, config, goal, clock, record, objects=objects,
                                     on_settled=settle)  # lines 5-7
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
                   on_settled: Callable[[list[Candidate]], bool] | None = None) -> list[Candidate]:
    """Symbolic candidates, best first, their actions on the whole scene (planned in the sub-scene of
    `objects` if given); the planner's figures go to record.symbolic_stats, failures to record.reasons
    (prefixed 'level 1'). `on_settled` (python backend): given the candidates as their place in the ranking
    becomes final, during the search; True ends the search, and only the candidates given are returned
    (`SymbolicPlanner.plan_probabilistic`; symbolic_stats["settled"]: how many, None: all)."""
    with clock.stage("symbols"):
        try:
            planner = models.symbolic_planner(config.backend, config.symbolic_time_limit)
            problem = symbolic_problem(models, X_init, X_goal, config, goal, objects)
        except ValueError as error:
            record.reasons.append(f"level 1: {error}")
            return []

    def candidate(p) -> Candidate:
        return Candidate(in_scene(p.actions, objects), p.count, p.probability, states=p.states, objects=objects)

    if probabilistic:
        with clock.stage("symbolic"):
            out = planner.plan_probabilistic(problem, n_domains=config.n_domains, seed=config.seed,
                                             budget=config.budget_for(len(X_init)),
                                             on_settled=None if on_settled is None else
                                             lambda plans: on_settled([candidate(p) for p in plans]))
        record.symbolic_stats = {"n_domains": out.n_domains, "unique_plans": len(out.plans), "settled": out.settled,
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
    """Verification of Level 1's ranked plans (Alg. 1, lines 9-14) with our extensions, into `record`.

    - The ranked plans' own rollouts are computed in growing chunks (1, 2, 4, ... plans), all prefixes
      of one length in one forward pass (`verify_many`): the same numbers as one plan at a time.
    - Alternatives (config.alternatives > 0, states known): the best plans of a beam search over the
      plan's skeleton (`refine_skeleton`), whose rollouts verify them; the group's verified plans are
      tried smallest predicted error first.
    - Kinematics (`feas`): a verified plan is taken only if it passes the check and refines.
    """

    def __init__(self, models: Models, X_init, X_goal, config: Level1Config, goal: VerifyConfig, clock: Clock,
                 feas: Feasibility | None, record: Level1Result):
        self.models, self.X_init, self.X_goal, self.config, self.goal = models, X_init, X_goal, config, goal
        self.clock, self.feas, self.record = clock, feas, record
        self.ranked: list[Candidate] = []
        self.model = models.require_dynamics()
        self.checked: list[Candidate] = []  # verified so far: ranked plans and their alternatives
        self.any_verified = False
        self.alternatives_left = ALTERNATIVES_TOTAL
        self._rollouts: dict[int, Verification] = {}
        self._done = 0  # ranked plans checked
        self._ended = False  # a plan taken, or no refinement left

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
        """Verify ranked plan i (and its alternatives); take the first acceptable verified plan."""
        candidate = self.ranked[i]
        self._done += 1
        group: list[Candidate] = [candidate]
        checks: list[Verification] = []
        limit = min(self.config.alternatives, self.alternatives_left)
        if limit > 0 and candidate.states is not None and candidate.actions:
            planner = self.models.symbolic_planner(self.config.backend, self.config.symbolic_time_limit)
            objects = candidate.objects
            options = [list(in_scene(step, objects)) for step in planner.skeleton_options(
                len(self.X_init) if objects is None else len(objects), candidate.states)]
            best, own = refine_skeleton(self.model, self.X_init, self.X_goal, options, limit + 1,
                                        self.goal.tau_verify, also=candidate.actions)
            assert own is not None  # `also` given
            alternatives = [v for v in best if v.actions != candidate.actions][:limit]
            self.alternatives_left -= len(alternatives)
            group += [Candidate(v.actions, candidate.count, candidate.probability, alternative_of=i,
                                states=candidate.states, objects=objects) for v in alternatives]
            checks = [own] + alternatives
        else:
            checks = [self._rollout(i)]
        for c, v in zip(group, checks):
            c.error, c.verified = v.error, v.verified
        self.checked += group
        verified = [v for v in checks if v.verified]
        verified.sort(key=lambda v: v.error)
        self.any_verified = self.any_verified or bool(verified)
        if self.record.chosen is None:
            self.record.chosen = feasible_choice(verified, self.feas)

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
        alts = sum(c.alternative_of is not None for c in self.checked)
        record.reasons.append(f"level 1: none of the {len(ranked)} symbolic plans verified"
                              + (f" (nor {alts} alternatives through the same symbols)" if alts else "")
                              + f" (best predicted error {best * 100:.1f} cm, "
                                f"tau {self.goal.tau_verify * 100:g} cm)")


def verify_candidate(models: Models, X_init, X_goal, candidate: Candidate, goal: VerifyConfig) -> Verification:
    """Verify one candidate alone (its error and verdict recorded on it); the baselines report it."""
    v = verify(models.require_dynamics(), X_init, X_goal, candidate.actions, goal.tau_verify)
    candidate.error, candidate.verified = v.error, v.verified
    return v


# --- our extensions: the goal's sub-scene, one block at a time ---------------------------------
def level1_scene(X_init: np.ndarray, X_goal: np.ndarray, config: Level1Config, goal: VerifyConfig,
                 release_targets: bool = True) -> tuple[int, ...] | None:
    """The objects Level 1 plans over (our extension, `Level1Config.objects`); None: every object.

    From config.focus_from objects on: the objects of the continuous search's pruned actions in X_init
    (`pruning.goal_oriented_actions`, with or without `release_targets`), i.e. the blocks off their goal
    and, for each, the objects it would be placed on. The Symbolic Model then sees a scene of the size it
    was trained on, and the symbols of blocks that play no part cannot make Sigma_goal unreachable; the
    Dynamics Model verifies the plans in the whole scene. With more than config.objects, Level 1 plans
    only one block at a time (`level1_serial`)."""
    if config.objects is None or not config.focused(len(X_init)):
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
    symbols the models learned on 2-4 blocks are reliable, however many objects the whole goal involves."""
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    left = sorted(misplaced_objects(X_init, X_goal, goal.misplaced, goal.eps).tolist(),
                  key=lambda i: (X_goal[i, 2], i))
    if len(left) < 2:
        return  # one block: the sub-scene plan above was this plan
    X = X_init
    actions: list[tuple[int, int, int, int]] = []
    stages: list[int] = []  # the blocks placed, in order
    while left:
        for block in left:
            sub_goal = X.copy()
            sub_goal[block, :3] = X_goal[block, :3]
            v = level1(models, X, sub_goal, config, goal, clock, None, release_targets).chosen  # time counted
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
    record.candidates.append(Candidate(whole.actions, 0, 0.0, whole.error, whole.verified, stages=tuple(stages)))
    if not whole.verified:
        record.reasons.append(f"level 1, one block at a time: the joined plan is predicted {whole.error * 100:.1f} "
                              f"cm from the goal (tau {goal.tau_verify * 100:g} cm)")
        return
    record.chosen = feasible_choice([whole], feas)
    if record.chosen is None:
        record.reasons.append("level 1, one block at a time: the joined plan is not kinematically feasible")


__all__: Sequence[str] = ["Verifier", "in_scene", "level1", "level1_scene", "level1_serial", "symbolic_plans",
                          "symbolic_problem", "verify_candidate"]
