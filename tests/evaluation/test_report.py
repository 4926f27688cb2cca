"""The evaluation report: every number in report.md recomputed from the rows, degraded sections, bad input.

The tables of report.md are parsed back (a small Markdown parser below) and each cell is compared
with a value recomputed here from the JSONL rows with plain numpy/scipy, so a wrong aggregation,
pairing or formatting fails.
"""
import json
import random
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import ttest_rel

from evaluation.report import write_report
from learned.interpret import interpret_symbols

METHODS = ("deterministic", "probabilistic", "probabilistic_oracle", "cfs", "bilevel", "bilevel_alg1", "bilevel_replan",
           "symbolic_sigmoid", "cfs_gumbel")
OUTCOMES = ("success", "no_plan", "kinematic_failure", "refinement_failure", "wrong_plan")


# --- synthetic rows ------------------------------------------------------------------------------
def make_rows(methods=METHODS, per_cell=4, seed=3):
    """Rows of the runner's schema with plans, no plans, empty plans, refinement failures and wrong
    plans; problems i of a cell belong to run i % 2 (paper protocol, a random count of moving actions)."""
    rng = random.Random(seed)
    rows = []
    for n in (2, 3, 4):
        for k in (1, 2, 3, 4, 5):
            for i in range(per_cell):
                name = f"n{n}-k{k}-{i:03d}"
                moved = rng.randint(0, k)
                for m in methods:
                    solved = rng.random() < 0.8
                    failure = None
                    if solved and rng.random() < 0.2:
                        failure = {"action": 0, "stage": rng.choice(["ik", "motion", "grasp"]), "where": "grasp",
                                   "reason": "no IK solution"}
                    final = rng.uniform(0.0, 0.1)
                    success = solved and failure is None and final < 0.05
                    outcome = ("no_plan" if not solved else "success" if success else "wrong_plan" if not failure
                               else "kinematic_failure" if failure["stage"] == "ik" else "refinement_failure")
                    empty = solved and m == "probabilistic" and k == 1 and i % 2 == 0
                    rows.append({
                        "problem": name, "n": n, "k": k, "run": i % 2, "protocol": "paper", "moved": moved,
                        "method": m, "solved": solved,
                        "level": rng.choice([1, 2]) if solved and m.startswith("bilevel") else None,
                        "plan": ([] if empty else [[0, 0, 1, 0]] * k) if solved else None,
                        "executed_plans": rng.randint(1, 5) if solved and m == "probabilistic_oracle" else int(solved),
                        "symbolic_backend": None if m.startswith("cfs") else "fd",
                        "planning_time_s": rng.uniform(0.001, 2.0), "level1_time_s": 0.004,
                        "level1_stages_s": {"symbols": rng.uniform(0, 0.002), "symbolic": rng.uniform(0, 0.01),
                                            "verify": rng.uniform(0, 0.01)} if m.startswith("bilevel") else None,
                        "predicted_error_m": rng.uniform(0.0, 0.16) if solved else None,
                        "candidates": [], "refined": None if not solved else failure is None,
                        "refine_failure": failure,
                        "refine_time_s": [rng.uniform(0.05, 0.3) for _ in range(k if failure is None else 1)]
                        if solved else [],
                        "executed_actions": k if solved and failure is None else 0,
                        "final_error_m": final, "success": success, "outcome": outcome,
                        "rounds": k - 1 if m == "bilevel_replan" else None,
                        "effect_error_m": [rng.uniform(0.0, 0.03) for _ in range(k)]
                        if solved and failure is None else [],
                        "fidelity": "fast", "eps_m": 0.05, "tau_verify_m": 0.07})
                    r = rows[-1]
                    ran = r["executed_actions"]
                    r["steps"] = None if m.startswith("cfs_") or not solved else [
                        {"operator": f"op{rng.randint(0, 5)}" if rng.random() < 0.95 else None,
                         "probability": 0.5, "on_plan": (r["level"] == 1) if r["level"] else None, "kinematic": "ok",
                         "refined": j < ran, "match": (rng.random() < 0.6) if j < ran else None,
                         "mismatched_bits": 0, "allowed": True if j < ran else None, "error_m": 0.01}
                        for j in range(max(ran, 1 if failure else 0))]
                    for step in r["steps"] or []:
                        if step["operator"] is None:
                            step["match"] = None
                    r["predictions"] = [{"class": rng.choice(["cube on a cube", "bar beside a cube"]),
                                         "miss_m": rng.uniform(0.0, 0.08), "bound_m": rng.uniform(0.01, 0.05),
                                         "epistemic_m": 0.005, "aleatoric_m": 0.01} for _ in range(ran)]
    for r in rows:
        if r["level1_stages_s"]:
            r["level1_time_s"] = sum(r["level1_stages_s"].values())
    # k = 1: the top probabilistic plan is the deterministic one, so Table II's k=1 p is "identical"
    det = {r["problem"]: r for r in rows if r["method"] == "deterministic"}
    for r in rows:
        if r["method"] == "probabilistic" and r["k"] == 1:
            for f in ("solved", "predicted_error_m", "refined", "refine_failure", "refine_time_s", "executed_actions",
                      "final_error_m", "success", "outcome"):
                r[f] = det[r["problem"]][f]
    # the Fig. 4 variants were not run on every problem: comparisons pair rows by problem
    def missing(r):
        return (r["method"] == "cfs_gumbel" and r["problem"].endswith("3")
                or r["method"] == "symbolic_sigmoid" and r["n"] == 4 and r["problem"].endswith("2"))
    return [r for r in rows if not missing(r)]


def write_rows(path, rows):
    path.mkdir(parents=True, exist_ok=True)
    (path / "rows.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))


ABLATION = {"source": "data/", "runs": 2, "epochs": 15, "num_test": 400, "num_train_val": 1600,
            "activations": {"gumbel_sigmoid": {"label": "Gumbel-Sigmoid", "mean_cm": 3.456, "std_cm": 0.123},
                            "tanh": {"label": "Tanh", "mean_cm": 2.5, "std_cm": 0.2},
                            "none": {"label": "No activation", "mean_cm": 2.4, "std_cm": 0.05},
                            "sigmoid": {"label": "Sigmoid", "mean_cm": 2.104, "std_cm": 0.011}}}


# two scenes: a cube on a bar and a cube beside it; another with three blocks on the table
SCENES = [np.array([[0.6, 0.0, 0.025, 0, 1], [0.6, 0.05, 0.075, 1, 0], [0.75, 0.2, 0.025, 1, 0]]),
          np.array([[0.5, -0.1, 0.025, 1, 0], [0.7, 0.1, 0.025, 0, 1], [0.8, 0.3, 0.025, 1, 0]])]


def toy_symbols(X):
    """A Symbolic Model whose unary bit is 'elevated' and whose relation is 'i on j'."""
    from learned.interpret import relation_facts

    return (X[:, 2:3] > 0.04).astype(np.uint8), relation_facts(X)["i on j"][None].astype(np.uint8)


# --- reading the report back ---------------------------------------------------------------------
def parse(md):
    """{section number: {"text": [...], "tables": [[{header: cell}, ...], ...]}} from report.md."""
    sections, cur, table = {}, None, None
    for line in md.splitlines():
        if line.startswith("## "):
            cur = sections.setdefault(line[3:].split(".")[0], {"text": [], "tables": []})
            table = None
        elif cur is None:
            continue
        elif line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if table is None:
                table = {"header": cells, "rows": []}
                cur["tables"].append(table)
            elif not set("".join(cells)) <= {"-"}:
                table["rows"].append(dict(zip(table["header"], cells)))
        else:
            table = None
            if line.strip():
                cur["text"].append(line)
    return {k: {"text": v["text"], "tables": [t["rows"] for t in v["tables"]]} for k, v in sections.items()}


def num(cell):
    return float(cell.replace("≈", ""))


def close(cell, expected, digits):
    """The cell shows `expected` rounded to `digits` decimals ('—' for None)."""
    if expected is None:
        assert cell == "—"
    else:
        assert abs(num(cell) - expected) <= 0.5 * 10 ** -digits + 1e-9, (cell, expected)


def close_pm(cell, values, digits):
    m, s = cell.split(" ± ")
    v = np.asarray(values, dtype=float)
    close(m, v.mean(), digits)
    close(s, v.std(ddof=1) if v.size > 1 else 0.0, digits)


def expected_p(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if len(a) < 2:
        return "—"
    if np.all(a == b):
        return "identical"
    return ttest_rel(a, b).pvalue


def check_p(cell, a, b):
    p = expected_p(a, b)
    if isinstance(p, str):
        assert cell == p
    elif p < 1e-4:
        assert cell == "< 0.0001"
    else:
        close(cell, p, 4)


def pct(flags):
    return 100.0 * sum(flags) / len(flags) if flags else None


class Rows:
    def __init__(self, rows):
        self.rows = rows
        self.by = {}
        for r in rows:
            self.by.setdefault(r["method"], {})[r["problem"]] = r

    def pairs(self, a, b, keep=lambda r: True):
        common = sorted(set(self.by[a]) & set(self.by[b]))
        return [(self.by[a][p], self.by[b][p]) for p in common if keep(self.by[a][p])]

    def of(self, m, keep=lambda r: True):
        return [r for r in self.by[m].values() if keep(r)]

    def cell(self, problem):
        r = next(r for r in self.rows if r["problem"] == problem)
        return r["n"], r["k"]


def runs_pm(cell, rows, value, digits):
    """The cell is mean ± std over runs 0 and 1 of value(rows of the run), runs without rows left out."""
    groups = [[r for r in rows if r["run"] == run] for run in (0, 1)]
    close_pm(cell, [value(g) for g in groups if g], digits)


def group_keep(label, field):
    if label.startswith("all"):
        return (lambda r: r["k"] > 1) if label == "all k > 1" else (lambda r: True)
    return lambda r: r[field] == int(label)


def check_comparison(table, data, a, b, col_a, col_b, field):
    labels = [row[next(iter(row))] for row in table if row[next(iter(row))] != "paper"]
    assert labels[-1].startswith("all") and len(labels) >= 3
    for row in table:
        label = row[next(iter(row))]
        if label == "paper":
            continue
        pairs = data.pairs(a, b, group_keep(label, field))
        sa, sb = [x["success"] for x, _ in pairs], [y["success"] for _, y in pairs]
        assert int(row["problems"]) == len(pairs)
        close(row[col_a], pct(sa), 1)
        close(row[col_b], pct(sb), 1)
        check_p(row["p"], sa, sb)


# --- the tests -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def full_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    rows = make_rows()
    write_rows(out, rows)
    (out / "meta.json").write_text(json.dumps({"models_dir": "/models/run1", "problems": "problems.jsonl",
                                               "config": {"fidelity": "fast", "n_domains": 100}}))
    ablation = out / "abl.json"
    ablation.write_text(json.dumps(ABLATION))
    (out / "symbols.json").write_text(json.dumps([b.to_dict() for b in interpret_symbols(toy_symbols, SCENES)]))
    md_path = write_report(out, ablation=ablation)
    return out, Rows(rows), parse(md_path.read_text())


def test_setup_and_table1(full_report):
    out, data, s = full_report
    items = {r["item"]: r["value"] for r in s["1"]["tables"][0]}
    assert items["rows"] == str(len(data.rows)) and items["problems"] == "60"
    assert items["meta: models_dir"] == "/models/run1" and items["meta: config.n_domains"] == "100"
    assert items["eps (cm)"] == "5" and items["tau_verify (cm)"] == "7" and items["fidelity"] == "fast"
    for row in s["1"]["tables"][1]:
        for k in range(1, 6):
            want = len({r["problem"] for r in data.rows
                        if (row["n"] == "all" or r["n"] == int(row["n"])) and r["k"] == k})
            assert int(row[f"k={k}"]) == want
    assert items["runs"] == "2" and items["protocol"] == "paper" and items["symbolic backend"] == "fd"
    moved = {r["problem"]: r["moved"] for r in data.rows}
    for row in s["1"]["tables"][2]:  # actions that moved / all actions (problems whose goal is the initial scene)
        for col in [f"k={k}" for k in range(1, 6)] + ["all"]:
            ps = [p for p in moved if (row["n"] == "all" or data.cell(p)[0] == int(row["n"]))
                  and (col == "all" or data.cell(p)[1] == int(col[2:]))]
            assert row[col] == f"{sum(moved[p] for p in ps)}/{sum(data.cell(p)[1] for p in ps)} " \
                               f"({sum(moved[p] == 0 for p in ps)})"
    assert {r["method"]: int(r["rows"]) for r in s["1"]["tables"][3]} == {f"`{m}`": len(data.by[m]) for m in METHODS}
    assert len(data.by["cfs_gumbel"]) == 45 and len(data.by["symbolic_sigmoid"]) == 55
    t1 = {r["activation"]: r for r in s["2"]["tables"][0]}
    for act in ABLATION["activations"].values():
        m, sd = t1[act["label"]]["ours (cm)"].split(" ± ")
        close(m, act["mean_cm"], 2)
        close(sd, act["std_cm"], 2)
    assert t1["Gumbel-Sigmoid"]["paper (cm)"] == "3.34 ± 0.18" and t1["Sigmoid"]["paper (cm)"] == "2.01 ± 0.13"


def test_table1_shows_the_runs_still_training_apart_from_the_means():
    from evaluation.report import section_table1

    table = {**ABLATION, "runs": 3, "complete": False, "trained": "trained to convergence (patience 100)",
             "zero_effect_cm": 2.5101,
             "activations": {"tanh": {"label": "Tanh", "runs": 3, "mean_cm": 0.6, "std_cm": 0.02,
                                      "epochs": [691, 700, 650], "in_progress": []},
                             "none": {"label": "No activation", "runs": 0, "mean_cm": None, "std_cm": 0.0,
                                      "epochs": [], "in_progress": [{"run": 0, "epochs": 1300, "test_cm": 0.375,
                                                                     "val_cm": 0.38}]}}}
    section = section_table1(table, Path("ablation.json"))
    text = "\n".join(section.lines)
    assert "| Tanh | 0.60 ± 0.02 | 3 | 691, 700, 650 | — | 2.24 ± 0.12 |" in text
    assert "| No activation | — | 0 | — | 0.38 after 1300 epochs, run 0 | 2.19 ± 0.08 |" in text
    assert "trained to convergence (patience 100)" in text and "not in the means" in text
    assert "predicting no effect: 2.51 cm" in text
    assert section.data["complete"] is False and section.data["activations"]["none"]["ours_cm"]["mean"] is None


def test_dual_model_and_table2(full_report):
    _, data, s = full_report
    sym, search = s["3"]["tables"]
    check_comparison(sym, data, "deterministic", "symbolic_sigmoid", "Gumbel-Sigmoid `deterministic` (%)",
                     "Sigmoid `symbolic_sigmoid` (%)", "n")
    check_comparison(search, data, "cfs", "cfs_gumbel", "Sigmoid `cfs` (%)", "Gumbel-Sigmoid `cfs_gumbel` (%)", "n")
    assert sym[-1]["p"] == search[-1]["p"] == "< 0.0001"  # the paper's row
    (t2,) = s["4"]["tables"]
    check_comparison(t2, data, "deterministic", "probabilistic", "deterministic (%)", "probabilistic (%)", "k")
    assert t2[0]["p"] == "identical"  # k = 1: the same plans by construction
    for row in t2:
        keep = group_keep(row["k"], "k")
        pairs = data.pairs("deterministic", "probabilistic", keep)
        success = lambda rs: pct([r["success"] for r in rs])  # noqa: E731
        runs_pm(row["deterministic runs (%)"], [a for a, _ in pairs], success, 1)
        runs_pm(row["probabilistic runs (%)"], [b for _, b in pairs], success, 1)
        oracle = data.of("probabilistic_oracle", keep)
        close(row["oracle (%)"], success(oracle), 1)
        runs_pm(row["oracle runs (%)"], oracle, success, 1)
        close(row["oracle plans executed (mean)"], np.mean([r["executed_plans"] for r in oracle if r["solved"]]), 2)
        first = {r["problem"]: r for r in data.rows}
        assert row["moved actions"] == f"{sum(r['moved'] for r in first.values() if keep(r))}/" \
                                      f"{sum(r['k'] for r in first.values() if keep(r))}"
    assert any("EXECUTION ORACLE" in t for t in s["4"]["text"])
    assert any("Fast Downward" in t and "`paper`" in t for t in s["4"]["text"])
    assert t2[0]["paper deterministic (%)"] == "62.40 ± 3.86" and t2[4]["paper probabilistic (%)"] == "28.93 ± 5.56"
    assert t2[-1]["paper p"] == "< 0.0001"


def test_verifier_confusion_and_sweep(full_report):
    _, data, s = full_report
    prob = data.of("probabilistic")
    plans = [r for r in prob if r["solved"]]
    note = f"{len(plans)} plans, {len(prob) - len(plans)} rows without a plan left out"
    assert any(note in t for t in s["5"]["text"])
    conf, kinds, sweep = s["5"]["tables"]

    def counts(rs, tau):
        v = [r["predicted_error_m"] < tau for r in rs]
        ok = [r["success"] for r in rs]
        return (sum(a and b for a, b in zip(v, ok)), sum(a and not b for a, b in zip(v, ok)),
                sum(not a and not b for a, b in zip(v, ok)), sum(not a and b for a, b in zip(v, ok)))

    for row in conf:
        if row["n"] == "paper":
            assert [row[c] for c in ("verified: success (%)", "unverified: failure (%)", "accuracy", "F1")] == \
                ["94.2", "90.9", "0.93", "0.90"]
            continue
        rs = [r for r in plans if row["n"] == "all" or r["n"] == int(row["n"])]
        tp, fp, tn, fn = counts(rs, 0.07)
        assert (int(row["plans"]), int(row["TP"]), int(row["FP"]), int(row["TN"]), int(row["FN"])) == \
            (len(rs), tp, fp, tn, fn)
        close(row["verified: success (%)"], 100 * tp / (tp + fp), 1)
        close(row["unverified: failure (%)"], 100 * tn / (tn + fn), 1)
        close(row["accuracy"], (tp + tn) / len(rs), 2)
        close(row["F1"], 2 * tp / (2 * tp + fp + fn), 2)
    for row in kinds:  # empty plans apart
        rs = [r for r in plans if {"non-empty plans": bool(r["plan"]), "empty plans": r["plan"] == [],
                                   "all plans": True}[row["plans"]]]
        tp, fp, tn, fn = counts(rs, 0.07)
        assert (int(row["count"]), int(row["TP"]), int(row["FP"]), int(row["TN"]), int(row["FN"])) == \
            (len(rs), tp, fp, tn, fn)
        runs_pm(row["accuracy runs"], rs, lambda g: sum(counts(g, 0.07)[i] for i in (0, 2)) / len(g), 2)
    assert int(kinds[1]["count"]) == sum(r["plan"] == [] for r in plans) > 0
    assert [int(r["tau (cm)"]) for r in sweep] == list(range(1, 16))
    for row in sweep:
        tau = int(row["tau (cm)"]) / 100
        for g in ("n=2", "n=3", "n=4", "all"):
            rs = [r for r in plans if g == "all" or r["n"] == int(g[2:])]
            tp, fp, tn, fn = counts(rs, tau)
            close(row[f"{g} accuracy"], (tp + tn) / len(rs), 2)
            close(row[f"{g} F1"], 2 * tp / (2 * tp + fp + fn) if 2 * tp + fp + fn else None, 2)


def test_success_per_cell_levels_and_outcomes(full_report):
    _, data, s = full_report
    cells, bvc, outcomes = s["6"]["tables"]
    assert len(cells) == 15 + 3 + 1
    for row in cells:
        def keep(r, row=row):
            return (row["n"] == "all" or r["n"] == int(row["n"])) and (row["k"] == "all" or r["k"] == int(row["k"]))
        assert int(row["problems"]) == len({r["problem"] for r in data.rows if keep(r)})
        for m in METHODS:
            close(row[f"`{m}` (%)"], pct([r["success"] for r in data.of(m, keep)]), 1)
        b = data.of("bilevel", keep)
        for lvl in (1, 2):
            close(row[f"`bilevel` Level {lvl} (%)"], pct([r["success"] and r["level"] == lvl for r in b]), 1)
    check_comparison(bvc, data, "bilevel", "cfs", "`bilevel` (%)", "`cfs` (%)", "n")
    assert bvc[-1]["paper p"] == "0.21"
    for row in outcomes:
        rs = data.of(row["method"].strip("`"))
        assert int(row["rows"]) == len(rs)
        for o in OUTCOMES:
            close(row[f"{o} (%)"], pct([r["outcome"] == o for r in rs]), 1)
    assert any("not given as numbers" in t or "without numbers" in t for t in s["6"]["text"])


def test_planning_time_table3(full_report):
    _, data, s = full_report
    times, split = s["7"]["tables"]
    for row in times:
        pairs = data.pairs("bilevel", "cfs", group_keep(row["n"], "n"))
        tb = [a["planning_time_s"] for a, _ in pairs]
        tc = [b["planning_time_s"] for _, b in pairs]
        assert int(row["problems"]) == len(pairs)
        close_pm(row["`bilevel` (s)"], tb, 3)
        close_pm(row["`cfs` (s)"], tc, 3)
        close(row["`bilevel` median (s)"], np.median(tb), 3)
        close(row["`cfs` median (s)"], np.median(tc), 3)
        close(row["speedup"], np.mean(tc) / np.mean(tb), 2)
        check_p(row["p"], tb, tc)
        mean_time = lambda rs: np.mean([r["planning_time_s"] for r in rs])  # noqa: E731
        runs_pm(row["`bilevel` runs (s)"], [a for a, _ in pairs], mean_time, 3)
        runs_pm(row["`cfs` runs (s)"], [b for _, b in pairs], mean_time, 3)
    assert [r["paper bilevel (s)"] for r in times] == ["0.83 ± 0.15", "2.63 ± 0.79", "4.75 ± 3.10", "—"]
    assert [r["paper speedup"] for r in times] == ["1.16", "1.21", "1.81", "—"]
    for row in split:
        if row["subset"].startswith("paper"):
            continue
        every = data.pairs("bilevel", "cfs", group_keep(row["n"], "n"))
        pairs = [(a, b) for a, b in every if (a["level"] == 1) == (row["subset"] == "Level 1")]
        assert int(row["problems"]) == len(pairs)
        close(row["share (%)"], 100 * len(pairs) / len(every), 1)
        close_pm(row["`bilevel` (s)"], [a["planning_time_s"] for a, _ in pairs], 3)
        close_pm(row["`cfs` (s)"], [b["planning_time_s"] for _, b in pairs], 3)
        close(row["`bilevel` success (%)"], pct([a["success"] for a, _ in pairs]), 1)
        close(row["`cfs` success (%)"], pct([b["success"] for _, b in pairs]), 1)
    paper_l1 = next(r for r in split if r["subset"] == "paper: Level 1")
    assert paper_l1["`bilevel` (s)"] == "0.006 ± 0.003" and paper_l1["`cfs` (s)"] == "0.932 ± 0.566"


def test_replanning_and_refinement(full_report):
    _, data, s = full_report
    (rp,) = s["8"]["tables"]
    assert [r["k"] for r in rp] == ["2", "3", "4", "5", "all k > 1"]
    check_comparison(rp, data, "bilevel", "bilevel_replan", "`bilevel` (%)", "`bilevel_replan` (%)", "k")
    for row in rp:
        pairs = data.pairs("bilevel", "bilevel_replan", group_keep(row["k"], "k"))
        close(row["gain (points)"], pct([b["success"] for _, b in pairs]) - pct([a["success"] for a, _ in pairs]), 1)
        close(row["rounds (mean)"], np.mean([b["rounds"] for _, b in pairs]), 2)
        runs_pm(row["`bilevel_replan` runs (%)"], [b for _, b in pairs], lambda g: pct([r["success"] for r in g]), 1)
    assert rp[0]["paper w/o (%)"] == "82.0 ± 3.0" and rp[3]["paper w (%)"] == "72.0 ± 5.0"
    (ref,) = s["9"]["tables"]
    for row in ref:
        rs = data.of(row["method"].strip("`"))
        plans = [r for r in rs if r["refined"] is not None]
        times = [t for r in rs for t in r["refine_time_s"]]
        assert (int(row["rows"]), int(row["plans"])) == (len(rs), len(plans))
        assert int(row["actions timed"]) == len(times)
        close(row["refined (%)"], pct([r["refined"] for r in plans]), 1)
        for stage in ("ik", "motion", "grasp"):
            failed = [r for r in rs if r["refine_failure"] and r["refine_failure"]["stage"] == stage]
            assert int(row[f"{stage} failures"]) == len(failed)
        close(row["refine time median (s)"], np.median(times), 3)
        close(row["refine time p90 (s)"], np.percentile(times, 90), 3)
        close(row["executed actions (mean)"], np.mean([r["executed_actions"] for r in plans]), 2)


def test_level1_algorithm1_against_our_extensions(full_report):
    _, data, s = full_report
    t, times = s["10"]["tables"]
    # Level-1 time per n and method, median / mean (ms), in total and per stage, from the rows
    assert [(row["n"], row["method"]) for row in times] == [
        (n, f"`{m}`") for n in ("2", "3", "4", "all") for m in ("bilevel_alg1", "bilevel")]
    for row in times:
        rs = [r for r in data.rows if r["method"] == row["method"].strip("`") and group_keep(row["n"], "n")(r)]
        assert int(row["problems"]) == len(rs)
        for col, value in (("Level 1", lambda r: r["level1_time_s"]),
                           ("symbols", lambda r: r["level1_stages_s"]["symbols"]),
                           ("verify", lambda r: r["level1_stages_s"]["verify"])):
            med, mean = (float(v) for v in row[col].split(" / "))
            xs = [1000 * value(r) for r in rs]
            assert med == pytest.approx(np.median(xs), abs=0.051) and mean == pytest.approx(np.mean(xs), abs=0.051)
    check_comparison(t, data, "bilevel_alg1", "bilevel", "`bilevel_alg1` (%)", "`bilevel` (%)", "n")
    for row in t[:-1]:
        pairs = data.pairs("bilevel_alg1", "bilevel", group_keep(row["n"], "n"))
        for m, side in (("bilevel_alg1", 0), ("bilevel", 1)):
            rs = [pair[side] for pair in pairs]
            close(row[f"`{m}` Level 1 (%)"], pct([r["level"] == 1 for r in rs]), 1)
            close(row[f"`{m}` Level-1 success (%)"], pct([r["level"] == 1 and r["success"] for r in rs]), 1)
            close(row[f"`{m}` time (s)"], np.mean([r["planning_time_s"] for r in rs]), 3)
            runs_pm(row[f"`{m}` Level 1 runs (%)"], rs, lambda g: pct([r["level"] == 1 for r in g]), 1)
    assert t[-1]["n"] == "paper" and t[-1]["`bilevel_alg1` Level 1 (%)"] == "≈60"


def test_scaling_with_the_number_of_blocks(full_report):
    _, data, s = full_report
    table, growth, effect = s["13"]["tables"]
    assert {(r["method"], r["n"]) for r in table} == {(f"`{m}`", str(n)) for m in METHODS for n in (2, 3, 4)}
    mean_t = {}
    for row in table:
        m, n = row["method"].strip("`"), int(row["n"])
        rs = [r for r in data.of(m) if r["n"] == n]
        times = [1000 * r["planning_time_s"] for r in rs]
        assert int(row["problems"]) == len(rs)
        close(row["success (%)"], pct([r["success"] for r in rs]), 1)
        med, mean = (float(v) for v in row["planning median / mean (ms)"].split(" / "))
        assert med == pytest.approx(np.median(times), abs=0.51) and mean == pytest.approx(np.mean(times), abs=0.51)
        mean_t[m, n] = np.mean(times)
        close(row["refined (%)"], pct([r["refined"] for r in rs if r["refined"] is not None]), 1)
        if m.startswith("bilevel"):
            close(row["Level 1 (%)"], pct([r["level"] == 1 for r in rs]), 1)
        else:
            assert row["Level 1 (%)"] == "—"
    for row in growth:
        m = row["method"].strip("`")
        if row["step"].startswith("overall"):
            expected = (mean_t[m, 4] / mean_t[m, 2]) ** 0.5
        else:
            a, b = (int(x) for x in row["step"].split("->"))
            expected = mean_t[m, b] / mean_t[m, a]
        assert float(row["mean"].rstrip("x")) == pytest.approx(expected, abs=0.006)
    dynamics = ("cfs", "bilevel", "bilevel_alg1", "bilevel_replan")
    for row in effect:
        errors = [e for r in data.rows if r["n"] == int(row["n"]) and r["method"] in dynamics
                  for e in r["effect_error_m"]]
        assert int(row["actions"]) == len(errors)
        close(row["mean (cm)"], 100 * np.mean(errors), 2)


def test_learned_symbols_section(full_report):
    _, _, s = full_report
    (t,) = s["11"]["tables"]
    rows = {r["bit"]: r for r in t}
    assert set(rows) == {"u0", "r0", "r0(i,i)"}
    assert rows["u0"]["best fact"] == "elevated (z > 4 cm)" and rows["u0"]["agreement (%)"] == "100.0"
    assert rows["u0"]["read on"] == "6" and rows["u0"]["rate"] == "0.167" and rows["u0"]["phi"] == "+1.00"
    assert rows["r0"]["best fact"] == "i on j" and rows["r0"]["read on"] == "12" and rows["r0"]["rate"] == "0.083"


def test_the_abstraction_fidelity_is_recomputed_from_rows(full_report):
    """Section 14: per method, executed steps judged against their operator, the share as expected, and
    success with every step as expected against with one that was not; each cell from the rows."""
    _, data, s = full_report
    (t,) = s["14"]["tables"]
    rows = [r for r in data.rows if r["outcome"] != "error"]
    assert [r["method"] for r in t] == [m for m in dict.fromkeys(r["method"] for r in rows)
                                        if any(x["steps"] is not None for x in rows if x["method"] == m)]
    for line in t:
        mine = [r for r in rows if r["method"] == line["method"] and r["steps"] is not None]
        judged = [x for r in mine for x in r["steps"] if x["match"] is not None]
        assert int(line["problems"]) == len(mine) and int(line["executed steps (with an operator)"]) == len(judged)
        close(line["as expected (%)"], 100 * np.mean([x["match"] for x in judged]), 1)
        broken = [r for r in mine if any(x["match"] is False for x in r["steps"])]
        assert line["success, a step not as expected (%)"] == \
            f"{100 * np.mean([r['success'] for r in broken]):.1f} (of {len(broken)})"
        assert int(line["no operator"]) == sum(x["operator"] is None for r in mine for x in r["steps"])


def test_the_failure_causes_are_recomputed_from_rows(full_report):
    """Section 15: failed problems per cause, method and n. The synthetic rows hold no search status
    nor step misses: a row without a plan is a symbolic planner's, one that could not be carried out
    an execution failure, a wrong plan a sum of small errors."""
    _, data, s = full_report
    (t,) = s["15"]["tables"]
    expected_cause = {"no_plan": "no_symbolic_plan", "kinematic_failure": "execution",
                      "refinement_failure": "execution", "wrong_plan": "small_errors"}
    rows = [r for r in data.rows if r["outcome"] != "error"]
    assert {line["method"].strip("`") for line in t} == {r["method"] for r in rows}
    for line in t:
        mine = [r for r in rows if r["method"] == line["method"].strip("`") and
                (line["n"] == "all" or r["n"] == int(line["n"]))]
        failed = [expected_cause[r["outcome"]] for r in mine if not r["success"]]
        assert int(line["failed"]) == len(failed)
        for cause in ("no_symbolic_plan", "execution", "small_errors"):
            assert int(line[f"`{cause}`"]) == failed.count(cause), (line, cause)


def test_the_dynamics_models_misses_and_calibration_are_recomputed_from_rows(full_report):
    """Section 16: per method and n, executed steps, the shares that missed by 2 and 5 cm or more and beyond
    the model's 95 % bound; per action class the same over every method."""
    _, data, s = full_report
    methods, classes = s["16"]["tables"]
    rows = [r for r in data.rows if r["outcome"] != "error"]
    for line in methods:
        mine = [p for r in rows if r["method"] == line["method"].strip("`") and
                (line["n"] == "all" or r["n"] == int(line["n"])) for p in r["predictions"]]
        assert int(line["steps"]) == len(mine)
        close(line[">= 2 cm (%)"], 100 * np.mean([p["miss_m"] >= 0.02 for p in mine]), 1)
        close(line["beyond the 95 % bound (%)"], 100 * np.mean([p["miss_m"] > p["bound_m"] for p in mine]), 1)
    assert {line["action"] for line in classes} == {"cube on a cube", "bar beside a cube"}


def test_figures_and_json(full_report):
    out, data, s = full_report
    for name in ("dual_model", "verifier_tau", "verifier_confusion", "success", "planning_time", "scaling"):
        png = out / "figures" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    numbers = json.loads((out / "report.json").read_text())
    assert numbers["skipped"] == []
    t2 = numbers["sections"]["table2"]["groups"]
    assert [g["group"] for g in t2] == ["1", "2", "3", "4", "5", "all"]
    assert t2[0]["p"] == "identical"
    assert numbers["sections"]["verifier"]["confusion"]["all"]["tp"] == int(s["5"]["tables"][0][3]["TP"])


def test_missing_sections_are_one_line_notes(tmp_path):
    write_rows(tmp_path, make_rows(methods=("deterministic", "cfs"), per_cell=2))
    md = write_report(tmp_path).read_text()
    s = parse(md)
    for key in ("2", "3", "4", "5", "7", "8"):
        assert s[key]["tables"] == [] and len(s[key]["text"]) == 1, (key, s[key])
    assert "ablation" in s["2"]["text"][0] and "symbolic_sigmoid" in s["3"]["text"][0]
    assert "No meta.json" in md
    assert {r["method"] for r in s["6"]["tables"][-1]} == {"`deterministic`", "`cfs`"}
    skipped = json.loads((tmp_path / "report.json").read_text())["skipped"]
    assert skipped == ["table1", "dual_model", "table2", "verifier", "table3", "replanning", "level1", "symbols"]
    assert "14" in s and s["14"]["tables"]  # the abstraction fidelity of the rows' steps
    assert (tmp_path / "figures" / "success.png").stat().st_size > 0


def test_bad_rows_name_the_file_and_line(tmp_path):
    with pytest.raises(ValueError, match="rows.jsonl"):
        write_report(tmp_path)
    rows = make_rows(methods=("cfs",), per_cell=1)
    text = [json.dumps(r) for r in rows]
    text[2] = text[2][:40]  # a truncated line
    (tmp_path / "rows.jsonl").write_text("\n".join(text) + "\n")
    with pytest.raises(ValueError, match=r"rows.jsonl line 3: not valid JSON"):
        write_report(tmp_path)
    bad = dict(rows[1], outcome="exploded")
    (tmp_path / "rows.jsonl").write_text("\n".join([text[0], json.dumps(bad)]) + "\n")
    with pytest.raises(ValueError, match=r"line 2: outcome: expected one of .*, got \"exploded\""):
        write_report(tmp_path)
    odd = dict(rows[1], predictions=[{"class": "cube on a cube", "miss_m": 0.01, "scene": [1]}])
    (tmp_path / "rows.jsonl").write_text("\n".join([text[0], json.dumps(odd)]) + "\n")
    with pytest.raises(ValueError, match=r"line 2: predictions\[0\]\.scene: expected one of"):
        write_report(tmp_path)
    (tmp_path / "rows.jsonl").write_text("\n".join([text[0], text[0]]) + "\n")
    with pytest.raises(ValueError, match=r"line 2: problem 'n2-k1-000' with method 'cfs' already on line 1"):
        write_report(tmp_path)
    assert not (tmp_path / "report.md").exists()


def test_an_interrupted_last_line_is_left_out_with_a_note(tmp_path):
    rows = make_rows(methods=("cfs",), per_cell=1)
    text = "".join(json.dumps(r) + "\n" for r in rows[:-1]) + json.dumps(rows[-1])[:30]
    (tmp_path / "rows.jsonl").write_text(text)
    s = parse(write_report(tmp_path).read_text())
    assert {r["item"]: r["value"] for r in s["1"]["tables"][0]}["rows"] == str(len(rows) - 1)
    assert any(f"Line {len(rows)} of" in t and "left out" in t for t in s["1"]["text"])
