"""Level 1 of Algorithm 1 (lines 4-14) and, beside it, our extensions to it.

    `level1` (lines 4-14):
      Sigma_init, Sigma_goal -> plans of N sampled domains, by frequency   lines 5-7    `level1_plans`
      for each plan, in decreasing order of probability                    line 9
          roll it out with the Dynamics Model: within tau of X_goal?       lines 10-11  `Verifier.check`
          the first verified plan is Level 1's                             line 12

How it runs (`Level1Config.settle`, on for both planners): a ranked plan is verified as soon as the search
has settled its place in the ranking (`symbolic.search.settled_prefix`), and the search ends once one is
taken; the plan is the one line 9 would reach after the whole search, sooner.

Our extensions (`Level1Config`; `bilevel_alg1` turns them off): the plans through the same symbolic
states verified with each ranked plan (`alternatives`), a non-empty plan when X_init is not at the
goal (`nonempty`), and from `focus_from` objects on: only misplaced blocks picked, Level 1 in the
sub-scene the goal involves (`level1_scene`), else one block at a time (`level1_serial`); a verified
plan cut where it reaches the goal (`cut`); kinematics (`feas`) before a verified plan is taken.
"""
from __future__ import annotations

import time
from typing import Callable, Sequence

import numpy as np

from tamp.planning.config import PlanConfig
from tamp.planning.feasibility import Feasibility, feasible_choice
from tamp.planning.models import Models
from tamp.planning.results import LEVEL1_STAGES, Candidate, PlanResult
from tamp.planning.search import goal_oriented_actions, misplaced_objects
from tamp.planning.verify import Verification, goal_error, refine_skeleton, verify, verify_many, without_repicks


# --- Algorithm 1, lines 4-14 -------------------------------------------------------------------
def level1(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
           feas: Feasibility | None) -> Verification | None:
    """Level 1 of Algorithm 1 (lines 4-14): Sigma_init, Sigma_goal -> plans of N sampled domains, ranked
    by frequency -> the first plan whose Dynamics Model rollout ends within tau of X_goal.

    The plans are verified as the search settles their place (cfg.level1.settle, module docstring).
    Our extensions: from cfg.level1.focus_from objects on, Sigma is read on the sub-scene of the objects the
    goal involves (`level1_scene`; none when they are more than cfg.level1.objects); and in
    `Verifier.check`, a ranked plan is verified together with the plans through the same symbolic
    states (`cfg.level1.alternatives`), and a verified plan must pass the kinematic check and refine (`feas`)."""
    t = time.perf_counter()
    objects = level1_scene(X_init, X_goal, cfg)  # our extension; None: every object, as the paper plans
    if objects is not None and cfg.level1.objects is not None and len(objects) > cfg.level1.objects:
        result.timings["symbols"] = time.perf_counter() - t
        result.reasons.append(f"level 1: the goal involves {len(objects)} objects, more than the "
                              f"{cfg.level1.objects} of the scenes it plans in (--level1-objects)")
        return None
    verifier = Verifier(models, X_init, X_goal, cfg, result, feas, [])

    def verify_settled(plans: list[Candidate]) -> bool:
        """Plans whose place in the ranking is final, as the search settles them: verified now, and the
        search ends once one is taken (our speed-up, `Level1Config.settle`: Alg. 1's plan, sooner)."""
        verifier.ranked += plans
        return verifier.run()

    settle = verify_settled if cfg.level1.settle and not cfg.level1.verify_all else None
    verifier.ranked = level1_plans(models, X_init, X_goal, cfg, result, objects=objects, on_settled=settle)  # 5-7
    verifier.run()  # line 9: in decreasing order of probability, lines 10-12
    verifier.finish()
    return verifier.chosen


def symbolic_problem(models: Models, X_init: np.ndarray, X_goal: np.ndarray, cfg: PlanConfig,
                     objects: tuple[int, ...] | None = None):
    """Sigma_init, Sigma_goal of the scene, or of the sub-scene of `objects` (`level1_scene`); with
    cfg.level1.nonempty, the empty plan is ruled out when it cannot verify (X_init itself is not within tau
    of X_goal although the symbols may agree); from cfg.level1.focus_from objects on, plans may pick up only
    the blocks off their goal."""
    from symbolic import make_problem

    assert models.symbolic is not None  # models.symbolic_planner() checked it
    X_init, X_goal = np.asarray(X_init), np.asarray(X_goal)
    scene = slice(None) if objects is None else list(objects)
    ui, ri = models.symbolic.symbols(X_init[scene])
    ug, rg = models.symbolic.symbols(X_goal[scene])
    movable = None
    if cfg.level1.focused(len(X_init)):
        wrong = misplaced_objects(X_init, X_goal, cfg.search.misplaced, cfg.search.eps).tolist()
        movable = (wrong if objects is None else [objects.index(o) for o in wrong]) or None
    nonempty = cfg.level1.nonempty and goal_error(X_init, X_goal) >= cfg.verify.tau_verify
    return make_problem(ui, ri, ug, rg, nonempty=nonempty, movable=movable)


def level1_plans(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
                 probabilistic: bool = True, objects: tuple[int, ...] | None = None,
                 on_settled: Callable[[list[Candidate]], bool] | None = None) -> list[Candidate]:
    """Symbolic candidates, best first, their actions on the whole scene (planned in the sub-scene of
    `objects` if given); failures go to result.reasons (prefixed 'level 1'). `on_settled` (python
    backend): given the candidates as their place in the ranking becomes final, during the search;
    True ends the search, and only the candidates given are returned
    (`SymbolicPlanner.plan_probabilistic`; result.symbolic_stats["settled"]: how many, None: all)."""
    t = time.perf_counter()
    try:
        planner = models.symbolic_planner(cfg.level1.backend, cfg.level1.symbolic_time_limit)
        problem = symbolic_problem(models, X_init, X_goal, cfg, objects)
    except ValueError as error:
        result.reasons.append(f"level 1: {error}")
        return []
    finally:
        result.timings["symbols"] = time.perf_counter() - t
    t = time.perf_counter()

    def candidate(p) -> Candidate:
        return Candidate(in_scene(p.actions, objects), p.count, p.probability, states=p.states, objects=objects)

    if probabilistic:
        out = planner.plan_probabilistic(problem, n_domains=cfg.level1.n_domains, seed=cfg.level1.seed,
                                         time_budget=cfg.level1.time_budget,
                                         budget=cfg.level1.budget_for(len(X_init)),
                                         on_settled=None if on_settled is None else
                                         lambda plans: on_settled([candidate(p) for p in plans]))
        result.timings["symbolic"] = time.perf_counter() - t - out.timings.get("elsewhere", 0.0)
        result.symbolic_stats = {"n_domains": out.n_domains, "unique_plans": len(out.plans), "settled": out.settled,
                                 "outcomes": dict(out.statuses), "expanded": out.expanded,
                                 "generated": out.generated, "movable": problem.movable,
                                 "objects": None if objects is None else list(objects),
                                 "timings": {k: round(v, 6) for k, v in out.timings.items()}}
        if not out.plans:
            result.reasons.append(f"level 1: no symbolic plan in any of the {out.n_domains} sampled domains "
                                  f"(outcomes: {dict(out.statuses)})")
        return [candidate(p) for p in out.plans]
    out = planner.plan_deterministic(problem)
    result.timings["symbolic"] = time.perf_counter() - t
    result.symbolic_stats = {"outcome": out.status.value}
    if not out.solved:
        result.reasons.append(f"level 1: no plan in the deterministic domain ({out.status.value}: {out.message})")
        return []
    from symbolic import steps_to_actions

    assert models.domain is not None  # models.symbolic_planner() checked it
    actions = steps_to_actions(models.domain, out.plan, len(X_init) if objects is None else len(objects))
    states = None if out.states is None else tuple(out.states)  # python backend: the plan's symbolic states
    return [Candidate(in_scene(actions, objects), 1, 1.0, states=states, objects=objects)]


class Verifier:
    """Verification of Level 1's ranked plans (Alg. 1, lines 9-14) with our extensions, and its record.

    - The ranked plans' own rollouts are computed in growing chunks (1, 2, 4, ... plans), all prefixes
      of one length in one forward pass (`verify_many`): the same numbers as one plan at a time.
    - Alternatives (cfg.level1.alternatives > 0, states known): the best plans of a beam search over the
      plan's skeleton (`refine_skeleton`), whose rollouts verify them; the group's verified plans are
      tried smallest predicted error first.
    - Kinematics (`feas`): a verified plan is taken only if it passes the check and refines.
    """

    def __init__(self, models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
                 feas: Feasibility | None, ranked: list[Candidate]):
        self.models, self.X_init, self.X_goal, self.cfg, self.result, self.feas, self.ranked = \
            models, X_init, X_goal, cfg, result, feas, ranked
        self.model = models.require_dynamics()
        self.checked: list[Candidate] = []  # verified so far: ranked plans and their alternatives
        self.chosen: Verification | None = None
        self.any_verified = False
        self.alternatives_left = cfg.level1.alternatives_total
        self._rollouts: dict[int, Verification] = {}
        self._done = 0  # ranked plans checked
        self._seconds = 0.0  # spent in `run`
        self._ended = False  # a plan taken, or no refinement left

    def run(self) -> bool:
        """Check the ranked plans not checked yet, in order, until one is taken (Alg. 1, line 12) or no
        full refinement is left; True when no more need checking."""
        t = time.perf_counter()
        try:
            while not self._ended and self._done < len(self.ranked):
                self.check(self._done)
                self._ended = (self.chosen is not None and not self.cfg.level1.verify_all) or \
                    self.refinements_used_up()
            return self._ended
        finally:
            self._seconds += time.perf_counter() - t

    def refinements_used_up(self) -> bool:
        """True (and the reason recorded) when no plan is chosen and no full refinement is left."""
        if self.feas is None or self.feas.refinements_left > 0 or self.chosen is not None:
            return False
        self.result.reasons.append(f"level 1: refinement budget ({self.cfg.kinematics.max_refinements}) used up")
        return True

    def _rollout(self, i: int) -> Verification:
        if i not in self._rollouts:
            chunk = self.ranked[i: i + max(1, len(self._rollouts))]
            for j, v in enumerate(verify_many(self.model, self.X_init, self.X_goal, [c.actions for c in chunk],
                                              self.cfg.verify.tau_verify)):
                self._rollouts[i + j] = v
        return self._rollouts[i]

    def check(self, i: int) -> None:
        """Verify ranked plan i (and its alternatives); take the first acceptable verified plan."""
        candidate = self.ranked[i]
        self._done += 1
        group: list[Candidate] = [candidate]
        checks: list[Verification] = []
        limit = min(self.cfg.level1.alternatives, self.alternatives_left)
        if limit > 0 and candidate.states is not None and candidate.actions:
            planner = self.models.symbolic_planner(self.cfg.level1.backend, self.cfg.level1.symbolic_time_limit)
            objects = candidate.objects
            options = [list(in_scene(step, objects)) for step in planner.skeleton_options(
                len(self.X_init) if objects is None else len(objects), candidate.states)]
            best, own = refine_skeleton(self.model, self.X_init, self.X_goal, options, limit + 1,
                                        self.cfg.verify.tau_verify, also=candidate.actions)
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
        if self.cfg.level1.cut:
            verified = [self._shortened(v) for v in verified]
        verified.sort(key=lambda v: v.error)
        self.any_verified = self.any_verified or bool(verified)
        if self.chosen is None:
            self.chosen = feasible_choice(verified, self.feas)

    def _shortened(self, v: Verification) -> Verification:
        """`v` cut where it reaches the goal, then without the picks the next action repeats if that
        plan is predicted within search.confident of the goal or no farther than `v` (cfg.level1.cut)."""
        v = v.cut(self.X_goal, self.cfg.search.confident)
        shorter = without_repicks(v.actions)
        if len(shorter) == len(v.actions):
            return v
        w = verify(self.model, self.X_init, self.X_goal, shorter, self.cfg.verify.tau_verify)
        return w if w.verified and (w.error < self.cfg.search.confident or w.error <= v.error) else v

    def finish(self) -> None:
        """Record the candidates (checked ones, then the rest), the verification time and, without a
        chosen plan, why."""
        result, feas, ranked = self.result, self.feas, self.ranked
        result.candidates = self.checked + ranked[self._done:]
        if ranked:
            result.timings["verify"] = self._seconds - (
                0.0 if feas is None else result.timings["feasibility"] + result.timings["refine"])
        if self.chosen is not None or not ranked:
            return
        if self.any_verified and feas is not None:
            rejected = result.rejected_dict()
            assert rejected is not None  # counted while feasibility is on
            result.reasons.append(f"level 1: no verified plan was kinematically feasible "
                                  f"(rejected: {rejected['level 1']})")
            return
        best = min(c.error for c in self.checked if c.error is not None)
        alts = sum(c.alternative_of is not None for c in self.checked)
        result.reasons.append(f"level 1: none of the {len(ranked)} symbolic plans verified"
                              + (f" (nor {alts} alternatives through the same symbols)" if alts else "")
                              + f" (best predicted error {best * 100:.1f} cm, "
                                 f"tau {self.cfg.verify.tau_verify * 100:g} cm)")


def verify_candidate(models: Models, X_init, X_goal, candidate: Candidate, cfg: PlanConfig) -> Verification:
    """Verify one candidate alone (its error and verdict recorded on it); the baselines report it."""
    v = verify(models.require_dynamics(), X_init, X_goal, candidate.actions, cfg.verify.tau_verify)
    candidate.error, candidate.verified = v.error, v.verified
    return v


# --- our extensions: the goal's sub-scene, one block at a time ---------------------------------
def level1_scene(X_init: np.ndarray, X_goal: np.ndarray, cfg: PlanConfig) -> tuple[int, ...] | None:
    """The objects Level 1 plans over (our extension, `Level1Config.objects`); None: every object.

    From cfg.level1.focus_from objects on: the objects of the continuous search's pruned actions in X_init
    (`search.goal_oriented_actions`), i.e. the blocks off their goal and, for each, the objects it
    would be placed on. The Symbolic Model then sees a scene of the size it was trained on, and the
    symbols of blocks that play no part cannot make Sigma_goal unreachable; the Dynamics Model
    verifies the plans in the whole scene. With more than cfg.level1.objects, Level 1 plans only one
    block at a time (`level1_serial`)."""
    if cfg.level1.objects is None or not cfg.level1.focused(len(X_init)):
        return None
    actions = goal_oriented_actions(np.asarray(X_init), np.asarray(X_goal), cfg.search.misplaced, cfg.verify.eps,
                                    cfg.search.release_targets)
    return tuple(int(o) for o in np.unique(actions[:, [0, 2]]))


def in_scene(actions, objects: tuple[int, ...] | None) -> tuple[tuple[int, int, int, int], ...]:
    """Actions on a sub-scene's objects (indices into `objects`) as actions on the whole scene."""
    if objects is None:
        return tuple((int(i), int(g), int(j), int(r)) for i, g, j, r in actions)
    return tuple((objects[i], int(g), objects[j], int(r)) for i, g, j, r in actions)


def level1_serial(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
                  feas: Feasibility | None) -> Verification | None:
    """Level 1 one misplaced block at a time (our extension, `Level1Config.serial`).

    Stage by stage, from the state the plan so far is predicted to reach: for the misplaced blocks
    left, lowest goal first (a support before what stands on it), Level 1 plans to put that block at
    its goal and leave the others where they are (its sub-scene: the block and the objects it would
    be placed on, `level1_scene`); the first block with a plan predicted within cfg.verify.eps of that
    sub-goal is the stage's. The plans are joined and verified against X_goal in the whole scene,
    then checked and refined as one. None (with the reason) when a stage places no block or the
    joined plan does not verify. Each stage plans in a scene of two or three objects, where the
    symbols the models learned on 2-4 blocks are reliable, however many objects the whole goal involves."""
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    left = sorted(misplaced_objects(X_init, X_goal, cfg.search.misplaced, cfg.search.eps).tolist(),
                  key=lambda i: (X_goal[i, 2], i))
    if len(left) < 2:
        return None  # one block: the sub-scene plan above was this plan
    X = X_init
    actions: list[tuple[int, int, int, int]] = []
    stages: list[int] = []  # the blocks placed, in order
    while left:
        for block in left:
            sub_goal = X.copy()
            sub_goal[block, :3] = X_goal[block, :3]
            stage = PlanResult(result.method, None)
            v = level1(models, X, sub_goal, cfg, stage, None)
            for key in LEVEL1_STAGES:  # Level 1's time, every stage counted
                result.timings[key] = result.timings.get(key, 0.0) + stage.timings.get(key, 0.0)
            if v is not None and v.error < cfg.verify.eps:
                break
        else:
            result.reasons.append(f"level 1, one block at a time: no plan places any of blocks {left} after "
                                  f"{len(stages)} placed ({stages})")
            result.symbolic_stats["serial"] = {"placed": stages, "left": left}
            return None
        stages.append(block)
        left.remove(block)
        actions += v.actions
        X = v.trajectory[-1]
    t = time.perf_counter()
    whole = verify(models.require_dynamics(), X_init, X_goal, actions, cfg.verify.tau_verify)
    result.timings["verify"] += time.perf_counter() - t
    result.symbolic_stats["serial"] = {"placed": stages, "left": [], "error_m": round(whole.error, 6)}
    result.candidates.append(Candidate(whole.actions, 0, 0.0, whole.error, whole.verified, stages=tuple(stages)))
    if not whole.verified:
        result.reasons.append(f"level 1, one block at a time: the joined plan is predicted {whole.error * 100:.1f} "
                              f"cm from the goal (tau {cfg.verify.tau_verify * 100:g} cm)")
        return None
    chosen = feasible_choice([whole], feas)
    if chosen is None:
        result.reasons.append("level 1, one block at a time: the joined plan is not kinematically feasible")
    return chosen


__all__: Sequence[str] = ["Verifier", "in_scene", "level1", "level1_plans", "level1_scene", "level1_serial",
                          "symbolic_problem", "verify_candidate"]
