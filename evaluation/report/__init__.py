"""The evaluation report: the paper's tables and figures next to ours, from OUT/rows.jsonl.

    write_report(Path("OUT"))   # -> OUT/report.md, OUT/report.json, OUT/figures/*.png

One row per (problem, method) (see `load_rows` for the fields used). Every table compares methods
on the problems both were run on (paired by problem name), so that the paired t-tests
(`scipy.stats.ttest_rel` on per-problem 0/1 success, or planning times) and the rates describe the
same problems. Success is a percentage of problems with one decimal, times are seconds with three
decimals; the paper's numbers (`evaluation.paper`) are quoted as printed. A section whose rows or
files are absent says so in one line.

The package holds one module per group of sections (`setup`: 1, 2, 11; `symbolic_planning`: 3-5;
`planning`: 6-8, 10, 13; `execution`: 9, 12, 14; `causes`: 15; `calibration`: 16), the row readers (`rows`)
and what the sections share (`results`: `Results`, the groups, `Section`); this module assembles the report.
"""
from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import Any

from guarded import atomic_write_json, make_dirs
from tamp.errors import UserError
from tamp.planning.vocabulary import OUTCOMES
from tamp.records import atomic_write_text

from .calibration import section_calibration
from .causes import section_causes
from .execution import section_feasibility, section_fidelity, section_refinement
from .planning import section_level1, section_replanning, section_scaling, section_success, section_table3
from .results import (
    BACKEND_INFO,
    FEASIBILITY_PAIRS,
    METHOD_INFO,
    METHOD_ORDER,
    PROTOCOL_INFO,
    TAUS_CM,
    Keep,
    Results,
    Section,
    compare_success,
    fmt_paper_p,
)
from .rows import ERROR_OUTCOME, STAGES, _read_rows, _read_symbols, load_ablation, load_rows, read_json_object
from .setup import section_setup, section_symbols, section_table1
from .symbolic_planning import section_dual_model, section_table2, section_verifier


def _json_safe(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    return x


def build_report(res: Results, figures: Path, ablation: dict | None = None,
                 ablation_source: Path = Path("ablation.json"), source: str = "rows.jsonl",
                 symbols: list[dict] | None = None, symbols_source: Path = Path("symbols.json")) -> tuple[str, dict]:
    """The Markdown report and its numbers (a JSON-ready dict); writes the PNGs into `figures`."""
    figures.mkdir(parents=True, exist_ok=True)
    sections = [section_setup(res, figures), section_table1(ablation, ablation_source),
                section_dual_model(res, figures), section_table2(res, figures), section_verifier(res, figures),
                section_success(res, figures), section_table3(res, figures), section_replanning(res, figures),
                section_refinement(res, figures), section_level1(res, figures),
                section_symbols(symbols, symbols_source)]
    if any(res.has(a, b) for a, b in FEASIBILITY_PAIRS):  # only when run before and after (`*_nofeas`)
        sections.append(section_feasibility(res, figures))
    sections.append(section_scaling(res, figures))
    sections.append(section_fidelity(res))
    sections.append(section_causes(res, figures))
    sections.append(section_calibration(res, figures))
    lines = ["# Evaluation report", "",
             f"From `{source}` ({len(res.rows)} rows, {len(res.cells)} problems). Ours next to the paper's "
             "numbers (Dogangun et al., quoted as printed). Success in % of problems (one decimal), times in "
             "seconds (three decimals); p from `scipy.stats.ttest_rel` on per-problem pairs, 'identical' when "
             "the two agree on every problem, '—' with fewer than two pairs.", ""]
    for s in sections:
        lines += [f"## {s.title}", ""] + s.lines
    numbers = {"source": source, "sections": {s.key: s.data for s in sections},
               "skipped": [s.key for s in sections if s.data is None]}
    return "\n".join(lines).rstrip() + "\n", _json_safe(numbers)


def write_report(results_dir: Path, ablation: Path | None = None) -> Path:
    """Write results_dir/report.md, report.json and figures/*.png from results_dir/rows.jsonl; returns report.md.

    `ablation`: the JSON of `tamp ablate-activations` (default results_dir/ablation.json, if present).
    """
    results_dir = Path(results_dir)
    rows_path = results_dir / "rows.jsonl"
    rows, dropped = _read_rows(rows_path)
    notes = [] if dropped is None else [f"Line {dropped} of {rows_path} is incomplete (an interrupted evaluation) "
                                        "and was left out."]
    errors = [r for r in rows if r["outcome"] == ERROR_OUTCOME]
    rows = [r for r in rows if r["outcome"] != ERROR_OUTCOME]
    notes += [f"Problem `{r['problem']}` with method `{r['method']}` raised an error and is left out of every "
              f"table: {r.get('error', 'no message')}" for r in errors]
    if not rows:
        raise UserError(f"{rows_path}: every row is an error row ({len(errors)}); nothing to report")
    meta_path = results_dir / "meta.json"
    meta = read_json_object(meta_path, "the evaluation's meta.json") if meta_path.is_file() else None
    if ablation is not None and not Path(ablation).is_file():
        raise UserError(f"{ablation}: no such ablation file")
    ablation_path = Path(ablation) if ablation is not None else results_dir / "ablation.json"
    ablation_data = load_ablation(ablation_path) if ablation_path.is_file() else None
    symbols_path = results_dir / "symbols.json"
    symbols = _read_symbols(symbols_path) if symbols_path.is_file() else None
    figures = results_dir / "figures"
    made = make_dirs(figures)
    try:
        md, numbers = build_report(Results(rows, meta, notes), figures, ablation_data, ablation_path,
                                   str(rows_path), symbols, symbols_path)
        out = results_dir / "report.md"
        atomic_write_json(results_dir / "report.json", numbers, indent=1, ensure_ascii=False)
        atomic_write_text(out, md)
    except BaseException:
        if made:  # a figures folder this run made holds only this run's figures: gone with the failed report
            shutil.rmtree(made[0], ignore_errors=True)
        raise
    return out


__all__ = ["BACKEND_INFO", "ERROR_OUTCOME", "FEASIBILITY_PAIRS", "Keep", "METHOD_INFO", "METHOD_ORDER", "OUTCOMES",
           "PROTOCOL_INFO", "Results", "STAGES", "Section", "TAUS_CM", "build_report", "compare_success",
           "section_causes",
           "fmt_paper_p", "load_ablation", "load_rows", "read_json_object", "section_dual_model",
           "section_feasibility", "section_fidelity", "section_level1", "section_refinement", "section_replanning",
           "section_scaling", "section_setup", "section_success", "section_symbols", "section_table1",
           "section_table2", "section_table3", "section_verifier", "write_report"]
