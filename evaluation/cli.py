"""`tamp problems`, `tamp evaluate` and `tamp report` (registered through the `tamp.commands` entry point)."""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from evaluation.methods import methods_help
from tamp.app.args import (
    WORKERS_LIMIT,
    Count,
    check_output_dir,
    check_output_file,
    int_list,
    models_directory,
    seed,
)
from tamp.app.faults import add_fault_arguments, faults_of
from tamp.app.parallel import add_arguments as add_parallel_arguments
from tamp.app.plan_command import add_max_actions_argument
from tamp.app.problem import PROTOCOLS
from tamp.app.settings import add_config_arguments
from tamp.errors import UserError
from tamp.planning.config import SYMBOLIC_BACKENDS, symbolic_backend_help
from tamp.sim.world_types import FIDELITIES


def _name_list(text: str) -> list[str]:
    names = [v.strip() for v in text.split(",") if v.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected method names like bilevel,cfs, got {text!r}")
    return names


def cmd_problems(args: argparse.Namespace) -> int:
    """Generate a problem set (JSONL) of random Drake scenes and goals."""
    from evaluation.problems import generate_problems, write_problems
    check_output_file(args.out, "--out")
    problems = generate_problems(args.objects, args.actions, args.per_cell, args.seed, progress=not args.quiet,
                                 protocol=args.protocol, runs=args.runs, workers=args.workers)
    path = write_problems(args.out, problems)
    last = args.seed + args.runs - 1
    seeds = f"seed {args.seed}" if args.runs == 1 else f"{args.runs} runs, seeds {args.seed}..{last}"
    moved = sum(p.moved for p in problems if p.moved is not None)  # generated problems all count it
    print(f"wrote {len(problems)} problems to {path} (objects {','.join(map(str, args.objects))}, actions "
          f"{','.join(map(str, args.actions))}, {args.per_cell} per cell, {seeds}, {args.protocol} protocol: "
          f"{moved} of {sum(p.k for p in problems if p.k is not None)} actions moved a block)")
    return 0


def _write_report(directory: Path, ablation: Path | None = None) -> Path:
    from evaluation.report import write_report

    return write_report(directory, ablation=ablation)


def _eval_config(args: argparse.Namespace):
    """The EvalConfig of the flags of `_add_run_arguments` (`tamp evaluate`, `tamp refinability`)."""
    from evaluation.configuration import EvalConfig
    from evaluation.methods import METHODS
    from tamp.app.settings import settings_of
    from tamp.planning.vocabulary import Loop

    if args.max_actions is not None and args.methods is not None and not any(
            m in METHODS and METHODS[m].loop == Loop.UNTIL_GOAL for m in args.methods):
        raise UserError(f"--max-actions sets the loop that runs until the goal (bilevel_loop); none of the methods "
                        f"({', '.join(args.methods)}) runs it")
    faults, settings = faults_of(args), settings_of(args)
    cameras = settings.perception.cameras_on  # the closed loops observe through the camera rig
    planner = replace(settings.planner, loop=faults.known_to(settings.planner.loop, cameras))  # it knows its noise
    return EvalConfig(planner=planner, fidelity=args.fidelity, workers=args.workers,
                      backend=args.backend, address=args.address,
                      oracle_max_plans=settings.evaluation.oracle_max_plans, progress=not args.quiet, faults=faults,
                      perception=settings.perception)


def _add_run_arguments(p: argparse.ArgumentParser, models_help: str, out_help: str, methods_default,
                       methods_help: str) -> None:
    """The flags of a command that runs methods on a problem set (`tamp evaluate`, `tamp refinability`)."""
    p.add_argument("--models", type=models_directory, required=True, help=models_help)
    p.add_argument("--problems", type=Path, required=True, help="problem set (tamp problems --out)")
    p.add_argument("--out", type=Path, required=True, help=out_help)
    p.add_argument("--methods", type=_name_list, default=methods_default, help=methods_help)
    p.add_argument("--fidelity", choices=FIDELITIES, default="fast",
                   help="execute in the fast world (default) or with the arm under physics")
    add_parallel_arguments(p, workers_default=1)
    add_fault_arguments(p, "closed loops")
    add_max_actions_argument(p, "bilevel_loop")
    add_config_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Every method on every problem: plan, refine, execute; rows to OUT/rows.jsonl, then the report."""
    from evaluation.run import evaluate, read_rows

    rows_path = evaluate(args.models, args.problems, args.out, args.methods, _eval_config(args))
    rows = read_rows(rows_path)
    print(f"{len(rows)} rows in {rows_path}: {sum(r['success'] for r in rows)} successes")
    if args.no_report:
        return 0
    try:
        report = _write_report(args.out)
    except Exception as error:  # the rows are safe; the report can be written later with `tamp report`
        print(f"tamp evaluate: warning: no report ({type(error).__name__}: {error}); the rows are complete, "
              f"run `tamp report {args.out}` to try again", file=sys.stderr)
        return 0
    print(f"report written to {report}")
    return 0


def cmd_refinability(args: argparse.Namespace) -> int:
    """Per learned operator: used, kinematically feasible, refined, symbolic effect realised."""
    from evaluation import refinability
    from evaluation.row import ERROR_OUTCOME
    from evaluation.run import evaluate, read_rows

    rows = read_rows(evaluate(args.models, args.problems, args.out, args.methods, _eval_config(args)))
    rows = [r for r in rows if r["outcome"] != ERROR_OUTCOME and r["method"] in args.methods]
    if not any(r.get("steps") for r in rows):
        raise UserError(f"{args.out}: no row has per-step records (the models need a Symbolic Model and its "
                        "domain, and the planners must have executed something)")
    paths = refinability.write(rows, args.out)
    def pct(value: float | None) -> str:
        return "—" if value is None else f"{value:.1f}"

    for f in refinability.fidelity_by_method(rows):
        print(f"{f['method']}: {f['judged']} executed steps with an operator, {pct(f['as_expected_pct'])} % as "
              f"expected; of the {f['accurate']} within 1 cm of the prediction, {pct(f['accurate_as_expected_pct'])} "
              f"% as expected and {pct(f['accurate_allowed_pct'])} % one of the operator's effects")
    print("written " + ", ".join(str(p) for p in paths))
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Tables, figures and significance tests from a results directory."""
    if not (args.directory / "rows.jsonl").is_file():
        raise UserError(f"no rows.jsonl in {args.directory} (the --out directory of `tamp evaluate`)")
    if args.ablation is not None and not args.ablation.is_file():
        raise UserError(f"no ablation file at {args.ablation}")
    print(f"report written to {_write_report(args.directory, args.ablation)}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    """Two evaluations of the same problems, paired: success, p, planning time, gained and lost."""
    from .compare import compare_markdown, compare_numbers, load_rows

    for d in (args.before, args.after):
        if not d.is_dir():
            raise UserError(f"no results directory at {d} (the --out directory of `tamp evaluate`)")
    numbers = compare_numbers(load_rows(args.before), load_rows(args.after))
    if not numbers["pairs"]:
        raise UserError(f"{args.before} and {args.after} share no (problem, run, method) row without an error: "
                        "evaluate the same problem set with the same methods")
    text = compare_markdown(numbers, str(args.before), str(args.after))
    if args.out is not None:
        from tamp.records import atomic_write_text

        atomic_write_text(args.out, text)
        print(f"comparison written to {args.out}")
    else:
        print(text, end="")
    return 0


def cmd_pool(args: argparse.Namespace) -> int:
    """Several evaluations as one results directory, one run per problem set."""
    from .pool import pool

    check_output_dir(args.out, "OUT")
    report = pool(args.out, args.sources)
    for r in report.runs:
        runs = ", ".join(f"{old} -> {new}" for old, new in r["runs"].items())
        print(f"{r['source']}: {r['rows']} rows, run {runs}")
    print(f"{report.rows} rows pooled in {report.out}; `tamp report {report.out}` reports them together")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add this package's subcommands to the `tamp` parser."""
    p = sub.add_parser(
        "problems",
        help="a problem set: random Drake scenes and the goals after k random actions (JSONL)",
        description="Generate --per-cell problems for every object count and every number of random "
        "actions: a random scene, then k random actions simulated in the fast Drake world give the goal. "
        "--protocol strict (default) redraws actions that fail or move nothing, so every one of the k "
        "moves a block; --protocol paper keeps every drawn action whatever its outcome, as the paper's "
        "authors do (an action that moves nothing changes nothing, so a k = 1 goal can equal the initial "
        "scene). Each "
        "line of --out is a `tamp plan --problem` object with its name (n{n}-k{k}-{i}, or r{run}-n{n}-k{k}-{i} "
        "with --runs), seed, generating actions and how many of them moved a block; the same arguments "
        "give the same file, byte for byte, for any number of workers.",
    )
    p.add_argument("--out", type=Path, required=True, help="problem set file to write (JSONL)")
    p.add_argument("--objects", type=int_list, default=(2, 3, 4), help="object counts (default 2,3,4)")
    p.add_argument("--actions", type=int_list, default=(1, 2, 3, 4, 5),
                   help="numbers k of random actions per goal (default 1,2,3,4,5)")
    p.add_argument("--per-cell", type=Count(1, 100_000), default=10, help="problems per (objects, k) (default 10)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the set (default 0); run j uses seed + j")
    p.add_argument("--protocol", choices=PROTOCOLS, default="strict",
                   help="strict: every action moves something (default); paper: actions kept whatever their "
                   "outcome, as the paper's authors do")
    p.add_argument("--runs", type=Count(1, 1000), default=1,
                   help="problem sets of seeds seed, seed + 1, ... in one file, for mean ± std over runs (default 1)")
    p.add_argument("--workers", type=Count(1, WORKERS_LIMIT), default=1, help="worker processes (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_problems)

    p = sub.add_parser(
        "evaluate",
        help="every method on every problem of a set: plan, refine, execute in Drake; rows + report",
        description="For each (problem, method): plan with the learned models (planning timed alone), "
        "refine the plan (IK, collision-checked motions, grasps) and execute it in the Drake world, or "
        "plan and execute in closed loop. One JSON row per pair is appended to OUT/rows.jsonl as it finishes; "
        "running the same command again resumes. A problem set with several runs (tamp problems --runs) is "
        "reported as mean ± std over its runs. Methods (the defaults, and the Fig. 4 variants when "
        "DIR/variants/ holds their models): " + methods_help() + ".",
    )
    _add_run_arguments(p, "models directory: symbolic.pt, dynamics.pt, domain/ (and optionally variants/)",
                       "results directory (new, or the one to resume)", None,
                       "comma-separated methods (default: all available)")
    p.add_argument("--no-report", action="store_true", help="write the rows only (tamp report makes the report)")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser(
        "refinability",
        help="per learned operator: how often plans use it, pass the kinematic check, refine, and realise its effect",
        description="Evaluate the methods on a problem set as `tamp evaluate` does (OUT is a results directory: "
        "the rows are resumed, not recomputed), then, for each learned operator the executed plans used: how "
        "often; how often its actions passed the planners' kinematic check and refined into IK and "
        "collision-free motions; of the executed ones, how often the symbols read after the step equal the ones "
        "the operator expected (and are one of its learned effects); the Dynamics Model's mean position error. "
        "Writes OUT/refinability.md (fidelity per method, the operator table, the ten least faithful "
        "operators with an example each), OUT/refinability.csv (every operator) and "
        "OUT/figures/refinability.png.",
    )
    _add_run_arguments(p, "models directory: symbolic.pt, dynamics.pt, domain/",
                       "results directory (new, or a `tamp evaluate --out` to resume)",
                       ["cfs", "bilevel", "bilevel_replan"],
                       "comma-separated methods whose plans are studied (default cfs,bilevel,bilevel_replan)")
    p.set_defaults(func=cmd_refinability)

    p = sub.add_parser(
        "report",
        help="Markdown tables, PNG figures and paired t-tests from a results directory",
        description="Read DIR/rows.jsonl (tamp evaluate --out DIR) and write DIR/report.md with the "
        "paper's tables, the figures and paired t-tests.",
    )
    p.add_argument("directory", type=Path, help="results directory (tamp evaluate --out)")
    p.add_argument("--ablation", type=Path, default=None,
                   help="ablation results to include (tamp ablate-activations output)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser(
        "compare",
        help="before and after: two results directories of the same problems, paired per problem",
        description="Pair the rows of two `tamp evaluate` results directories by (problem, run, method) and "
        "print, per method and number of blocks, success before -> after with a paired t-test, planning time "
        "(median / mean) before -> after, and the problems gained and lost. Rows only one side holds are "
        "counted and left out. Reads rows.jsonl, or the rows.jsonl.gz that results/ ships.",
    )
    p.add_argument("before", type=Path, help="results directory of the baseline (tamp evaluate --out)")
    p.add_argument("after", type=Path, help="results directory of the change, on the same problem set")
    p.add_argument("--out", type=Path, default=None, help="write the Markdown here instead of printing it")
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser(
        "pool",
        help="several evaluations (e.g. two seeds' problem sets) as one results directory, one run per set",
        description="Pool the rows of `tamp evaluate` results directories made with the same models and "
        "settings (checked in their meta.json) into OUT: the sources' runs become runs 0, 1, ... in the order "
        "given, and each problem is named r{run}-NAME, as `tamp problems --runs` names them. `tamp report OUT` "
        "then gives every table over all the sets, with mean ± std over runs; `tamp compare` pairs two pooled "
        "directories made from the same problem sets in the same order. Reads rows.jsonl or rows.jsonl.gz; "
        "writes OUT/rows.jsonl and OUT/meta.json, never over existing ones.",
    )
    p.add_argument("out", type=Path, metavar="OUT", help="new results directory for the pooled rows")
    p.add_argument("sources", type=Path, nargs="+", metavar="RESULTS_DIR",
                   help="two or more --out directories of `tamp evaluate` (or shipped results folders)")
    p.set_defaults(func=cmd_pool)

    p = sub.add_parser(
        "reproduce",
        help="the paper's experiments end to end: collect, train, domains, problems, evaluate, report",
        description="Run every stage into --out: collect interaction data, train the Dynamics and "
        "Symbolic Models and the two Fig. 4 variants (with the Table I ablation alongside), learn the "
        "domains, generate the problem set, evaluate every method in the Drake world and write "
        "OUT/results/report.md. Stages that finished are skipped when the command is run again, so an "
        "interrupted run resumes. --scale quick (the default) runs every stage small (40k samples, 250 "
        "epochs, 10 problems per cell), to check the whole pipeline; --scale paper is the "
        "paper's size (160k samples, 4000 epochs, 100 problems per cell) for bigger machines or Ray. "
        "With --models DIR only the problems, the evaluation and the report are made, for DIR's models "
        "(e.g. `--models paper --protocol paper --runs 3`: the bundled paper set, the paper's protocol, three runs).",
    )
    p.add_argument("--scale", choices=("quick", "paper"), default="quick", help="sizes (default quick)")
    p.add_argument("--out", type=Path, required=True, help="output directory (new, or the one to resume)")
    add_parallel_arguments(p)
    p.add_argument("--fidelity", choices=FIDELITIES, default="fast",
                   help="execute the plans in the fast world (default) or with the arm under physics")
    p.add_argument("--protocol", choices=PROTOCOLS, default="strict",
                   help="problem sets: strict (every random action moves something, default) or paper (actions "
                   "kept whatever their outcome, as the paper's authors do)")
    p.add_argument("--runs", type=Count(1, 1000), default=1,
                   help="problem sets of consecutive seeds, reported as mean ± std over runs "
                        "(default 1; the paper: 10)")
    p.add_argument("--models", type=models_directory, default=None,
                   help="evaluate this models directory, or a bundled set (paper: the paper's configuration), "
                        "instead of collecting and training")
    p.add_argument("--symbolic-backend", choices=tuple(SYMBOLIC_BACKENDS), default="python",
                   help=symbolic_backend_help("python"))
    p.set_defaults(func=cmd_reproduce)

    from evaluation.practice import add_practice

    add_practice(sub)


def cmd_reproduce(args: argparse.Namespace) -> int:
    """Every stage of the paper's experiments, resumable."""
    from evaluation.reproduce import TrainingUnfinished, reproduce

    try:
        report = reproduce(args.out, args.scale, workers=args.workers, backend=args.backend, fidelity=args.fidelity,
                           protocol=args.protocol, runs=args.runs, models=args.models,
                           symbolic_backend=args.symbolic_backend, address=args.address)
    except TrainingUnfinished as e:
        print(f"unfinished: {e}", file=sys.stderr)
        return 3
    print(f"report written to {report}")
    return 0
