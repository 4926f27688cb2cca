"""The paper's reported figures, as printed (the only numbers typed by hand in `evaluation`).

Source: ../shared/paper/bilevel-planning-paper.tex, Section "Results & Discussion". Pairs are
(mean, std) over the paper's ten runs. `P_BELOW` stands for "p < 0.0001" in the text.
"""
from __future__ import annotations

P_BELOW = 1e-4  # the text's "p < 0.0001"

# Table I (tab:eff_pred): mean effect prediction error (cm) per bottleneck activation, ten runs.
TABLE1_ERROR_CM: dict[str, tuple[float, float]] = {
    "gumbel_sigmoid": (3.34, 0.18),
    "tanh": (2.24, 0.12),
    "none": (2.19, 0.08),
    "sigmoid": (2.01, 0.13),
}

# Fig. 4 (fig:dual_model), text of "Validation of the Dual-Model Design": bars not given as numbers.
# Symbolic planning: Gumbel-Sigmoid Symbolic Model > Sigmoid variant; continuous search: Sigmoid
# Dynamics Model > Gumbel-Sigmoid variant; both p < 0.0001.
FIG4_SYMBOLIC_BETTER = "deterministic"  # the Gumbel-Sigmoid Symbolic Model (not `symbolic_sigmoid`)
FIG4_SEARCH_BETTER = "cfs"  # the Sigmoid Dynamics Model (not `cfs_gumbel`)
FIG4_P = P_BELOW

# Table II (tab:ppddl): success (%) of the deterministic and probabilistic planners per k,
# averaged over n in {2, 3, 4}; the text gives p < 0.0001 for the difference.
TABLE2_SUCCESS_PCT: dict[int, dict[str, tuple[float, float]]] = {
    1: {"deterministic": (62.40, 3.86), "probabilistic": (71.70, 3.48)},
    2: {"deterministic": (44.57, 6.16), "probabilistic": (54.87, 5.07)},
    3: {"deterministic": (33.60, 7.20), "probabilistic": (43.90, 6.57)},
    4: {"deterministic": (27.63, 6.75), "probabilistic": (35.67, 6.81)},
    5: {"deterministic": (22.27, 5.71), "probabilistic": (28.93, 5.56)},
}
TABLE2_P = P_BELOW

# "Effectiveness of the Plan Verification Mechanism" (text; Figs. 6 and 7), tau_verify = 7 cm:
# verified symbolic plans succeed 94.2 %, unverified ones fail 90.9 %; mean accuracy and F1.
VERIFIER_TAU_M = 0.07
VERIFIER = {"verified_success_pct": 94.2, "unverified_failure_pct": 90.9, "accuracy": 0.93, "f1": 0.90}

# Fig. 5 (fig:planning_results): success per (n, k) and method; the bars are not given as numbers.
# The text: bilevel vs continuous forward search not significantly different, p = 0.21.
BILEVEL_VS_CFS_P = 0.21

# Table III (tab:planning_time): planning time (s) per n, bilevel vs continuous forward search,
# 50 problems, ten runs, k in 1..5; the text gives the speedups.
TABLE3_TIME_S: dict[int, dict[str, tuple[float, float]]] = {
    2: {"bilevel": (0.83, 0.15), "cfs": (0.96, 0.14)},
    3: {"bilevel": (2.63, 0.79), "cfs": (3.18, 0.72)},
    4: {"bilevel": (4.75, 3.10), "cfs": (8.58, 4.88)},
}
TABLE3_SPEEDUP: dict[int, float] = {2: 1.16, 3: 1.21, 4: 1.81}

# Text after Table III: problems solved at Level 1 (about 60 %) and the rest (Level 2), planning
# time (s) of each method on the same problems.
LEVEL1_SHARE_PCT = 60.0  # "approximately 60 %"
LEVEL1_TIME_S = {"bilevel": (0.006, 0.003), "cfs": (0.932, 0.566)}
REST_TIME_S = {"bilevel": (5.95, 1.42), "cfs": (5.87, 1.36)}

# Table IV (tab:replanning): bilevel success rate (fraction) without and with replanning, k > 1,
# 50 problems, ten runs, averaged over n.
REPLAN_SUCCESS: dict[int, dict[str, tuple[float, float]]] = {
    2: {"bilevel": (0.82, 0.03), "bilevel_replan": (0.91, 0.02)},
    3: {"bilevel": (0.74, 0.05), "bilevel_replan": (0.85, 0.02)},
    4: {"bilevel": (0.67, 0.07), "bilevel_replan": (0.80, 0.04)},
    5: {"bilevel": (0.60, 0.04), "bilevel_replan": (0.72, 0.05)},
}
