"""Ctrl-C at any moment of `tamp evaluate --workers 2`: exit 130, no traceback and no warning from any
process, the rows intact, and a resumed run ends with the rows of an uninterrupted one.

Runs `tamp evaluate` in its own process group and sends SIGINT to the whole group, as a terminal's
Ctrl-C does, at each given time; then resumes the same --out to the end and compares its rows with
those of one uninterrupted run (timings left out). Prints one line per time and exits 1 if any fails.

    .venv/bin/python bench/interrupt_evaluate.py --at 1,3,10,30
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from evaluation.run import read_rows, strip_timings

TAMP = str(Path(sys.executable).with_name("tamp"))


def evaluate(problems: Path, out: Path, methods: str, interrupt_at: float | None = None) -> tuple[int, str]:
    """Run `tamp evaluate` (SIGINT to its process group after `interrupt_at` s); (exit code, stderr)."""
    command = [TAMP, "evaluate", "--models", "pretrained", "--problems", str(problems), "--out", str(out),
               "--methods", methods, "--workers", "2", "--quiet", "--no-report"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    if interrupt_at is not None:
        try:
            process.wait(timeout=interrupt_at)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=600)
    return process.returncode, err


def rows(out: Path) -> list[dict]:
    return sorted((strip_timings(r) for r in read_rows(out / "rows.jsonl")), key=lambda r: (r["problem"], r["method"]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--at", default="1,3,10,30", help="seconds after the start to send SIGINT (default 1,3,10,30)")
    parser.add_argument("--methods", default="cfs,bilevel", help="methods evaluated (default cfs,bilevel)")
    parser.add_argument("--per-cell", type=int, default=2, help="problems per (n, k) of n = 2, 3 and k = 1, 2")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        problems = work / "problems.jsonl"
        subprocess.run([TAMP, "problems", "--objects", "2,3", "--actions", "1,2", "--per-cell", str(args.per_cell),
                        "--out", str(problems), "--quiet"], check=True, stdout=subprocess.DEVNULL)
        t = time.perf_counter()
        code, err = evaluate(problems, work / "whole", args.methods)
        assert code == 0, err
        whole = rows(work / "whole")
        print(f"uninterrupted: {len(whole)} rows in {time.perf_counter() - t:.0f} s")
        failed = False
        for at in (float(v) for v in args.at.split(",")):
            out = work / f"at-{at:g}"
            code, err = evaluate(problems, out, args.methods, interrupt_at=at)
            written = len(read_rows(out / "rows.jsonl")) if (out / "rows.jsonl").exists() else 0
            # the one line expected: the command's, or `tamp`'s while the command's modules still load
            noise = [line for line in err.splitlines()
                     if line.strip() and line.strip() not in ("tamp evaluate: interrupted", "tamp: interrupted")]
            resumed, err2 = evaluate(problems, out, args.methods)
            same = resumed == 0 and rows(out) == whole
            ok = code in (0, 130) and not noise and same
            failed |= not ok
            print(f"SIGINT at {at:g} s: exit {code}, {written} rows kept, stderr {err.strip()!r}"
                  f"{' + ' + repr(noise[:2]) if noise else ''}; resumed: exit {resumed}, rows identical to the "
                  f"uninterrupted run: {same}{'' if ok else '  <- FAILED'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
