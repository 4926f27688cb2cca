"""The per-step view of a run, for studying how symbolic steps refine into motion: each step's
symbols (`tamp.planning.steps`) beside what refinement and execution made of it (the skill's
`StepInfo`). `tamp plan` and `tamp demo` print it, write it as JSON beside the replay
(`<replay>.steps.json`, or `--steps`), and the replay shows it in a panel that follows the timeline.

One record per step (JSON keys):
- ``symbols``: `SymbolicStep.to_dict` (before / expected / observed states, the operator, its effect
  and probability, the changes expected and observed, the mismatches, and ``objects``: the objects
  the symbols were read on when a Level-1 plan was made in a sub-scene, else None), or None without
  a Symbolic Model;
- ``motion``: the refinement of the action: IK solver per waypoint (one branch: elbow up, wrist
  down), planner ("direct": the straight joint segment was free; "rrtconnect") and planning time
  per motion, the failure stage, where and why when it did not refine;
- ``dynamics_error_m``: the Dynamics Model's error predicting the step (mean over objects, metres);
- ``t_start``: seconds into the replay at which the step's motion begins (None: no replay, or the
  arm never moved);
- closed loop only: ``round``, the planning round whose plan chose the action, and ``plan``, how
  that round got it: "planned", "kept on course" (the last plan, judged by its own prediction) or
  "kept by rollout" (judged by a rollout from the observed state); `tamp evaluate`'s closed-loop
  rows carry the same two keys in their ``steps``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterator, Sequence

from guarded import atomic_write_json
from learned.interpret import BitNames
from tamp.app.plan_file import fmt_action
from tamp.planning.steps import SymbolicStep, symbolic_steps

if TYPE_CHECKING:
    from tamp.app.runner import ClosedLoopRun, Execution
    from tamp.planning.models import Models
    from tamp.planning.results import PlanResult
    from tamp.sim.world_types import StepInfo


def steps_path(replay: Path) -> Path:
    """Where the steps of a replay are written: beside it, ``<name>.steps.json``."""
    return replay.with_name(replay.stem + ".steps.json")


def motion_record(info: StepInfo | None) -> dict | None:
    """What refinement did for one action: IK, motions, failure."""
    if info is None:
        return None
    from tamp.sim.kinematics import BRANCH
    from tamp.sim.refine import step_failure

    failure = step_failure(info)
    return {"status": str(info.status), "ik_branch": BRANCH, "ik_solver": dict(info.ik_solver),
            "motions": {name: {"planner": info.motion_planner.get(name, ""),
                               "seconds": round(info.motion_seconds.get(name, 0.0), 4), "found": ok}
                        for name, ok in info.motion_success.items()},
            "refined": failure is None,
            "failure": None if failure is None else {"stage": str(failure[0]), "where": failure[1],
                                                     "reason": failure[2]},
            "seconds": round(info.timings.get("total", 0.0) - info.timings.get("execute", 0.0), 4)}


def step_records(steps: Sequence[SymbolicStep], infos: Sequence[StepInfo | None], names: BitNames,
                 starts: Sequence[float | None] = ()) -> list[dict]:
    """One record per step (see the module docstring)."""
    out = []
    for k, step in enumerate(steps):
        out.append({"index": k, "action": list(step.action),
                    "symbols": step.to_dict(names) if step.before is not None else None,
                    "motion": motion_record(infos[k] if k < len(infos) else None),
                    "dynamics_error_m": None if step.dynamics_error_m is None else round(step.dynamics_error_m, 4),
                    "t_start": starts[k] if k < len(starts) else None})
    return out


def open_loop_steps(models: Models, result: PlanResult, X_init, execution: Execution, names: BitNames,
                    starts: Sequence[float | None] = ()) -> list[dict]:
    """The records of a plan refined and executed open loop (`runner.execute_plan`)."""
    assert result.plan is not None
    steps = symbolic_steps(models, [X_init, *execution.X_after], result.plan, result.plan_states,
                           objects=result.plan_scene)
    return step_records(steps, execution.refined.infos, names, starts)


@dataclass
class LoopStep:
    """One action a closed loop sent to the world, with what its step record needs."""

    index: int
    round: int  # the planning round whose plan chose it
    plan: str  # how that round got its plan (`PlanResult.origin`)
    states: list  # the observed states before and after (before only: it could not be refined, nothing ran)
    action: tuple
    plan_states: Sequence[int] | None  # that round's plan's symbolic states from this action on (Level 1)
    info: StepInfo | None
    scene: tuple[int, ...] | None = None  # the sub-scene of plan_states (`PlanResult.plan_scene`); None: all objects


def loop_steps(run: ClosedLoopRun) -> Iterator[LoopStep]:
    """The actions of a closed loop with the round that chose each: every round executes its plan's
    first action, the last round that executed runs its plan to the end."""
    loop, k = run.loop, 0
    planned = [r for r in loop.rounds if r.plan]
    for r, result in enumerate(planned):
        for j in range(len(loop.executed) - k if r == len(planned) - 1 else 1):
            info = run.infos[k] if k < len(run.infos) else None
            ran = info is None or info.changed
            states = result.plan_states
            yield LoopStep(k, r, result.origin, loop.states[k:k + (2 if ran else 1)], tuple(loop.executed[k]),
                           None if states is None else states[j:], info, result.plan_scene)
            k += 1


def closed_loop_steps(models: Models, run: ClosedLoopRun, names: BitNames) -> list[dict]:
    """The records of a closed loop (`loop_steps`); an action that could not be refined did not run:
    no observed symbols, no prediction error."""
    records: list[dict] = []
    for s in loop_steps(run):
        (step,) = symbolic_steps(models, s.states, [s.action], s.plan_states, objects=s.scene)
        records += step_records([step], [s.info], names, run.action_starts[s.index:s.index + 1])
        records[-1].update(index=s.index, round=s.round, plan=s.plan)
    return records


def steps_document(problem: str, method: str, level: int | None, records: list[dict], names: BitNames,
                   configuration: dict | None = None) -> dict:
    """The JSON file beside a replay: the run, the configuration it was planned with, and its steps."""
    return {"problem": problem, "method": method, "level": level, "configuration": configuration or {},
            "bit_names": {bit: {"fact": fact, "bit 1 means": "not " + fact if negated else fact}
                          for bit, (fact, negated) in names.facts.items()},
            "steps": records}


def write_steps(path: Path, document: dict) -> Path:
    return atomic_write_json(path, document, indent=1)


def _change(bit: str, value: int, meaning: str | None) -> str:
    return f"{bit}={value}" + (f" ~ {meaning}" if meaning else "")


def print_steps(records: Sequence[dict], blank_line: bool = False) -> None:
    """Print `format_steps` under its header (nothing without records; `blank_line`: one before it), as
    `tamp plan` and `tamp demo` do."""
    if records:
        print("\n" * blank_line
              + "steps (symbols read by the Symbolic Model on the observed states; see `tamp plan --help`):")
        for line in format_steps(records):
            print("  " + line)


def _chosen_by(record: dict) -> str:
    """" (round 1: kept on course)" for a closed-loop step, else ""."""
    return f" (round {record['round']}: {record['plan']})" if "round" in record else ""


def _of_scene(symbols: dict) -> str:
    """" (of o3, o4: the plan's sub-scene)" when the symbols were read on a Level-1 plan's sub-scene."""
    objects = symbols.get("objects")
    return "" if not objects else f" (of {', '.join(objects)}: the plan's sub-scene)"


def format_steps(records: Sequence[dict]) -> list[str]:
    """Text lines of the records: per step the symbols before (as the facts the named bits say),
    the operator with its effect and what it expects to change, the motion, what was observed, and
    the Dynamics Model's error."""
    lines = []
    for r in records:
        lines.append(f"step {r['index'] + 1}: {fmt_action(r['action'])}{_chosen_by(r)}")
        s = r["symbols"]
        if s is not None:
            before = s["before"]
            facts = "; ".join(before["facts"]) or "no named fact holds"
            lines.append(f"  symbols before{_of_scene(s)}: {facts} ({len(before['set'])} bits set)")
            if s["operator"] is None:
                lines.append("  operator: none of the learned operators grounds this action in these symbols")
            else:
                changes = ", ".join(_change(c["bit"], c["value"], c["meaning"]) for c in s["expected_changes"]) \
                    or "no change"
                plan = "" if s["on_plan"] is None else ("; the plan's symbols" if s["on_plan"] else
                                                        "; off the plan's symbols (an earlier step differed)")
                lines.append(f"  operator {s['operator']}({', '.join(s['binding'])}): effect {s['effect'] + 1} of "
                             f"{s['n_effects']}, p = {s['probability']:.2f}{plan}; expects {changes}")
        m = r["motion"]
        if m is not None:
            lines.append("  motion: " + format_motion(m))
        if s is not None and s["operator"] is not None:
            if not s["executed"]:
                lines.append("  observed: not executed")
            elif s["match"]:
                lines.append("  observed: the expected symbols")
            else:
                diffs = ", ".join(f"{d['bit']}={d['observed']} (expected {d['expected']})"
                                  + (f" ~ {d['meaning_observed']}" if d["meaning_observed"] else "")
                                  for d in s["mismatches"])
                allowed = "" if s["observed_effect"] is None else \
                    f" ({_allowed(s)}, not the expected one)"
                lines.append(f"  observed: MISMATCH in {len(s['mismatches'])} bit(s){allowed}: {diffs}")
        if r["dynamics_error_m"] is not None:
            lines.append(f"  Dynamics Model: {r['dynamics_error_m'] * 100:.1f} cm off (mean over blocks)")
    return lines


def _allowed(s: dict) -> str:
    """Which learned effect gave a step's observed symbols: the expected operator's, or another's of the action."""
    if s.get("observed_operator") in (None, s["operator"]):
        return f"the operator's effect {s['observed_effect'] + 1}"
    return f"effect {s['observed_effect'] + 1} of {s['observed_operator']}, another operator of the action"


def format_motion(m: dict) -> str:
    """One line: IK solvers, each motion's planner (time when it searched), total, failure."""
    solvers = sorted(set(m["ik_solver"].values()))
    ik = f"IK {' + '.join(solvers) or 'none'} ({len(m['ik_solver'])} waypoints, {m['ik_branch']})"
    motions = ", ".join(f"{name} {v['planner'] or 'none'}"
                        + (f" {v['seconds'] * 1e3:.0f} ms" if v["planner"] == "rrtconnect" else "")
                        for name, v in m["motions"].items())
    text = f"{ik}; {motions or 'no motion planned'}; {m['seconds']:.2f} s"
    if m["failure"] is not None:
        f = m["failure"]
        text += f"; FAILED at {f['stage']} [{f['where']}]: {f['reason']}"
    return text


# --- the replay's step panel ---------------------------------------------------------------------
_MISMATCH = "color:#c0392b;font-weight:bold"


def _bit_rows(s: dict) -> list[tuple[str, int, int | None, int | None, str, bool]]:
    """(bit, before, expected, observed, meaning of the observed (else expected) value, mismatch) for
    every bit expected to change, observed to change, or mismatched."""
    def value(state: dict | None, bit: str) -> int | None:
        return None if state is None else int(bit in state["set"])

    meanings: dict[str, str] = {}
    for key in ("expected_changes", "observed_changes"):
        for c in s[key] or []:
            if c["meaning"]:
                meanings[c["bit"]] = c["meaning"]
    bits = list(dict.fromkeys([c["bit"] for c in s["expected_changes"] or []]
                              + [c["bit"] for c in s["observed_changes"] or []]))
    rows = []
    for bit in bits:
        e, o = value(s["expected"], bit), value(s["observed"], bit)
        rows.append((bit, int(value(s["before"], bit) or 0), e, o, meanings.get(bit, ""),
                     e is not None and o is not None and e != o))
    return rows


def step_panel_html(record: dict, total: int) -> str:
    """One step in the replay's panel: the action, the operator, the changed bits (before, expected,
    observed; mismatches in red), the verdict, the motion and the Dynamics Model's error."""
    from html import escape

    r, s, m = record, record["symbols"], record["motion"]
    out = [f"<div><b>step {r['index'] + 1} of {total}</b>: {escape(fmt_action(r['action']) + _chosen_by(r))}</div>"]
    if s is not None:
        facts = "; ".join(s["before"]["facts"]) or "no named fact holds"
        out.append(f"<div><b>before</b>{escape(_of_scene(s))}: {escape(facts)} ({len(s['before']['set'])} bits "
                   "set)</div>")
        if s["operator"] is None:
            out.append("<div>no learned operator grounds this action in these symbols</div>")
        else:
            out.append(f"<div><b>operator</b> {escape(s['operator'])}({escape(', '.join(s['binding']))}): effect "
                       f"{s['effect'] + 1} of {s['n_effects']}, p = {s['probability']:.2f}</div>")
            cell = 'style="padding:1px 6px;border-bottom:1px solid #ddd;text-align:left"'
            head = "".join(f"<th {cell}>{h}</th>" for h in ("bit", "before", "expected", "observed", "meaning"))
            rows = []
            for bit, before, e, o, meaning, bad in _bit_rows(s):
                style = f' style="{_MISMATCH}"' if bad else ""
                values = "".join(f"<td {cell}>{'-' if v is None else v}</td>" for v in (before, e, o))
                rows.append(f"<tr{style}><td {cell}>{escape(bit)}</td>{values}<td {cell}>{escape(meaning)}</td></tr>")
            if rows:
                out.append(f'<table style="border-collapse:collapse;margin:3px 0">{head}{"".join(rows)}</table>')
            else:
                out.append("<div>no bit expected or observed to change</div>")
            if not s["executed"]:
                out.append("<div><b>observed</b>: not executed</div>")
            elif s["match"]:
                out.append('<div><b>observed</b>: <span style="color:#1e8449">the expected symbols</span></div>')
            else:
                allowed = "" if s["observed_effect"] is None else f"; {escape(_allowed(s))}"
                out.append(f'<div><b>observed</b>: <span style="{_MISMATCH}">MISMATCH in '
                           f"{len(s['mismatches'])} bit(s)</span> (red rows{allowed})</div>")
    if m is not None:
        out.append(f"<div><b>motion</b>: {escape(format_motion(m))}</div>")
    if r["dynamics_error_m"] is not None:
        out.append(f"<div><b>Dynamics Model</b>: {r['dynamics_error_m'] * 100:.1f} cm off (mean over blocks)</div>")
    return "\n".join(out)


def panel_entries(records: Sequence[dict], t_end: float) -> list[tuple[float, str]]:
    """The replay panel's entries: the symbols before the first step from t = 0, then each step from
    the time its motion begins (a step whose arm never moved: from the end of the replay)."""
    from html import escape

    if not records:
        return []
    first = records[0]["symbols"]
    intro = "<div><b>before step 1</b></div>"
    if first is not None:
        intro += f"<div>{escape('; '.join(first['before']['facts']) or 'no named fact holds')} " \
                 f"({len(first['before']['set'])} bits set)</div>"
    entries = [(0.0, intro)]
    for r in records:
        t = r["t_start"] if r["t_start"] is not None else t_end
        entries.append((float(t), step_panel_html(r, len(records))))
    return entries
