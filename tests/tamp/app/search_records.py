"""Synthetic search records (`tamp plan --search`'s format, version 1) for the search view's tests and bench:
a closed loop of rounds, Level 1 candidates, a Level 2 tree of any size and a refinement, in a 3-block world."""
from __future__ import annotations

import random
from typing import Any

X_INIT = [[0.55, -0.20, 0.025, 1, 0], [0.60, 0.10, 0.025, 0, 1], [0.45, 0.25, 0.025, 1, 0]]
X_GOAL = [[0.60, 0.175, 0.075, 1, 0], [0.60, 0.10, 0.025, 0, 1], [0.60, 0.025, 0.075, 1, 0]]
REASONS = ("no grasp", "IK", "collision", "<i>blocked</i> & \"quoted\"")  # the last tests escaping


def _scene(rng: random.Random, near: list[list[float]]) -> list[list[float]]:
    return [[round(x + rng.uniform(-0.03, 0.03), 4), round(y + rng.uniform(-0.03, 0.03), 4), z]
            for x, y, z, *_ in near]


def level2_tree(n_nodes: int, seed: int = 0) -> dict[str, Any]:
    """A Level 2 search of `n_nodes` nodes: expanded best-first (about a third of them), every expansion generating
    a few successors, a quarter of which are rejected with a reason; the path runs to the deepest expanded node."""
    rng = random.Random(seed)
    nodes = [{"id": 0, "parent": None, "order": 0, "action": None, "g": 0.0, "h": 3.0, "X": _scene(rng, X_INIT),
              "verdict": "ok", "reason": None}]
    frontier, order = [0], 1
    while len(nodes) < n_nodes and frontier:
        parent = frontier.pop(rng.randrange(len(frontier))) if order > 1 else frontier.pop()
        if nodes[parent]["order"] is None:
            nodes[parent]["order"] = order
            order += 1
        for _ in range(min(4, n_nodes - len(nodes))):
            bad = rng.random() < 0.25
            reason = rng.choice(REASONS) if bad else None
            node = {"id": len(nodes), "parent": parent, "order": None,
                    "action": [rng.randrange(3), rng.choice((-1, 0, 1)), rng.randrange(3), rng.choice((-1, 0, 1))],
                    "g": round(nodes[parent]["g"] + 1.0, 3), "h": round(rng.uniform(0, 3), 3),
                    "X": _scene(rng, X_GOAL if rng.random() < 0.5 else X_INIT),
                    "verdict": reason or "ok", "reason": f"{reason} at the place pose" if bad else None}
            nodes.append(node)
            if not bad:
                frontier.append(node["id"])
    path, node = [], max((n for n in nodes if n["order"] is not None), key=lambda n: (n["g"], n["order"]))
    while node is not None:
        path.append(node["id"])
        node = nodes[node["parent"]] if node["parent"] is not None else None
    return {"status": "found", "expanded": order, "generated": len(nodes), "truncated": False, "nodes": nodes,
            "path": path[::-1]}


def _candidate(rank: int, actions: list[list[int]], verified: bool, chosen: bool, verdicts: list[str]) -> dict:
    states = [X_INIT] + [X_GOAL] * len(actions)
    return {"rank": rank, "actions": actions, "count": 12 - 3 * rank, "probability": round(0.8 / rank, 3),
            "error_m": 0.004 if verified else 0.06, "verified": verified, "chosen": chosen,
            "facts": [["u1(o0)", "o1 large"]] + [["o0 elevated", "o0 above o1"]] * len(actions),
            "predicted": [[x[:3] for x in s] for s in states], "kinematics": [{"verdict": v} for v in verdicts]}


def search_record(n_nodes: int = 40, rounds: int = 2, replay: str | None = None) -> dict[str, Any]:
    """A record of `rounds` closed-loop rounds: round 0 Level 1 fails to verify and Level 2 (`n_nodes` nodes)
    finds the plan; the later rounds keep it on course. Each round executes one step that misses by 1-4 cm."""
    plan = [[0, 0, 1, 1], [2, 0, 1, -1]]
    record: dict[str, Any] = {
        "format": "tamp-search-record", "version": 1,
        "config": {"method": "cfs", "n_domains": 12, "max_expansions": 1500},
        "problem": {"name": "synthetic-3 <b>&</script>", "X_init": X_INIT, "X_goal": X_GOAL},
        "symbols": {"names": {"u1": "o elevated", "u0": "o in the far half"}},
        "rounds": [],
    }
    for k in range(rounds):
        first = k == 0
        tree = level2_tree(n_nodes, seed=k) if first else None
        candidates = [_candidate(1, plan, verified=not first, chosen=not first, verdicts=["ok", "ok"]),
                      _candidate(2, [[0, 1, 2, 0]], verified=False, chosen=False, verdicts=["IK"])]
        record["rounds"].append({
            "index": k, "X_observed": X_INIT, "origin": "planned" if first else "kept on course",
            "why": "the first round plans" if first else "the scene matched the prediction",
            "method": "cfs", "level": 2 if first else 1, "plan": plan, "timings_s": {"level1": 0.8, "level2": 2.1},
            "reasons": ["no Level 1 candidate verified"] if first else [],
            "level1": {"candidates": candidates, "stats": {"domains": 12, "plans": 2}},
            "level2": tree,
            "refinements": [{"level": 2 if first else 1, "plan": plan, "outcome": "ok", "actions": [
                {"ik_branch": "elbow up, wrist down", "planner": "direct", "time_s": 0.08, "failure": None},
                {"ik_branch": "elbow up, wrist down", "planner": "rrtconnect", "time_s": 0.41, "failure": None}]}],
            "executed": {"action": plan[0], "predicted": [x[:3] for x in X_GOAL],
                         "observed": [[x[0] + 0.01 * (k + 1), x[1], x[2]] for x in X_GOAL], "miss_m": 0.01 * (k + 1)},
        })
    if replay is not None:
        record["replay"] = replay
    return record

