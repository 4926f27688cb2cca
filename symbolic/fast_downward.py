"""Fast Downward from the `up-fast-downward` wheel, called as a subprocess (no unified-planning).

Every call runs in its own temporary directory with explicit ``--plan-file`` and ``--sas-file``,
so parallel calls never see each other's files; the directory is removed afterwards (never any
cleanup by process name). Outcomes are typed (`PlannerStatus`): SOLVED, UNSOLVABLE (translator or
search proved no plan exists), TIMEOUT (time limit) and CRASHED (anything else, with the exit code
and the planner's stderr tail in the message). `raise_for_status` turns them into exceptions.

Besides the full driver (`run_fast_downward`) there is a split use for many domains over the same
objects: `translate` once, then `SasTask.restrict` + `run_search` (the search binary alone, ~5 ms).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from symbolic.structs import PlannerResult, PlannerStatus, PlanStep


def _find_fd() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("up_fast_downward")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("up-fast-downward is not installed (pip install up-fast-downward)")
    return Path(list(spec.submodule_search_locations)[0]) / "downward"


FD_DIR = _find_fd()
DRIVER = FD_DIR / "fast-downward.py"
SEARCH_BIN = FD_DIR / "builds" / "release" / "bin" / "downward"
DEFAULT_SEARCH = "astar(lmcut())"
# Aliases the search binary understands only in expanded form (copied from the driver's aliases.py).
ALIASES = {
    "lama-first": "let(hlm, eval_modify_costs(landmark_sum(lm_factory=lm_reasonable_orders_hps(lm_rhw()),"
                  "pref=false),cost_type=one),let(hff, eval_modify_costs(ff(),cost_type=one),"
                  "lazy_greedy([hff,hlm],preferred=[hff,hlm],cost_type=one,reopen_closed=false)))",
}
UNSOLVABLE_CODES = {10: "translator proved the task unsolvable", 11: "search proved the task unsolvable",
                    12: "search space exhausted (incomplete search)", 13: "unsolvable within bound"}
TIMEOUT_CODES = {21, 23, 24, -signal.SIGXCPU, 256 - signal.SIGXCPU}  # SIGXCPU: a CPU-time rlimit hit
PLAN_FOUND_CODES = {0, 1, 2, 3}


class PlannerError(RuntimeError):
    def __init__(self, result: PlannerResult):
        super().__init__(result.message)
        self.result = result


class PlannerUnsolvable(PlannerError):
    pass


class PlannerTimeout(PlannerError):
    pass


class PlannerCrashed(PlannerError):
    pass


def raise_for_status(result: PlannerResult) -> PlannerResult:
    """Return a solved result unchanged; raise the exception matching any other outcome."""
    exc = {PlannerStatus.UNSOLVABLE: PlannerUnsolvable, PlannerStatus.TIMEOUT: PlannerTimeout,
           PlannerStatus.CRASHED: PlannerCrashed}.get(result.status)
    if exc is not None:
        raise exc(result)
    return result


_STEP = re.compile(r"^\(\s*([^\s()]+)((?:\s+[^\s()]+)*)\s*\)$")


def parse_plan(text: str) -> list[PlanStep]:
    """Fast Downward plan file -> [(operator name, (objects...))]; comment lines are skipped."""
    steps = []
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith(";"):
            continue
        m = _STEP.match(line)
        if m is None:
            raise ValueError(f"malformed plan line {line!r}")
        steps.append((m.group(1).lower(), tuple(m.group(2).lower().split())))
    return steps


def _tail(text: str, lines: int = 15) -> str:
    return "\n".join(text.strip().splitlines()[-lines:])


def _run(cmd: list[str], cwd: str, time_limit: float | None, stdin_path: str | None = None):
    """Run in its own process group; on timeout kill exactly that group. -> (rc or None, out, err, s)."""
    start = time.perf_counter()
    stdin = open(stdin_path, "rb") if stdin_path else subprocess.DEVNULL
    try:
        proc = subprocess.Popen(cmd, cwd=cwd, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                start_new_session=True)
        try:
            out, err = proc.communicate(timeout=time_limit)
            rc: int | None = proc.returncode
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            rc = None
    finally:
        if not isinstance(stdin, int):  # a file we opened, not DEVNULL
            stdin.close()
    return rc, out.decode(errors="replace"), err.decode(errors="replace"), time.perf_counter() - start


def _result(rc: int | None, out: str, err: str, wall: float, plan_file: Path, what: str,
            time_limit: float | None) -> PlannerResult:
    tail = _tail(err) or _tail(out)
    if rc is None:
        return PlannerResult(PlannerStatus.TIMEOUT, None, f"{what}: killed after the {time_limit} s time limit",
                             wall, None, tail)
    if rc in PLAN_FOUND_CODES and plan_file.exists():
        return PlannerResult(PlannerStatus.SOLVED, parse_plan(plan_file.read_text()), f"{what}: plan found",
                             wall, rc, tail)
    if rc in UNSOLVABLE_CODES:
        return PlannerResult(PlannerStatus.UNSOLVABLE, None, f"{what}: {UNSOLVABLE_CODES[rc]}", wall, rc, tail)
    if rc in TIMEOUT_CODES:
        return PlannerResult(PlannerStatus.TIMEOUT, None, f"{what}: out of time (exit code {rc})", wall, rc, tail)
    return PlannerResult(PlannerStatus.CRASHED, None,
                         f"{what}: crashed with exit code {rc}; stderr tail:\n{tail}", wall, rc, tail)


def _search_args(search: str) -> list[str]:
    return ["--search", ALIASES.get(search, search)]


def run_fast_downward(domain: str, problem: str, search: str = DEFAULT_SEARCH,
                      time_limit: float | None = 30.0, keep_dir: str | Path | None = None) -> PlannerResult:
    """Translate + search one PDDL task given as text. `search` is an alias (lama-first) or a
    search string such as ``astar(lmcut())``. keep_dir: copy the work files there (debugging)."""
    with tempfile.TemporaryDirectory(prefix="fd-") as tmp:
        d = Path(tmp)
        (d / "domain.pddl").write_text(domain)
        (d / "problem.pddl").write_text(problem)
        cmd = [sys.executable, str(DRIVER), "--plan-file", str(d / "plan"), "--sas-file", str(d / "output.sas")]
        if time_limit is not None:
            cmd += ["--overall-time-limit", f"{max(1, int(time_limit + 0.999))}s"]
        cmd += [str(d / "domain.pddl"), str(d / "problem.pddl")] + _search_args(search)
        limit = None if time_limit is None else time_limit + 5.0  # the driver's own limit comes first
        rc, out, err, wall = _run(cmd, tmp, limit)
        result = _result(rc, out, err, wall, d / "plan", "fast-downward", time_limit)
        if keep_dir is not None:
            import shutil
            shutil.copytree(d, keep_dir, dirs_exist_ok=True)
        return result


def translate(domain: str, problem: str, time_limit: float | None = 60.0) -> str:
    """Run only the translator; returns the SAS text. Raises PlannerUnsolvable / PlannerCrashed /
    PlannerTimeout."""
    with tempfile.TemporaryDirectory(prefix="fd-translate-") as tmp:
        d = Path(tmp)
        (d / "domain.pddl").write_text(domain)
        (d / "problem.pddl").write_text(problem)
        cmd = [sys.executable, str(DRIVER), "--translate", "--sas-file", str(d / "output.sas"),
               str(d / "domain.pddl"), str(d / "problem.pddl")]
        rc, out, err, wall = _run(cmd, tmp, time_limit)
        if rc == 0 and (d / "output.sas").exists():
            return (d / "output.sas").read_text()
        raise_for_status(_result(rc if rc != 0 else -1, out, err, wall, d / "missing", "translate", time_limit))
        raise AssertionError("unreachable")


class SasTask:
    """A translated SAS task split into operator blocks, to be restricted to subsets of operators."""

    def __init__(self, sas: str):
        head, sep, rest = sas.partition("end_goal\n")
        count_line, _, rest = rest.partition("\n")
        blocks = rest.split("end_operator\n")
        if not sep or len(blocks) - 1 != int(count_line):
            raise ValueError("unexpected SAS layout")
        self.head = head + sep
        self.blocks = [b + "end_operator\n" for b in blocks[:-1]]
        self.tail = blocks[-1]
        self.names = [b.split("\n", 2)[1] for b in self.blocks]  # "name arg1 arg2 ..."

    def restrict(self, keep) -> str:
        """SAS text with the operators whose index i has keep[i] true."""
        kept = [b for b, k in zip(self.blocks, keep) if k]
        return self.head + f"{len(kept)}\n" + "".join(kept) + self.tail


def run_search(sas: str, search: str = DEFAULT_SEARCH, time_limit: float | None = 30.0) -> PlannerResult:
    """Run the search binary alone on a SAS task given as text."""
    with tempfile.TemporaryDirectory(prefix="fd-search-") as tmp:
        d = Path(tmp)
        (d / "output.sas").write_text(sas)
        cmd = [str(SEARCH_BIN)] + _search_args(search) + ["--internal-plan-file", str(d / "plan")]
        rc, out, err, wall = _run(cmd, tmp, time_limit, stdin_path=str(d / "output.sas"))
        return _result(rc, out, err, wall, d / "plan", "fast-downward search", time_limit)
