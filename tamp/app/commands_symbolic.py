"""`tamp domain`, `tamp pddl` and `tamp symbols`: the learned symbolic domain and what its bits mean."""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from guarded import atomic_write_text, dumps
from tamp.app.args import (
    MAX_DOMAINS,
    Count,
    check_output_dir,
    check_output_file,
    fraction,
    models_directory,
    non_negative_int,
    positive_int,
    probability,
    seed,
)
from tamp.errors import UserError


def cmd_symbols(args: argparse.Namespace) -> int:
    """What each learned bit of a Symbolic Model means, on held-out scenes."""
    from learned import load_model
    from learned.interpret import format_symbols_markdown, interpret_symbols, summarize_symbols, write_symbols_png

    for path, flag in ((args.json, "--json"), (args.png, "--png")):
        if path is not None:
            check_output_file(path, flag)
    model = load_model(args.model)
    scenes = symbol_scenes(args.problems, args.data, args.max_scenes, args.seed)
    report = interpret_symbols(model.symbols, scenes)
    pairs = list(zip(scenes[0::2], scenes[1::2])) if args.problems is not None else []
    cfg = model.config
    given = ([f"u{cfg.d_z}"] if cfg.type_symbol else []) + \
        ([f"r{k}(i,i)" for k in range(cfg.heads)] if cfg.relations == "pairwise" else [])
    summary = summarize_symbols(report, model.symbols, pairs, given)
    print(f"{args.model}: d_z = {cfg.d_z} learned unary bit(s)"
          + (f" and the given type as u{cfg.d_z}" if cfg.type_symbol else "")
          + f", K = {cfg.heads} {cfg.relations} relation(s), read on {len(scenes)} scenes of "
          f"{args.problems or args.data}")
    print(format_symbols_markdown(report))
    print("\n".join(summary.lines()))
    if args.json is not None:
        atomic_write_text(args.json, dumps([b.to_dict() for b in report], indent=1) + "\n")
        print(f"written {args.json}")
    if args.png is not None:
        write_symbols_png(report, args.png)
        print(f"written {args.png}")
    return 0


def symbol_scenes(problems: Path | None, data: Path | None, max_scenes: int, seed: int = 0) -> list[np.ndarray]:
    """Scenes to read symbols on: X_init and X_goal of a problem set, or (at most `max_scenes`,
    drawn with `seed`) the states of a dataset's transitions."""
    if (problems is None) == (data is None):
        raise UserError("give exactly one of --problems (a problem set) or --data (a dataset directory)")
    if problems is not None:
        from tamp.app.problem import read_problem_set

        return [X for p in read_problem_set(problems) for X in (p.X_init, p.X_goal)][:max_scenes]
    from learned import load_transitions

    assert data is not None  # exactly one of problems and data (checked above)
    t = load_transitions(data)
    if len(t) == 0:
        raise UserError(f"{data}: the dataset holds no transitions")
    pick = np.random.default_rng(seed).permutation(len(t))[:max_scenes]
    return [t.X[i, :int(t.n[i])] for i in sorted(pick)]


def cmd_domain(args: argparse.Namespace) -> int:
    """Symbols from the Symbolic Model -> learned PDDL / PPDDL domain and its statistics."""
    from tamp.planning.domain import learn_domain

    check_output_dir(args.out, "--out")
    if args.core_from_all and not args.involved_only:
        raise UserError("--core-from-all needs --involved-only (it adds operators of the picked and target objects)")
    from tamp.records import output_dir

    with output_dir(args.out, "--out", own=("operators.json", "stats.json", "domain.pddl")):
        report = learn_domain(args.model, args.data, args.out, holdout=args.holdout, seed=args.seed,
                              sampled_domains=args.sampled, involved_only=args.involved_only,
                              min_count=args.min_count, min_prob=args.min_prob, only_moved=args.only_moved,
                              any_bottleneck=args.any_bottleneck, max_arity=args.max_arity,
                              core_from_all=args.core_from_all, general_bystanders=args.general_bystanders)
    held = report.get("coverage_holdout") or {}
    general = f" ({report['n_general']} general)" if args.general_bystanders else ""
    print(f"{report['n_operators']} operators{general} from {report['transitions']} transitions -> {args.out}")
    left_out = report["max_arity"]["transitions_left_out"]
    if left_out:
        print(f"  {left_out} training transitions involve more than {report['max_arity']['limit']} objects "
              "(the most the lifted search takes): no operator learned from them")
    for key in ("effects_per_operator", "coverage_train"):
        if key in report:
            print(f"  {key}: {json.dumps(report[key])}")
    print(f"  coverage_holdout: {json.dumps(held)}")
    return 0


def cmd_pddl(args: argparse.Namespace) -> int:
    """A models directory's learned domain (and a problem's symbols) as PDDL files."""
    from tamp.app.problem import load_problem
    from tamp.planning.models import load_models, pretrained_dir

    check_output_dir(args.out, "--out")
    models_dir = args.models or pretrained_dir()
    problem = None if args.problem is None else load_problem(args.problem)
    if problem is not None:  # every model the problem needs is checked before a file is written
        load_models(models_dir).require_objects(problem.n, str(args.problem))
    paths = staged_export(models_dir, args.out, problem, args)
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    return 0


PDDL_OUTPUTS = ("domain.pddl", "domain.ppddl", "problem.pddl", "sampled")  # what `tamp pddl` writes in --out


def staged_export(models_dir: Path, out: Path, problem, args: argparse.Namespace) -> dict[str, Path]:
    """`export_pddl` into a staging folder beside `out`, moved into `out` once every file is written: a
    failure (a full disk, a model that cannot be read) leaves `out` as it was and no staging behind."""
    import shutil

    from guarded import OutputError
    from tamp.planning.domain import export_pddl
    from tamp.records import made_by_tool, output_dir

    foreign = [out / name for name in PDDL_OUTPUTS if (out / name).is_dir() and not made_by_tool(out)]
    if foreign and args.sampled > 0:  # a folder there is replaced only when the tool made the folder around it
        raise UserError(f"--out {out}: {foreign[0]} is a folder the tool did not make; give another --out")
    staging = out.parent / f".{out.name}.staging-{os.getpid()}"
    try:
        with output_dir(out, "--out", own=PDDL_OUTPUTS):
            try:
                made = export_pddl(models_dir, staging, None if problem is None else problem.X_init,
                                   None if problem is None else problem.X_goal,
                                   problem_name=(problem.name or args.problem.stem) if problem is not None
                                   else "symbolic-task", sampled=args.sampled, seed=args.seed)
            except OSError as error:
                raise OutputError(f"cannot write {out}: {error.strerror or error}") from None
            paths = {}
            for kind, path in made.items():
                target = out / path.relative_to(staging)
                if target.is_dir() and not target.is_symlink():  # a folder of the tool's (checked above)
                    shutil.rmtree(target)
                os.replace(path, target)
                paths[kind] = target
            return paths
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def add_domain(sub) -> None:
    """`tamp domain`."""
    p = sub.add_parser(
        "domain",
        help="learned symbolic domain (PDDL, PPDDL, operators.json) from a Symbolic Model and data",
        description="Compute the Symbolic Model's unary and relational bits before and after every "
        "transition, learn lifted operators (most frequent effect and the empirical distribution), "
        "and write domain.pddl, domain.ppddl, operators.json and stats.json (number of operators, "
        "effects per operator, coverage on held-out transitions). `tamp pddl` writes the PDDL files of an "
        "existing models directory (the bundled one by default) and of a problem.",
    )
    p.add_argument("--model", required=True, help="Symbolic Model checkpoint (tamp train --bottleneck gumbel_sigmoid)")
    p.add_argument("--data", required=True, nargs="+", metavar="DIR",
                   help="dataset directory, or several (learned from together)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--holdout", type=fraction, default=0.1, help="fraction of transitions held out for coverage")
    p.add_argument("--sampled", type=Count(0, MAX_DOMAINS), default=0, metavar="N",
                   help="also write N sampled PDDL domains")
    p.add_argument("--involved-only", action="store_true",
                   help="operators mention only the objects a transition involves (picked, target, and "
                   "those whose symbols change) rather than every object in the scene: far fewer operators")
    p.add_argument("--core-from-all", action="store_true",
                   help="with --involved-only: every transition also teaches the operator of its picked and target "
                   "objects alone, other objects' changes ignored there; without it that operator holds only the "
                   "transitions that disturbed nothing else (mostly failed picks) and expects nothing to happen")
    p.add_argument("--general-bystanders", action="store_true",
                   help="an operator does not test its bystanders' own bits (where on the table they stand, "
                   "their type) or the relations among them, when its transitions left those bits alone: what "
                   "a step does to a block beside the moved ones depends on where it stands relative to them. "
                   "Fewer operators, and pre-states no transition showed are still covered")
    p.add_argument("--only-moved", action="store_true",
                   help="learn from the transitions that moved their picked block (failed grasps and blocked "
                   "motions left out, as the paper's authors do)")
    p.add_argument("--min-count", type=non_negative_int, default=0, metavar="N",
                   help="keep operators seen at least N times (default 0: all; the paper's authors: 51)")
    p.add_argument("--max-arity", type=Count(1, 16), default=None, metavar="A",
                   help="learn no operator from a transition that involves more than A objects (default: the "
                   "most the lifted search takes, 4 with 1 unary bit and 3 relations; larger ones are refused "
                   "by the planner)")
    p.add_argument("--min-prob", type=probability, default=0.0, metavar="P",
                   help="drop effects of probability below P and renormalise (default 0; the paper's authors: 0.1)")
    p.add_argument("--any-bottleneck", action="store_true",
                   help="accept a --model that is not a Symbolic Model (e.g. the Fig. 4 Sigmoid variant)")
    p.add_argument("--seed", type=seed, default=0)
    p.set_defaults(func=cmd_domain)


def add_pddl(sub) -> None:
    """`tamp pddl`."""
    p = sub.add_parser(
        "pddl",
        help="export a models directory's learned domain (and a problem) as PDDL for other planners",
        description="Write the learned domain of --models (its domain/operators.json) as domain.pddl "
        "(most frequent effects: a deterministic STRIPS domain with equality) and domain.ppddl (PPDDL "
        "probabilistic effects), with --problem the problem's symbols (from the Symbolic Model) as "
        "problem.pddl, and with --sampled N the distinct domains of N sampled ones, as Level 1 draws them. "
        "Fast Downward and other PDDL planners read domain.pddl and problem.pddl; "
        "`tamp domain` learns a domain from data.",
    )
    p.add_argument("--models", type=models_directory, default=None,
                   help="models directory (domain/, and symbolic.pt for --problem), or a bundled set: pretrained "
                   "(the default), pairwise, spatial or regions")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--problem", type=Path, default=None, help="problem file (JSON: X_init, X_goal) to export")
    p.add_argument("--sampled", type=Count(0, MAX_DOMAINS), default=0, metavar="N",
                   help="also write the distinct domains among N sampled ones (sampled/, with sampled.json)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the sampled domains (default 0)")
    p.set_defaults(func=cmd_pddl)


def add_symbols(sub) -> None:
    """`tamp symbols`."""
    p = sub.add_parser(
        "symbols",
        help="what each learned bit of a Symbolic Model means: its rate and agreement with geometric facts",
        description="Read the Symbolic Model's unary bits, relations r_k(i, j) (i != j) and self relations "
        "r_k(i, i) on held-out scenes (the initial and goal scenes of a problem set, or states of a "
        "dataset) and compare each with facts a reader understands: block type, elevated, on another "
        "block, carrying one, left/right along y, near, on top of, above, vertical order, level, in line. "
        "Prints a table (agreement in %, the better of the fact and its negation, and the Matthews "
        "correlation phi, which does not reward agreeing with a rare fact by being always 0; --png draws "
        "it), then a summary: relations with a spatial fact at |phi| >= 0.8, near-constant bits, bits that "
        "are the block type, and with --problems the goals whose symbols equal their initial scene's "
        "(given bits, the type symbol and the pairwise diagonal, are left out).",
    )
    p.add_argument("--model", type=Path, required=True, help="Symbolic Model checkpoint")
    p.add_argument("--problems", type=Path, default=None, help="problem set (tamp problems --out): its scenes")
    p.add_argument("--data", type=Path, default=None, help="or a dataset directory: states of its transitions")
    p.add_argument("--max-scenes", type=positive_int, default=5000, help="scenes read at most (default 5000)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the scenes drawn from --data (default 0)")
    p.add_argument("--png", type=Path, default=None, help="write the table as a heat map (PNG)")
    p.add_argument("--json", type=Path, default=None, help="write every figure as JSON")
    p.set_defaults(func=cmd_symbols)
