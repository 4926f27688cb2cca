"""Operator learning on hand-made bit datasets with known operators; persistence; bad input."""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest

from symbolic import blocksworld as bw
from symbolic.atoms import pack_state, state_atoms, unpack_state
from symbolic.build import build_domain, load_domain
from symbolic.dataset import make_dataset
from symbolic.operators import coverage, filter_operators, from_json, learn_operators, stats, to_json
from symbolic.reference import GroundTask
from symbolic.structs import Effect

# Two blocks, d_z = 1 (u0 = clear), K = 1 (r0(a, b) = a on b). The three scenes:
TABLE = ([[1], [1]], [[[0, 0], [0, 0]]])
ZERO_ON_ONE = ([[1], [0]], [[[0, 1], [0, 0]]])
ONE_ON_ZERO = ([[0], [1]], [[[0, 0], [1, 0]]])
OFFSETS = [(g, r) for g in (-1, 0, 1) for r in (-1, 0, 1)]


def _world(state, action, success: bool):
    """Ground truth: stacking p on t succeeds iff `success`; pick == place unstacks p."""
    u, r = (np.array(x, np.uint8) for x in state)
    p, _, q, _ = action
    u, r = u.copy(), r.copy()
    if p != q and u[p, 0] and u[q, 0] and success:
        r[0, p, q], u[q, 0] = 1, 0
    if p == q and u[p, 0] and r[0, p].any():
        q2 = int(np.flatnonzero(r[0, p])[0])
        r[0, p, q2], u[q2, 0] = 0, 1
    return u, r


def _known_dataset():
    """Every (scene, action) four times; stacking succeeds 3 of 4 times with offset g == 0 and
    1 of 4 times otherwise."""
    rows = []
    for state in (TABLE, ZERO_ON_ONE, ONE_ON_ZERO):
        for p in (0, 1):
            for q in (0, 1):
                for g, r in OFFSETS:
                    wins = 3 if g == 0 else 1
                    for rep in range(4):
                        a = (p, g, q, r)
                        rows.append((state, a, _world(state, a, rep < wins)))
    up = np.array([s[0] for s, _, _ in rows], np.uint8)
    rp = np.array([s[1] for s, _, _ in rows], np.uint8)
    uq = np.array([o[0] for _, _, o in rows])
    rq = np.array([o[1] for _, _, o in rows])
    acts = np.array([a for _, a, _ in rows])
    return make_dataset(up, rp, acts, uq, rq, np.full(len(rows), 2))


STACK = Effect(unary_flips=((1, 0),), rel_flips=((0, 0, 1),))  # r0(p, t) := 1, clear(t) := 0
UNSTACK = Effect(unary_flips=((1, 0),), rel_flips=((0, 0, 1),))  # r0(p, x) := 0, clear(x) := 1
NOOP = Effect()


def _known_operators():
    """(same, g, r, pre_unary, pre_rel) -> {effect: probability}, written out by hand."""
    known = {}
    for g, r in OFFSETS:
        win = Fraction(3, 4) if g == 0 else Fraction(1, 4)
        # pick != place, parameters (?p, ?t)
        known[(False, g, r, ((1,), (1,)), (((0, 0), (0, 0)),))] = {STACK: win, NOOP: 1 - win}
        known[(False, g, r, ((1,), (0,)), (((0, 1), (0, 0)),))] = {NOOP: Fraction(1)}  # p already on t
        known[(False, g, r, ((0,), (1,)), (((0, 0), (1, 0)),))] = {NOOP: Fraction(1)}  # t on p
        # pick == place, parameters (?p, ?x1)
        known[(True, g, r, ((1,), (0,)), (((0, 1), (0, 0)),))] = {UNSTACK: Fraction(1)}  # p on x
        known[(True, g, r, ((1,), (1,)), (((0, 0), (0, 0)),))] = {NOOP: Fraction(1)}
        known[(True, g, r, ((0,), (1,)), (((0, 0), (1, 0)),))] = {NOOP: Fraction(1)}  # x on p
    return known


def _as_table(ops):
    table = {}
    for op in ops.operators:
        key = (op.same, op.grasp, op.release, tuple(map(tuple, op.pre_unary.tolist())),
               tuple(tuple(map(tuple, m)) for m in op.pre_rel.tolist()))
        assert key not in table, f"two operators share the precondition {key}"
        table[key] = {e: Fraction(c, op.count) for e, c in zip(op.effects, op.counts)}
    return table


def test_learned_operators_equal_known_ones():
    ops = learn_operators(_known_dataset())
    assert (ops.n_unary, ops.n_relations) == (1, 1)
    assert len(ops) == 54
    assert all(op.arity == 2 and op.count == 8 for op in ops.operators)
    assert _as_table(ops) == _known_operators()
    for op in ops.operators:  # most frequent effect first; names carry the offsets
        assert op.counts == tuple(sorted(op.counts, reverse=True))
        assert f"_g{ {-1: 'm1', 0: '0', 1: 'p1'}[op.grasp] }_r" in op.name


def test_deterministic_effect_is_the_mode():
    ops = learn_operators(_known_dataset())
    stack_ops = [op for op in ops.operators if not op.same and op.pre_unary.tolist() == [[1], [1]]]
    assert len(stack_ops) == 9
    for op in stack_ops:
        assert op.effects[0] == (STACK if op.grasp == 0 else NOOP)
        np.testing.assert_allclose(op.probabilities, [0.75, 0.25])


def _relabel(data, seed):
    """The same transitions with object identities permuted per transition."""
    rng = np.random.default_rng(seed)
    d = data.subset(np.arange(len(data)))
    for t in range(len(d)):
        n = int(d.n[t])
        perm = rng.permutation(n)  # new object i is old object perm[i]
        inv = np.argsort(perm)
        for arr in (d.unary_pre, d.unary_post):
            arr[t, :n] = arr[t, perm]
        for arr in (d.rel_pre, d.rel_post):
            arr[t, :, :n, :n] = arr[t][:, perm][:, :, perm]
        d.actions[t, 0], d.actions[t, 2] = inv[d.actions[t, 0]], inv[d.actions[t, 2]]
    return d


def test_rare_operators_and_rare_effects_are_filtered():
    data = _known_dataset()
    more = learn_operators(data.subset(np.r_[np.arange(len(data)), np.arange(40)]))  # some seen more often
    counts = sorted({op.count for op in more.operators})
    kept = filter_operators(more, min_count=counts[-1])
    assert len(counts) > 1 and 0 < len(kept) < len(more) and all(op.count >= counts[-1] for op in kept.operators)
    ops = learn_operators(data)
    # stacking succeeds 3 times in 4 at offset 0: a threshold above 0.25 drops the no-op outcome
    sure = filter_operators(ops, min_prob=0.3)
    assert len(sure) == len(ops) and all(len(op.effects) == 1 for op in sure.operators)
    stack = [op for op in sure.operators if not op.same and op.pre_unary.tolist() == [[1], [1]] and op.grasp == 0]
    assert stack and all(op.effects == (STACK,) and op.probabilities.tolist() == [1.0] for op in stack)
    assert len(filter_operators(ops, min_prob=0.2)) == len(ops) and \
        sum(len(op.effects) for op in filter_operators(ops, min_prob=0.2).operators) == \
        sum(len(op.effects) for op in ops.operators)
    with pytest.raises(ValueError, match="min_prob"):
        filter_operators(ops, min_prob=1.5)


def test_lifting_is_invariant_to_object_identities():
    data = bw.random_dataset(1500, (2, 3, 4), seed=3, p_large=0.0)
    a, b = learn_operators(data), learn_operators(_relabel(data, 7))
    ta = {(op.arity,) + k: v for op, (k, v) in zip(a.operators, _as_table(a).items())}
    tb = {(op.arity,) + k: v for op, (k, v) in zip(b.operators, _as_table(b).items())}
    assert ta == tb
    assert len(a) < len(data) / 2  # isomorphic scenes really were merged


def test_json_round_trip_and_versioning(tmp_path):
    ops = learn_operators(bw.random_dataset(600, (2, 3), seed=1))
    doc = json.loads(json.dumps(to_json(ops)))
    back = from_json(doc)
    assert _as_table(back) == _as_table(ops) and [o.name for o in back.operators] == [o.name for o in ops.operators]
    doc["version"] = 99
    with pytest.raises(ValueError, match="version"):
        from_json(doc)


def test_stats_and_coverage():
    ops = learn_operators(_known_dataset())
    s = stats(ops)
    assert s["n_operators"] == 54 and s["n_probabilistic"] == 9
    assert s["effects_per_operator"]["histogram"] == {"1": 45, "2": 9}
    full = coverage(ops, _known_dataset())
    assert full["matched"] == 1.0 and full["effect_predicted"] == 1.0
    # 432 transitions; stacking outcomes that are not the mode: 3 offsets with g == 0 x 2 failures
    # + 6 offsets with g != 0 x 2 successes
    assert full["transitions"] == 432
    assert full["effect_is_mode"] == pytest.approx(1 - 18 / 432)
    held = _known_dataset().subset(np.arange(0, 432, 4))  # every scene/action once, mostly successes
    assert coverage(ops, held)["matched"] == 1.0
    with pytest.raises(ValueError, match="d_z"):
        coverage(ops, bw.random_dataset(50, (3,), seed=0))  # symbols of another model


def test_build_domain_writes_files_and_holdout_coverage(tmp_path):
    data = bw.random_dataset(3000, (2, 3), seed=4)
    report = build_domain(data.unary_pre, data.rel_pre, data.actions, data.unary_post, data.rel_post,
                          data.n, tmp_path, holdout=0.2, seed=0, sampled_domains=5)
    for name in ("domain.pddl", "domain.ppddl", "operators.json", "stats.json"):
        assert (tmp_path / name).stat().st_size > 0
    assert report["train_transitions"] == 2400 and report["coverage_holdout"]["transitions"] == 600
    assert 0.5 < report["coverage_holdout"]["matched"] <= 1.0
    assert report["coverage_holdout"]["effect_predicted"] <= report["coverage_holdout"]["matched"]
    assert report["coverage_train"]["matched"] == 1.0
    assert 1 <= report["sampled_domains"]["distinct"] == len(list((tmp_path / "sampled").glob("*.pddl"))) <= 5
    assert json.loads((tmp_path / "stats.json").read_text())["n_operators"] == len(load_domain(tmp_path))


def test_pack_unpack_and_atoms():
    rng = np.random.default_rng(0)
    u, r = rng.integers(0, 2, (3, 4)), rng.integers(0, 2, (2, 3, 3))
    s = pack_state(u, r)
    assert s < 2 ** (12 + 18)
    uu, rr = unpack_state(s, 3, 4, 2)
    assert np.array_equal(uu, u) and np.array_equal(rr, r)
    atoms = state_atoms([[1, 0]], [[[0]]])
    assert atoms == ["(u0 o0)", "(not-u1 o0)", "(not-r0 o0 o0)"]


@pytest.mark.parametrize("mutate, message", [
    (lambda a: {**a, "unary_pre": a["unary_pre"][:0], "rel_pre": a["rel_pre"][:0], "actions": a["actions"][:0],
                "unary_post": a["unary_post"][:0], "rel_post": a["rel_post"][:0],
                "n_per_transition": a["n_per_transition"][:0]},
     "empty"),
    (lambda a: {**a, "unary_pre": a["unary_pre"][:, :, 0]}, "unary_pre must have shape"),
    (lambda a: {**a, "rel_pre": a["rel_pre"][:, :, :2]}, "rel_pre must have shape"),
    (lambda a: {**a, "unary_post": a["unary_post"][:, :, :1]}, "unary_post shape"),
    (lambda a: {**a, "actions": a["actions"][:, :3]}, "actions must have shape"),
    (lambda a: {**a, "unary_pre": a["unary_pre"] * 2}, "binary"),
    (lambda a: {**a, "n_per_transition": a["n_per_transition"] + 5}, "n_per_transition"),
    (lambda a: {**a, "actions": a["actions"] + np.array([0, 2, 0, 0])}, "grasp_offset"),
    (lambda a: {**a, "actions": np.where(np.arange(4) == 2, 3, a["actions"]),
                "n_per_transition": np.full(len(a["actions"]), 3)},
     "object 3 outside 0..2"),
])
def test_bad_input_gives_clear_value_error(mutate, message):
    data = bw.random_dataset(20, (3, 4), seed=0)
    args = {"unary_pre": data.unary_pre, "rel_pre": data.rel_pre, "actions": data.actions,
            "unary_post": data.unary_post, "rel_post": data.rel_post, "n_per_transition": data.n}
    with pytest.raises(ValueError, match=message):
        make_dataset(**mutate(args))


def test_involved_only_keeps_the_objects_a_transition_involves():
    from symbolic.dataset import restrict_to_involved

    # Two transitions in a 3-object scene (1 unary bit, 1 relation): object 2 changes in the first
    # (a block carried along), nothing besides pick/place is touched in the second.
    U = np.array([[[0], [1], [0]], [[0], [1], [1]]], np.uint8)
    R = np.zeros((2, 1, 3, 3), np.uint8)
    Uq = U.copy()
    Uq[0, 2, 0] = 1
    Rq = R.copy()
    Rq[1, 0, 0, 1] = 1  # picked object 0 now on object 1
    data = make_dataset(U, R, np.array([[0, 0, 1, 0], [0, 0, 1, 0]]), Uq, Rq, np.array([3, 3]))
    small = restrict_to_involved(data)
    assert small.n.tolist() == [3, 2]
    assert small.actions[:, [0, 2]].tolist() == [[0, 1], [0, 1]]
    np.testing.assert_array_equal(small.unary_post[0, :3, 0], [0, 1, 1])
    assert small.rel_post[1, 0, 0, 1] == 1
    # The same involved sub-state in scenes with more bystanders becomes one operator.
    ops = learn_operators(restrict_to_involved(bw.random_dataset(2000, (2, 3), seed=1)))
    full = learn_operators(bw.random_dataset(2000, (2, 3), seed=1))
    assert len(ops) < len(full)
    assert max(op.arity for op in ops.operators) <= max(op.arity for op in full.operators)


def test_build_domain_involved_only_plans_with_fewer_operators(tmp_path):
    data = bw.random_dataset(3000, (2, 3), seed=4)
    args = (data.unary_pre, data.rel_pre, data.actions, data.unary_post, data.rel_post, data.n)
    full = build_domain(*args, tmp_path / "full", holdout=0.2, seed=0)
    small = build_domain(*args, tmp_path / "small", holdout=0.2, seed=0, involved_only=True)
    assert small["involved_only"] and small["n_operators"] < full["n_operators"]
    assert small["coverage_holdout"]["matched"] >= full["coverage_holdout"]["matched"]


def test_domains_keep_to_the_operator_size_the_lifted_search_takes(tmp_path):
    """With 5 and 6 blocks some transitions involve more objects than the lifted search's int64 keys
    hold (4 with the bundled 1 unary bit and 3 relations): no operator is learned from them, by default,
    and a domain built past the limit is refused by the search with a message that says what to do."""
    from symbolic.lifted import LiftedTask, max_arity

    assert max_arity(1, 3) == 4 and max_arity(8, 4) == 2
    assert max_arity(2, 4) == 3 and max_arity(2, 4, given_diagonal=True) == 4
    data = bw.random_dataset(1500, (2, 3, 4, 5), seed=2)
    rel_pre = data.rel_pre.copy()
    rel_pre[0, 0, 0, 0] = 1  # one block "on itself" once: the diagonal is no longer given, it takes key bits
    args = (data.unary_pre, rel_pre, data.actions, data.unary_post, data.rel_post, data.n)
    limit = max_arity(data.n_unary, data.n_relations)
    assert 2 <= limit < 5
    report = build_domain(*args, tmp_path / "default", holdout=0.2, seed=0)
    ops = load_domain(tmp_path / "default")
    assert max(op.arity for op in ops.operators) == limit
    left_out = report["max_arity"]["transitions_left_out"]
    assert report["max_arity"]["limit"] == limit and 0 < left_out < 1500
    assert report["train_transitions"] + left_out == 1200
    assert report["coverage_holdout"]["matched"] < 1.0  # held-out large transitions count as not covered
    LiftedTask(ops, 5)  # takes the scene of 5
    build_domain(*args, tmp_path / "all", holdout=0.2, seed=0, max_arity=5)
    with pytest.raises(ValueError, match=rf"arity 5 .* at most arity {limit} .*--max-arity"):
        LiftedTask(load_domain(tmp_path / "all"), 5)
    with pytest.raises(ValueError, match="at least 1"):
        build_domain(*args, tmp_path / "none", holdout=0.2, seed=0, max_arity=0)


def test_a_diagonal_the_same_in_every_operator_leaves_room_for_larger_operators(tmp_path):
    """No block is on itself: the relations' diagonal is 0 in every transition, so the lifted search
    leaves it out of its keys (as it does for pairwise relations, always 1) and arity 5 fits where it did
    not; the successors are still exactly the grounded ones. An operator that reads a diagonal bit
    otherwise makes the diagonal part of the key again, and the domain is refused."""
    from symbolic.lifted import LiftedTask, max_arity

    data = bw.random_dataset(1500, (2, 3, 4, 5), seed=2)
    args = (data.unary_pre, data.rel_pre, data.actions, data.unary_post, data.rel_post, data.n)
    report = build_domain(*args, tmp_path / "all", holdout=0.2, seed=0)
    limit = max_arity(data.n_unary, data.n_relations)
    assert report["max_arity"] == {"limit": max_arity(data.n_unary, data.n_relations, given_diagonal=True),
                                   "transitions_left_out": 0}
    every = load_domain(tmp_path / "all")
    assert max(op.arity for op in every.operators) == 5 > limit
    _check_lifted_against_grounded(every, 5)
    odd = next(op for op in every.operators if op.arity == 5)
    odd.pre_rel[0, 0, 0] = 1
    with pytest.raises(ValueError, match=rf"arity 5 .* at most arity {limit} .*--max-arity"):
        LiftedTask(every, 5)


def test_with_core_from_all_the_operator_of_the_picked_and_target_objects_learns_from_every_transition(tmp_path):
    """One action in 3-object scenes, u0 = on the table: 2 transitions put the picked block on the target,
    5 do that and also lift the third block, 3 change nothing. Restricted to the objects involved, the
    picked-target operator sees only the 5 that changed no third object and expects nothing (3 of 5); with
    core_from_all it sees all 10 and expects the block to leave the table (7 of 10). The bystander operator
    is the same either way."""
    table = np.ones((3, 1), np.uint8)
    lifted = table.copy()
    lifted[0] = 0
    both = lifted.copy()
    both[2] = 0
    after = [lifted] * 2 + [both] * 5 + [table] * 3
    rel = np.zeros((10, 1, 3, 3), np.uint8)
    args = (np.repeat(table[None], 10, 0), rel, np.array([(0, 0, 1, 0)] * 10), np.stack(after), rel, np.full(10, 3))

    def by_arity(out):
        build_domain(*args, out, holdout=0.0, involved_only=True, core_from_all=out.name == "core")
        ops = load_domain(out)
        return {op.arity: op for op in ops.operators}

    plain, core = by_arity(tmp_path / "plain"), by_arity(tmp_path / "core")
    assert plain[2].count == 5 and core[2].count == 10
    assert plain[2].effects[0].unary_flips == () and float(plain[2].probabilities[0]) == pytest.approx(0.6)
    assert core[2].effects[0].unary_flips == ((0, 0),) and float(core[2].probabilities[0]) == pytest.approx(0.7)
    assert plain[3].count == core[3].count == 5 and plain[3].effects == core[3].effects
    with pytest.raises(ValueError, match="involved_only"):
        build_domain(*args, tmp_path / "x", holdout=0.0, core_from_all=True)


def _beside_dataset():
    """3-object scenes, u0 = far half, u1 = on the table, r0(a, b) = a beside b. Object 2 stands beside
    object 1; the action puts object 0 on object 1, which makes it beside object 2 as well. Object 2
    stands in the near half in every transition (u0 = 0). A last transition knocks object 2 over
    (its u1 changes): it keeps a full operator."""
    u = np.array([[0, 1], [0, 1], [0, 1]], np.uint8)
    r = np.zeros((1, 3, 3), np.uint8)
    r[0, 1, 2] = r[0, 2, 1] = 1
    uq, rq = u.copy(), r.copy()
    uq[0, 1] = 0
    rq[0, 0, 2] = rq[0, 2, 0] = 1
    knocked = uq.copy()
    knocked[2, 1] = 0
    rows = [(u, r, uq, rq)] * 6 + [(u, r, knocked, rq)]
    return make_dataset(*(np.stack([row[i] for row in rows]) for i in (0, 1)), np.array([(0, 0, 1, 0)] * len(rows)),
                        *(np.stack([row[i] for row in rows]) for i in (2, 3)), np.full(len(rows), 3))


def test_general_bystander_operators_cover_where_a_bystander_stands_unseen(tmp_path):
    """A bystander in the far half (u0 = 1) was never seen; what the step does to it depends only on
    its relations to the moved blocks, so the general operator applies and predicts it, in the lifted
    search, the grounded reference, the PDDL, the JSON file and the held-out coverage."""
    from symbolic.lifted import LiftedTask
    from symbolic.pddl import DomainWriter

    data = _beside_dataset()
    full, general = learn_operators(data), learn_operators(data, general_bystanders=True)
    assert len(full) == 1 and not full.operators[0].is_general and full.operators[0].counts == (6, 1)
    assert sorted(op.is_general for op in general.operators) == [False, True]
    op = next(op for op in general.operators if op.is_general)
    assert op.count == 6 and op.known_unary.tolist() == [[True, True], [True, True], [False, False]]
    assert op.known_rel[0, 2, 2]  # the diagonal stays tested
    assert op.known_rel[0, 0, 2] and op.known_rel[0, 2, 1]  # relations to the moved blocks are tested
    knocked = next(op for op in general.operators if not op.is_general)
    assert knocked.count == 1 and knocked.pre_unary[2].tolist() == [0, 1]

    far = data.subset(np.arange(6))
    far.unary_pre[:, 2, 0] = far.unary_post[:, 2, 0] = 1  # the bystander stands in the far half
    state = pack_state(far.unary_pre[0, :3], far.rel_pre[0, :, :3, :3])
    after = pack_state(far.unary_post[0, :3], far.rel_post[0, :, :3, :3])
    assert after not in LiftedTask(full, 3).expand(state).successors
    task, ground = LiftedTask(general, 3), GroundTask(general, 3)
    assert after in task.expand(state).successors
    gs = ground.applicable(state)
    assert task.expand(state).successors == list(dict.fromkeys(state ^ f for g in gs for f in ground.flips[g]))
    assert coverage(full, far)["matched"] == 0.0
    assert coverage(general, far) == {"transitions": 6, "matched": 1.0, "effect_predicted": 1.0, "effect_is_mode": 1.0}

    head = DomainWriter(general)._render_head(op)
    assert "u0 ?x1)" not in head and "u1 ?x1)" not in head and "(r0 ?t ?x1)" in head and "(u1 ?t)" in head
    back = from_json(json.loads(json.dumps(to_json(general))))
    assert [(o.is_general, o.known_bits().tolist()) for o in back.operators] == \
        [(o.is_general, o.known_bits().tolist()) for o in general.operators]


def test_general_bystander_domains_give_the_grounded_successors(tmp_path):
    """On a blocks world of 2-5 blocks (a bystander's own bits change when a block is taken off it),
    the lifted search's successors and ground actions equal the grounded reference's, and the general
    domain has fewer operators than the full one and covers more held-out transitions."""
    data = bw.random_dataset(2500, (2, 3, 4, 5), seed=3)
    args = (data.unary_pre, data.rel_pre, data.actions, data.unary_post, data.rel_post, data.n)
    full = build_domain(*args, tmp_path / "full", holdout=0.2, seed=0, involved_only=True)
    report = build_domain(*args, tmp_path / "general", holdout=0.2, seed=0, involved_only=True,
                          general_bystanders=True)
    assert report["general_bystanders"] and 0 < report["n_general"] < report["n_operators"] < full["n_operators"]
    assert report["coverage_holdout"]["matched"] >= full["coverage_holdout"]["matched"]
    ops = load_domain(tmp_path / "general")
    _check_lifted_against_grounded(ops, 5)


def _check_lifted_against_grounded(ops, n: int) -> None:
    """On the initial and goal states of random n-block problems, the lifted task's successors and
    ground actions (in ground-action order) are the grounded reference's."""
    from symbolic.lifted import LiftedTask

    task, ground = LiftedTask(ops, n), GroundTask(ops, n)
    for seed in range(6):
        problem = bw.random_problem(n, 3, seed=seed)[0]
        for s in (pack_state(problem.init_unary, problem.init_rel), pack_state(problem.goal_unary, problem.goal_rel)):
            gs = ground.applicable(s)
            assert task.expand(s).successors == list(dict.fromkeys(s ^ f for g in gs for f in ground.flips[g]))
            assert task.applicable(s) == [task.n_tuples * ground.op_index[g]
                                          + _tuple(task, ground.op_index[g], ground.binding[g]) for g in gs]


def _tuple(task, operator: int, binding: tuple) -> int:
    """The lifted task's tuple index of a binding, in the tuples of the operator's group."""
    op = task.ops.operators[operator]
    group = next(g for g, (a, known) in enumerate(task.groups)
                 if a == op.arity and known.tolist() == op.known_bits().tolist())
    return next(i for i, t in enumerate(task.tuples) if t == binding and task._tuple_tag[i] == group)
