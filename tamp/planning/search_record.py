"""The search record: what a planning call considered, as JSON-ready data (docs/search-record.md).

One round per planning call (a closed loop's round, or the one call of an open loop), built by `round_record`
from its `PlanResult` and what its `Recorder` collected (`tamp.planning.search_trace`): Level 1's ranked
candidates (facts along each, rollout, verdict, kinematic verdict per action, the chosen one marked), the
continuous search's tree (`tree_record`), each full refinement with its motions. Positions are metres rounded
to 1 mm. A tree is bounded (`MAX_TREE_BYTES`): the expanded nodes, the path and the successors left out are kept,
then the generated nodes that were never expanded, closest to the goal first, while they fit; `truncated` says
when some were left out. The file around the rounds (format, version, configuration, problem, symbols) and its
schema are `tamp.app.search_record`'s.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from tamp.planning.results import Candidate, PlanResult
from tamp.planning.search_trace import Recorder, Tree

if TYPE_CHECKING:  # `learned` loads torch: a reader of record files does without it
    from learned.interpret import BitNames

FORMAT, VERSION = "tamp-search-record", 1
MAX_TREE_BYTES = 1_800_000  # a tree's nodes in JSON: a search of 1,500 expansions stays under 2 MB with the rest
NODE_BYTES, POSITION_BYTES = 120, 24  # estimated JSON bytes of a node without its scene, and per block of a scene
REFINED_REASON = "the kinematic check rejected its action when the search took it from the frontier"

Facts = Callable[[Candidate], list[list[str]]]  # the facts along a candidate's symbolic states


def mm(P: np.ndarray) -> list:
    """Positions (..., 3) in metres rounded to 1 mm, as lists."""
    return np.round(np.asarray(P, dtype=float), 3).tolist()


def _round(x: float | None, digits: int = 4) -> float | None:
    return None if x is None or not np.isfinite(x) else round(float(x), digits)


def facts_reader(n_unary: int, n_relations: int, names: BitNames, n: int) -> Facts:
    """The facts (as `tamp symbols` names the bits) of each packed symbolic state of a candidate in a scene of
    `n` objects (or its sub-scene `Candidate.objects`)."""
    from symbolic.atoms import unpack_state
    from tamp.planning.steps import Symbols, named_facts

    def facts(candidate: Candidate) -> list[list[str]]:
        if candidate.states is None:
            return []
        m = n if candidate.objects is None else len(candidate.objects)
        return [list(dict.fromkeys(named_facts(Symbols.of(*unpack_state(s, m, n_unary, n_relations)), names,
                                               candidate.objects)))  # two bits may name one fact
                for s in candidate.states]
    return facts


def candidate_record(rank: int, c: Candidate, chosen: bool, facts: Facts | None,
                     predicted: np.ndarray | None = None) -> dict:
    """One Level-1 candidate; `predicted`: its rollout when the candidate did not keep one (a kept plan's)."""
    rollout = c.predicted if c.predicted is not None else predicted
    verdicts = c.kinematics or ("unchecked",) * len(c.actions)
    return {"rank": rank, "actions": [list(a) for a in c.actions], "count": int(c.count),
            "probability": round(float(c.probability), 4), "error_m": _round(c.error), "verified": c.verified,
            "chosen": chosen, "facts": [] if facts is None else facts(c),
            "predicted": None if rollout is None else mm(rollout[:, :, :3]),
            "kinematics": [{"verdict": v} for v in verdicts],
            "stages": None if c.stages is None else list(c.stages)}


def level1_record(result: PlanResult, facts: Facts | None) -> dict:
    plan = None if result.plan is None else [tuple(int(v) for v in a) for a in result.plan]
    chosen = [result.level == 1 and plan == list(c.actions) for c in result.candidates]
    return {"candidates": [candidate_record(i + 1, c, chosen[i], facts, result.predicted if chosen[i] else None)
                           for i, c in enumerate(result.candidates)],
            "stats": result.symbolic_stats}


def tree_record(tree: Tree, searches: int, result: PlanResult, max_bytes: int = MAX_TREE_BYTES) -> dict:
    """The continuous search's tree (see the module docstring): nodes with id, parent, expansion order, action,
    g, h, predicted positions (None for the successors left out), verdict and reason."""
    nodes, left_out = tree.nodes, tree.left_out
    P = np.stack([node[0] for node in nodes] + [out[4] for out in left_out])
    h = tree.heuristic(P, np.linalg.norm(P - tree.goal[None], axis=2)).round(4)
    order = {index: k for k, index in enumerate(tree.order)}
    kept, truncated = _bounded(nodes, h, {*order, *tree.path, *tree.closest, *tree.verdicts}, len(left_out),
                               P.shape[1], max_bytes)
    hs, Xs = h[kept].tolist(), np.round(P[kept], 3).tolist()  # at once: per node, numpy's calls cost more
    rows: list[dict] = []
    for i, h_i, X_i in zip(kept, hs, Xs):
        if i >= len(nodes):
            parent, action, verdict, reason, _ = left_out[i - len(nodes)]
            rows.append({"id": i, "parent": parent, "order": None, "action": list(action), "g": nodes[parent][3] + 1,
                         "h": h_i, "X": None, "verdict": verdict, "reason": reason})
            continue
        _, parent, action, g = nodes[i]
        verdict = tree.verdicts.get(i, "ok")
        rows.append({"id": i, "parent": None if parent < 0 else parent, "order": order.get(i),
                     "action": None if action is None else list(action), "g": g, "h": h_i, "X": X_i,
                     "verdict": verdict, "reason": None if verdict == "ok" else REFINED_REASON})
        if i in tree.duplicates:
            rows[-1]["duplicates"] = tree.duplicates[i]
    search = result.search
    return {"status": str(search.status) if search is not None else "unknown",
            "reason": search.reason if search is not None else "",
            "expanded": len(tree.order), "generated": tree.generated, "truncated": truncated,
            "searches": searches, "omitted": len(nodes) + len(left_out) - len(rows), "nodes": rows,
            "path": list(tree.path), "closest": list(tree.closest)}


def _bounded(nodes: list, h: np.ndarray, first: set[int], left_out: int, n: int, max_bytes: int
             ) -> tuple[list[int], bool]:
    """The ids of the nodes to record within about `max_bytes` of JSON: `first` (expanded, on the path, rejected)
    and the `left_out` successors after the nodes, then the nodes never expanded, least h first; whether any
    were left out."""
    scene = NODE_BYTES + POSITION_BYTES * n
    keep = first | set(range(len(nodes), len(nodes) + left_out))
    room = (max_bytes - scene * len(first) - NODE_BYTES * left_out) // scene
    never = np.ones(len(nodes), dtype=bool)
    never[[i for i in first if i < len(nodes)]] = False
    rest = np.flatnonzero(never)
    if len(rest) > room:
        rest = rest[np.argsort(h[rest], kind="stable")[:max(room, 0)]]
    keep.update(rest.tolist())
    return sorted(keep), len(keep) < len(nodes) + left_out


def why_record(result: PlanResult) -> str:
    """Why the round's plan is the one it has (or why it has none), in one line."""
    said = ("kept the rest", "searched again over every action", "toward the closest state")
    for reason in reversed(result.reasons):
        if reason.startswith(said):
            return reason
    if not result.solved:
        return "no plan: " + ("; ".join(result.reasons) or "the planner found none")
    if result.level == 1:
        return "level 1: the most frequent symbolic plan that verified" + \
            ("" if result.rejected is None else ", passed the kinematic check and refined")
    return "level 2: the continuous search's plan" + ("" if result.rejected is None else ", refined")


def refinement_record(x: dict) -> dict:
    failed = x.get("failed_action")
    outcome = "refined" if failed is None else f"failed at action {failed} ({x.get('reason')}: {x.get('message')})"
    return {"level": x["level"], "plan": x["plan"], "outcome": outcome, "failed_action": failed,
            "actions": list(x.get("actions", []))}


def round_record(index: int, result: PlanResult, recorder: Recorder | None, X_observed: np.ndarray,
                 facts: Facts | None = None, max_tree_bytes: int = MAX_TREE_BYTES) -> dict:
    """One planning call's round of the record (`executed` filled by the caller once the loop acts)."""
    tree = None if recorder is None else recorder.tree
    return {"index": index, "X_observed": np.round(np.asarray(X_observed, dtype=float), 4).tolist(),
            "origin": result.origin, "why": why_record(result), "method": result.method, "level": result.level,
            "plan": None if result.plan is None else [list(map(int, a)) for a in result.plan],
            "predicted_error_m": _round(result.predicted_error),
            "timings_s": {k: round(v, 4) for k, v in result.timings.items()}, "reasons": list(result.reasons),
            "level1": level1_record(result, facts),
            "level2": None if tree is None or recorder is None else
            tree_record(tree, recorder.searches, result, max_tree_bytes),
            "rejected": result.rejected_dict(),
            "refinements": [refinement_record(x) for x in result.refinements], "executed": None}


def executed_record(result: PlanResult, action, X_after: np.ndarray) -> dict | None:
    """What a round's executed first action did against its plan's prediction (None: no prediction of it)."""
    action = [int(v) for v in action]
    if result.predicted is None or len(result.predicted) < 2 or not result.plan or list(result.plan[0]) != action:
        return None
    predicted, observed = result.predicted[1][:, :3], np.asarray(X_after, dtype=float)[:, :3]
    return {"action": action, "predicted": mm(predicted), "observed": mm(observed),
            "miss_m": round(float(np.linalg.norm(predicted - observed, axis=1).max(initial=0.0)), 4)}


def symbol_names(names: BitNames) -> dict[str, str]:
    """Each named bit and what its value 1 means, as `tamp symbols` names it."""
    return {bit: ("not " + fact if negated else fact) for bit, (fact, negated) in names.facts.items()}


__all__: Sequence[str] = ["FORMAT", "MAX_TREE_BYTES", "VERSION", "executed_record", "facts_reader", "mm",
                          "round_record", "symbol_names", "tree_record"]
