"""Written PDDL is accepted by Fast Downward's translator; PPDDL parses with the right
probabilities; domain sampling is reproducible and deduplicated."""

from __future__ import annotations

import numpy as np
import pytest

from symbolic import blocksworld as bw
from symbolic import fast_downward as fd
from symbolic.operators import learn_operators
from symbolic.pddl import DomainWriter, problem_pddl, write_domains
from symbolic.ppddl_parser import parse_domain
from symbolic.sampling import dedup_choices, sample_choices, write_sampled_domains


@pytest.fixture(scope="module")
def ops():
    return learn_operators(bw.random_dataset(800, (2, 3), seed=11, p_large=0.2))


@pytest.fixture(scope="module")
def problem():
    return bw.random_problem(3, 2, seed=1, p_large=0.2)[0]


@pytest.mark.slow
def test_every_written_pddl_is_accepted_by_the_translator(ops, problem, tmp_path):
    paths = write_domains(ops, tmp_path)
    sampled = write_sampled_domains(ops, tmp_path / "sampled", n_domains=6, seed=0)
    prob = problem_pddl(ops, problem)
    texts = [paths["pddl"].read_text(), DomainWriter(ops).union()] + [p.read_text() for p, _ in sampled[:2]]
    for text in texts:
        sas = fd.translate(text, prob)
        task = fd.SasTask(sas)
        assert task.names, "translation kept no operator"
        assert all(line.split()[0].split("__e")[0] in ops.by_name() for line in task.names)


def test_translator_rejects_broken_pddl(ops, problem):
    broken = DomainWriter(ops).pddl().replace("(:predicates", "(:predicates (u0 ?o ?p)", 1)
    with pytest.raises(fd.PlannerCrashed, match="exit code"):
        fd.translate(broken, problem_pddl(ops, problem))


def test_ppddl_parses_with_the_learned_probabilities(ops, tmp_path):
    text = write_domains(ops, tmp_path)["ppddl"].read_text()
    dom = parse_domain(text)
    assert ":probabilistic-effects" in dom.requirements
    assert len(dom.actions) == len(ops)
    assert dom.predicates == {"u0": 1, "not-u0": 1, "u1": 1, "not-u1": 1, "u2": 1, "not-u2": 1,
                              "r0": 2, "not-r0": 2, "r1": 2, "not-r1": 2}
    for act, op in zip(dom.actions, ops.operators):
        assert act.name == op.name and len(act.parameters) == op.arity
        assert len(act.precondition) == op.arity * (op.arity - 1) // 2 + op.arity * 3 + 2 * op.arity ** 2
        probs = [p for p, _ in act.outcomes]
        np.testing.assert_allclose(probs, op.probabilities, atol=1e-6)
        for (_, lits), e in zip(act.outcomes, op.effects):
            assert len(lits) == 2 * (len(e.unary_flips) + len(e.rel_flips))
    assert any(len(a.outcomes) > 1 for a in dom.actions)
    # the deterministic domain parses too and keeps the most frequent effect
    det = parse_domain(DomainWriter(ops).pddl())
    assert all(len(a.outcomes) == 1 for a in det.actions)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("(probabilistic 0.", "(probabilistic 0.9", 1), "sum to"),
    (lambda t: t.replace("(u0 ?p)", "(u7 ?p)", 1), "undeclared predicate"),
    (lambda t: t.replace("(u0 ?p)", "(u0 ?q)", 1), "not a parameter"),
    (lambda t: t.replace(" :probabilistic-effects", "", 1), "without :probabilistic-effects"),
    (lambda t: t[:-3], "unbalanced"),
])
def test_ppddl_validator_rejects_bad_domains(ops, edit, message):
    text = DomainWriter(ops).ppddl()
    with pytest.raises(ValueError, match=message):
        parse_domain(edit(text))


def test_min_prob_drops_rare_effects(ops):
    dom = parse_domain(DomainWriter(ops).ppddl(min_prob=0.3))
    for act, op in zip(dom.actions, ops.operators):
        kept = op.probabilities[op.probabilities >= 0.3]
        kept = kept if op.probabilities[0] >= 0.3 else np.concatenate([[op.probabilities[0]], kept])
        assert len(act.outcomes) == len(kept)


def test_sampling_is_reproducible_and_follows_probabilities(ops):
    a, b = sample_choices(ops, 400, seed=5), sample_choices(ops, 400, seed=5)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, sample_choices(ops, 400, seed=6))
    assert np.array_equal(a[:50], sample_choices(ops, 50, seed=5))  # domain k does not depend on N
    det = [i for i, op in enumerate(ops.operators) if not op.is_probabilistic]
    assert (a[:, det] == 0).all()
    i = max(range(len(ops)), key=lambda j: (len(ops.operators[j].effects) > 1) * ops.operators[j].count)
    freq = np.bincount(sample_choices(ops, 4000, seed=1)[:, i], minlength=len(ops.operators[i].effects)) / 4000
    np.testing.assert_allclose(freq, ops.operators[i].probabilities, atol=0.03)


def test_dedup_counts_identical_domains():
    choices = np.array([[0, 1, 0], [0, 1, 1], [0, 1, 0], [1, 0, 0], [0, 1, 1]])
    reps, counts, group = dedup_choices(choices)
    assert reps.tolist() == [0, 1, 3] and counts.tolist() == [2, 2, 1]
    assert group.tolist() == [0, 1, 0, 2, 1]
    reps, counts, _ = dedup_choices(choices, np.array([0, 1]))
    assert reps.tolist() == [0, 3] and counts.tolist() == [4, 1]


def test_sampled_domain_files_are_deduplicated(ops, tmp_path):
    written = write_sampled_domains(ops, tmp_path, n_domains=30, seed=2)
    assert sum(c for _, c in written) == 30
    texts = [p.read_text() for p, _ in written]
    assert len(set(texts)) == len(texts)
    again = write_sampled_domains(ops, tmp_path / "again", n_domains=30, seed=2)
    assert [p.read_text() for p, _ in again] == texts


def test_an_independent_parser_reads_our_domains_and_problems(ops, problem, tmp_path):
    """The PyPI `pddl` parser (not ours, not Fast Downward's) accepts domain.pddl, a sampled domain and
    the problem file, with every action and object. (It does not read PPDDL's probabilistic effects;
    domain.ppddl is checked by `symbolic.ppddl_parser` above.)"""
    import pddl

    paths = write_domains(ops, tmp_path)
    sampled = write_sampled_domains(ops, tmp_path / "sampled", n_domains=4, seed=3)
    (tmp_path / "problem.pddl").write_text(problem_pddl(ops, problem))
    for path in (paths["pddl"], sampled[-1][0]):
        domain = pddl.parse_domain(path)
        assert {a.name for a in domain.actions} == {op.name for op in ops.operators}
    parsed = pddl.parse_problem(tmp_path / "problem.pddl")
    assert {o.name for o in parsed.objects} == set(problem.objects)
    assert len(parsed.goal.operands) == problem.init_unary.size + problem.init_rel.size  # one atom per bit


def test_problem_names_are_valid_pddl_names():
    from symbolic.pddl import pddl_name

    assert pddl_name("problem") != "problem" and pddl_name("domain") != "domain"
    assert pddl_name("n4-k3-007") == "n4-k3-007"
    assert pddl_name("3 blocks/odd") == "symbolic-task-3-blocks-odd"
    assert pddl_name("") == "symbolic-task"
