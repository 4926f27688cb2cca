"""`tamp practice`: the robot learns from its own plans (data aggregation for system identification).

Random exploration teaches the Dynamics Model where actions do nothing; the planner acts elsewhere, on
the actions the model is optimistic about. Practice closes that loop, round after round:

    round r:  problems of its own (seed PRACTICE_SEED + r, never a user's evaluation seed)
              -> the closed loop plans them with round r's models and executes them in the world
              -> every executed transition (X, a, X') written as a dataset (the format `tamp collect` writes),
                 and (with `explore`) other actions the planner would consider, run from every state it visited
              -> an ensemble Dynamics Model trained on the random data and every round's practice so far
                 (`learned.ensemble_train`: a share of each member's resample is practice), warm-started
                 from round r's, becomes round r + 1's

Round r's figures (success, how far executed steps landed from the prediction, how often beyond the
model's own 95 % bound) are measured on problems its models never learned from, so the curve is a
measurement, not a claim. The Symbolic Model and the domain are the given ones in every round.

Layout of OUT:

    OUT/practice.json            the inputs and settings (a rerun resumes only with the same ones)
    OUT/round-R/problems.jsonl   the round's problems (strict and paper protocol, names prefixed)
    OUT/round-R/eval/            `tamp evaluate` rows of the round's models on them
    OUT/round-R/data/            the round's executed transitions
    OUT/round-R/explore/         with `explore`: steps beside the plans from the states the round visited
    OUT/round-R/models/          the round's models (round 0: a copy-free reference to --models)
    OUT/curve.json, curve.md     the learning curve, rewritten after every round
    OUT/models/                  the last round's models (`tamp plan --models OUT/models`)

Every stage resumes: problems and datasets are written atomically, the evaluation recomputes missing
rows only, training continues each member where it stopped.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from guarded import Schema, atomic_write_json, read_json
from tamp.errors import UserError
from tamp.records import atomic_write_text, made_by_tool, output_dir
from tamp.sim.world_types import FIDELITIES, fidelity_of

if TYPE_CHECKING:
    from learned import TrainConfig

PRACTICE_SEED = 1_000_000  # round r's problems have seed PRACTICE_SEED + r: far from the small seeds users evaluate on
STATE_NAME, CURVE_JSON, CURVE_MD = "practice.json", "curve.json", "curve.md"
FORMAT = "tamp-practice/1"


@dataclass(frozen=True)
class PracticeConfig:
    """What the robot practises and how it learns from it."""
    rounds: int = 3  # practice-and-train cycles; one more evaluation round measures the last models
    per_cell: int = 12  # problems per (n, k) and protocol each round: 600 problems, about 1,100 executed steps
    objects: tuple[int, ...] = (2, 3, 4, 5, 6)
    actions: tuple[int, ...] = (1, 2, 3, 4, 5)
    protocols: tuple[str, ...] = ("strict", "paper")
    seed: int = PRACTICE_SEED
    method: str = "bilevel_loop"  # the closed loop that does not know k: the product's planner
    fidelity: str = "fast"  # the world the plans are executed in ("full": the arm under physics)
    # goal-oriented actions run beside the plan from every visited state (`evaluation.explore`; 0: none); off by
    # default: they taught the model those steps, not the ones the planner picks (docs/practice-and-doubt.md)
    explore: int = 0
    members: int = 2  # ensemble members (`learned.ensemble_train.EnsembleConfig`): a bound at twice one network's cost
    extra_share: float = 0.3  # share of each member's resample drawn from the practice data
    epochs: int = 60  # per member and round, at most: a warm start's error creeps down for hundreds (12 min a round)
    patience: int = 20  # epochs without a better validation error before a member stops
    lr: float = 4e-4  # below the bundled Dynamics Model's from-scratch 1e-3 (batch 512): a fine-tune
    batch_size: int = 512  # the bundled Dynamics Model's training batch
    precision: str = "float32"  # the bundled Dynamics Model's; bfloat16 trains faster but fine-tunes it coarser
    # the members' effect loss: "squared" (the paper's Eq. 1, the bundled model's) or "distance" (a median: a step
    #   with two outcomes is predicted at the more frequent one, not between them; learned.TrainConfig.effect_loss)
    effect_loss: str = "squared"
    # train the members on the transitions that moved their picked block alone (`tamp train --only-moved`), as the
    #   default set's Dynamics Model was fine-tuned: every transition would teach it partial moves again
    only_moved: bool = False
    workers: int = 2  # evaluation workers and members trained at once
    backend: str = "local"  # "local" process pool or "ray" (the evaluation)

    def __post_init__(self) -> None:
        if isinstance(self.explore, bool) or not isinstance(self.explore, int) or self.explore < 0:
            raise UserError(f"--explore must be a whole number of actions, 0 or more, got {self.explore!r}")
        for name in ("rounds", "per_cell", "members", "epochs", "patience", "batch_size", "workers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise UserError(f"--{name.replace('_', '-')} must be a positive integer, got {value!r}")
        if not 0.0 < self.extra_share < 1.0:
            raise UserError(f"--extra-share must be in (0, 1), got {self.extra_share}")
        if not 0 <= self.seed < 2**62:
            raise UserError(f"--seed must be in [0, 2^62), got {self.seed}")
        from evaluation.problems import _counts
        from tamp.app.problem import MAX_K, PROTOCOLS
        from tamp.planning.validate import MAX_OBJECTS

        # as `generate_problems` checks them, before anything is written
        _counts(self.objects, "--objects", 1, MAX_OBJECTS)
        _counts(self.actions, "--actions", 1, MAX_K)
        if not self.protocols or any(p not in PROTOCOLS for p in self.protocols):
            raise UserError(f"protocols must be among {', '.join(PROTOCOLS)}, got {self.protocols!r}")
        fidelity_of(self.fidelity, "--fidelity")
        if self.precision not in ("float32", "bfloat16"):
            raise UserError(f"--precision must be float32 or bfloat16, got {self.precision!r}")
        if self.effect_loss not in ("squared", "distance"):
            raise UserError(f"--effect-loss must be squared or distance, got {self.effect_loss!r}")

    def defining(self) -> dict[str, Any]:
        """The settings a round's results depend on (all but rounds, workers and backend; those added since runs
        began, `_LATER`, only when not at their default, so that such runs resume)."""
        return {k: v for k, v in json.loads(json.dumps(dataclasses.asdict(self))).items()
                if k not in ("rounds", "workers", "backend") and _LATER.get(k, _UNSET) != v}


_UNSET = object()
# settings added after practice runs were made -> the value those runs had
_LATER = {"effect_loss": "squared", "only_moved": False}


# --------------------------------------------------------------------------- one round's stages

def round_dir(out: Path, r: int) -> Path:
    return out / f"round-{r}"


def make_problems(path: Path, r: int, config: PracticeConfig, progress: bool) -> Path:
    """The round's problem set (both protocols, names prefixed by the protocol), written once."""
    if path.is_file():
        return path
    from evaluation.problems import generate_problems, write_problems

    problems = []
    for protocol in config.protocols:
        made = generate_problems(config.objects, config.actions, config.per_cell, config.seed + r, progress,
                                 protocol, workers=config.workers)
        problems += [dataclasses.replace(p, name=f"{protocol}-{p.name}") for p in made]
    return write_problems(path, problems)


def write_transitions(rows_path: Path, directory: Path, seed: int, fidelity: str) -> int:
    """The executed transitions of the rows at `rows_path` as a dataset at `directory` (written once; a
    directory left half-written by a kill is written again), its world the one that executed them
    (`fidelity`, paths simplified); returns their number."""
    from learned.dataset import DatasetWriter, load_transitions
    from tamp.app.collect import STATUS_CODES
    from tamp.planning.validate import MAX_OBJECTS
    from tamp.sim.world_types import WorldConfig

    from .run import read_rows

    done = directory / ".complete"
    if done.is_file():
        return len(load_transitions(directory))
    if directory.exists():
        shutil.rmtree(directory)
    world = WorldConfig(fidelity=fidelity, simplify_paths=True)  # as tamp.app.runner.executing_world's
    steps = [t for row in read_rows(rows_path) for t in (row.get("transitions") or [])]
    if not steps:
        return 0
    with DatasetWriter(directory, n_max=MAX_OBJECTS, world_config=world.to_dict(), seed=seed,
                       status_codes=STATUS_CODES, shard_size=1000,
                       extra_meta={"collection": {"source": f"executed steps of {rows_path}"}}) as writer:
        for t in steps:
            writer.add(t["X"], t["action"], t["X_next"], t["grasped"], STATUS_CODES[t["status"]])
    done.write_text("")
    return len(steps)


def train_round_models(base: Path, previous: Path, data: list[Path], practice: list[Path], out: Path,
                       config: PracticeConfig, progress: bool) -> Path:
    """Round r + 1's models at `out`: the base's Symbolic Model and domain, and an ensemble Dynamics Model
    trained on the random `data` and the `practice` datasets, warm-started from `previous`'s."""
    from learned.ensemble_train import EnsembleConfig, cleanup_members, train_ensemble
    from tamp.planning.models import DOMAIN_DIR, DYNAMICS_FILE, SYMBOLIC_FILE, SYMBOLS_FILE

    if (out / DYNAMICS_FILE).is_file():
        return out
    staging = out.with_name(out.name + ".training")
    staging.mkdir(parents=True, exist_ok=True)
    train = member_training(config)
    ensemble = EnsembleConfig(members=config.members, extra_share=config.extra_share, workers=config.workers)
    train_ensemble([str(d) for d in data], staging / DYNAMICS_FILE, extra=[str(p) for p in practice] or None,
                   train=train, ensemble=ensemble, init=previous / DYNAMICS_FILE, progress=progress)
    cleanup_members(staging / DYNAMICS_FILE, config.members)
    for name in (SYMBOLIC_FILE, SYMBOLS_FILE):
        if (base / name).is_file():
            shutil.copy2(base / name, staging / name)
    shutil.copytree(base / DOMAIN_DIR, staging / DOMAIN_DIR, dirs_exist_ok=True,
                    ignore=shutil.ignore_patterns("*.pddl", "*.ppddl", "sampled*"))
    if out.exists():
        shutil.rmtree(out)
    staging.rename(out)
    return out


def member_training(config: PracticeConfig) -> TrainConfig:
    """How each ensemble member of a round is trained (`learned.TrainConfig`)."""
    from learned import TrainConfig

    return TrainConfig.fast(batch_size=config.batch_size, epochs=config.epochs, patience_epochs=config.patience,
                            lr=config.lr, precision=config.precision, effect_loss=config.effect_loss,
                            only_moved=config.only_moved)


def round_figures(rows_path: Path) -> dict[str, Any]:
    """A round's point on the learning curve: success (all, by n and protocol), executed steps and their misses,
    calibration, planning time."""
    from evaluation.report.calibration import step_figures
    from evaluation.stats import median

    from .run import read_rows

    rows = [r for r in read_rows(rows_path) if r.get("outcome") != "error"]
    preds = [p for r in rows for p in (r.get("predictions") or [])]

    def success(rs: list[dict]) -> float | None:
        return 100.0 * sum(bool(r["success"]) for r in rs) / len(rs) if rs else None

    return {"problems": len(rows), "success_pct": success(rows),
            "success_by_n": {str(n): success([r for r in rows if r["n"] == n]) for n in sorted({r["n"] for r in rows})},
            "success_by_protocol": {p: success([r for r in rows if r["protocol"] == p])
                                    for p in sorted({r["protocol"] for r in rows})},
            "steps": step_figures(preds),
            "planning_median_s": median([r["planning_time_s"] for r in rows]),
            "planning_mean_s": sum(r["planning_time_s"] for r in rows) / len(rows) if rows else None}


# --------------------------------------------------------------------------- the rounds

# what a resumed practice compares and extends (each round's record is its own: `_round`)
STATE_SCHEMA = Schema({"type": "object", "required": ["models", "data", "config", "rounds"], "properties": {
    "models": {"type": "string"}, "data": {"type": "array", "items": {"type": "string"}}, "config": {"type": "object"},
    "rounds": {"type": "array", "items": {"type": "object", "required": ["round"],
                                          "properties": {"round": {"type": "integer", "minimum": 0}}}}}})


def _prepare(out: Path, models: Path, data: list[Path], config: PracticeConfig) -> dict[str, Any]:
    """OUT/practice.json: written on the first run, compared on a resume."""
    state = {"format": FORMAT, "models": str(models.resolve()), "data": [str(d.resolve()) for d in data],
             "config": config.defining()}
    path = out / STATE_NAME
    if path.is_file():
        old = read_json(path, "practice state file")
        if not isinstance(old, dict) or old.get("format") != FORMAT:
            raise UserError(f"{path} is not the state file of a `tamp practice` directory")
        STATE_SCHEMA.check(old, str(path))
        differ = [k for k in ("models", "data", "config") if old.get(k) != state[k]]
        if differ:
            raise UserError(f"{out} was practised with other {', '.join(differ)}; give a new --out, or the same "
                            "inputs and settings to resume")
        return old
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(path, {**state, "rounds": []}, indent=2)
    return {**state, "rounds": []}


def practise(models: Path, data: list[Path], out: Path, config: PracticeConfig = PracticeConfig(),
             progress: bool = True) -> list[dict[str, Any]]:
    """Run `config.rounds` practice rounds and one more that measures the last models (module docstring);
    returns the learning curve, one record per round."""
    from learned import read_meta
    from tamp.planning.models import load_models

    models, out = Path(models), Path(out)
    load_models(models)  # every input checked before anything is written
    for d in data:
        read_meta(d)
    final = out / "models"
    if final.exists() and not final.is_symlink() and not made_by_tool(final):
        raise UserError(f"{final} is a folder the tool did not make (it puts a link to the last round's models "
                        "there); move it away or give another --out")
    with output_dir(out, "--out", own=(STATE_NAME,)):
        state = _prepare(out, models, data, config)
    return _rounds(models, data, out, config, state, progress)


def _rounds(models: Path, data: list[Path], out: Path, config: PracticeConfig, state: dict[str, Any],
            progress: bool) -> list[dict[str, Any]]:
    """The rounds of `practise` in the claimed folder `out`, then the link OUT/models to the last round's models."""
    from evaluation.configuration import EvalConfig
    from evaluation.run import evaluate

    curve: list[dict[str, Any]] = []
    current = models
    for r in range(config.rounds + 1):
        rd = round_dir(out, r)
        rd.mkdir(parents=True, exist_ok=True)
        timings: dict[str, float] = {}
        if r > 0:
            t = time.perf_counter()
            practice = [d for q in range(r) for d in (round_dir(out, q) / "data", round_dir(out, q) / "explore")
                        if (d / ".complete").is_file() and any(d.glob("shard-*.npz"))]
            current = train_round_models(models, current, data, practice, rd / "models", config, progress)
            timings["train_s"] = time.perf_counter() - t
        t = time.perf_counter()
        problems = make_problems(rd / "problems.jsonl", r, config, progress)
        timings["problems_s"] = time.perf_counter() - t
        t = time.perf_counter()
        eval_config = EvalConfig(fidelity=config.fidelity, workers=config.workers, backend=config.backend,
                                 progress=progress)
        rows = evaluate(current, problems, rd / "eval", [config.method], eval_config)
        timings["practice_s"] = time.perf_counter() - t
        transitions = write_transitions(rows, rd / "data", config.seed + r, config.fidelity)
        explored = 0
        if config.explore and r < config.rounds:  # the last round only measures: nothing trains on its steps
            from evaluation.explore import explore

            t = time.perf_counter()
            explored = explore(rows, problems, rd / "explore", config.explore, config.seed + r, config.workers,
                               config.backend, progress)
            timings["explore_s"] = time.perf_counter() - t
        point = {"round": r, "models": str(current), "seed": config.seed + r, "transitions": transitions,
                 "explored": explored, **round_figures(rows), "wall_s": timings}
        previous = next((p for p in state.get("rounds", []) if p["round"] == r), None)
        if previous is not None:  # a resumed round keeps the wall times of the run that did the work
            point["wall_s"] = {k: max(v, previous.get("wall_s", {}).get(k, 0.0)) for k, v in timings.items()}
        curve.append(point)
        state["rounds"] = curve + [p for p in state.get("rounds", []) if p["round"] > r]
        atomic_write_json(out / STATE_NAME, state, indent=2)
        write_curve(out, curve)
        if progress:
            print(format_point(point), file=sys.stderr, flush=True)
    link_models(out / "models", current)
    return curve


def link_models(final: Path, current: Path) -> None:
    """Point the link `final` at `current`, atomically (a new link renamed over it); what is at `final` is
    replaced only when the tool made it (a link, or a folder with its marker): never a folder of the user's."""
    if final.exists() and not final.is_symlink():
        if not made_by_tool(final):
            raise UserError(f"{final} is a folder the tool did not make; it is left alone, the last round's "
                            f"models are at {current}")
        shutil.rmtree(final)
    tmp = final.with_name(f".{final.name}.tmp-{os.getpid()}")
    tmp.unlink(missing_ok=True)
    try:
        tmp.symlink_to(current.resolve(), target_is_directory=True)
        os.replace(tmp, final)
    except OSError as error:
        tmp.unlink(missing_ok=True)
        raise UserError(f"cannot write {final}: {error.strerror}") from None


def format_point(p: dict[str, Any]) -> str:
    s = p["steps"]
    miss = "no step executed" if not s.get("steps") else (
        f"{s['steps']} steps, {s['miss_ge_2cm_pct']:.1f} % >= 2 cm, {s['miss_ge_5cm_pct']:.1f} % >= 5 cm"
        + ("" if s.get("exceeded_pct") is None else f", {s['exceeded_pct']:.1f} % beyond the 95 % bound"))
    return (f"round {p['round']}: success {p['success_pct']:.1f} % of {p['problems']}; {miss}; "
            f"{p['transitions']} transitions, {p.get('explored', 0)} beside the plans")


def write_curve(out: Path, curve: list[dict[str, Any]]) -> None:
    """OUT/curve.json and OUT/curve.md: one line per round."""
    atomic_write_json(out / CURVE_JSON, curve, indent=2)
    ns = sorted({n for p in curve for n in p["success_by_n"]}, key=int)
    header = ["round", "problems", "success (%)", *[f"n = {n} (%)" for n in ns], "steps", ">= 2 cm (%)",
              ">= 5 cm (%)", "beyond bound (%)", "median miss / bound (cm)", "transitions (executed + beside)",
              "train (min)", "practice (min)"]
    lines = ["# Practice: the learning curve", "",
             "Each round's models measured on that round's own problems, which no model before it learned from "
             "(`tamp practice`; round 0: the given models).", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]

    def pct(x: float | None) -> str:
        return "—" if x is None else f"{x:.1f}"

    def cm(metres: float | None) -> str:
        return "—" if metres is None else f"{100 * metres:.1f}"

    for p in curve:
        s = p["steps"]
        cells = [str(p["round"]), str(p["problems"]), pct(p["success_pct"]),
                 *[pct(p["success_by_n"].get(n)) for n in ns], str(s.get("steps", 0)),
                 pct(s.get("miss_ge_2cm_pct")), pct(s.get("miss_ge_5cm_pct")), pct(s.get("exceeded_pct")),
                 f"{cm(s.get('median_miss_m'))} / {cm(s.get('median_bound_m'))}",
                 f"{p['transitions']} + {p.get('explored', 0)}", f"{p['wall_s'].get('train_s', 0.0) / 60:.1f}",
                 f"{sum(p['wall_s'].get(k, 0.0) for k in ('practice_s', 'problems_s', 'explore_s')) / 60:.1f}"]
        lines.append("| " + " | ".join(cells) + " |")
    atomic_write_text(out / CURVE_MD, "\n".join(lines) + "\n")


# --------------------------------------------------------------------------- the command

def cmd_practice(args: argparse.Namespace) -> int:
    from tamp.app.args import check_output_dir

    check_output_dir(args.out, "--out")
    config = PracticeConfig(rounds=args.rounds, per_cell=args.per_cell, objects=tuple(args.objects),
                            seed=args.seed, fidelity=args.fidelity, explore=args.explore, members=args.members,
                            extra_share=args.extra_share, epochs=args.epochs, patience=args.patience,
                            batch_size=args.batch_size, precision=args.precision, effect_loss=args.effect_loss,
                            only_moved=args.only_moved, workers=args.workers, backend=args.backend)
    from tamp.planning.models import pretrained_dir

    models = Path(args.models) if args.models else pretrained_dir()
    curve = practise(models, [Path(d) for d in args.data], Path(args.out), config, progress=not args.quiet)
    for p in curve:
        print(format_point(p))
    print(f"learning curve: {Path(args.out) / CURVE_MD}; the last round's models: {Path(args.out) / 'models'}")
    return 0


def add_practice(sub) -> None:
    """`tamp practice`."""
    from tamp.app.args import WORKERS_LIMIT, Count, fraction, int_list, models_directory, positive_int, seed

    p = sub.add_parser(
        "practice",
        help="the robot practises: plans its own problems, executes them and learns from its own steps",
        description="Round after round: make problems of its own seeds, plan them in the closed loop with the "
        "current models, execute them in the world, record every executed transition, and train an ensemble "
        "Dynamics Model on the random data and all the practice so far (warm-started). Each round's models are "
        "measured on that round's new problems before training on them: OUT/curve.md is the learning curve. "
        "Resumable: run the same command again (a larger --rounds continues).",
    )
    p.add_argument("--data", nargs="+", required=True, metavar="DIR",
                   help="the random interaction data the models learned from (tamp collect --out)")
    p.add_argument("--models", type=models_directory, default=None, metavar="DIR",
                   help="the models to start from (default: the bundled ones); their Symbolic Model and domain are "
                   "kept in every round")
    p.add_argument("--out", type=Path, required=True, help="the practice directory (rounds, curve, final models)")
    p.add_argument("--rounds", type=Count(1, 1000), default=PracticeConfig.rounds,
                   help=f"practice-and-train cycles (default {PracticeConfig.rounds}); one more round measures "
                   "the last models")
    p.add_argument("--per-cell", type=Count(1, 100_000), default=PracticeConfig.per_cell,
                   help=f"problems per (objects, k) and protocol each round (default {PracticeConfig.per_cell}: "
                   "600 problems a round)")
    p.add_argument("--objects", type=int_list, default=PracticeConfig.objects,
                   help="object counts of the practice problems (default 2,3,4,5,6)")
    p.add_argument("--seed", type=seed, default=PRACTICE_SEED,
                   help=f"round r's problems have seed SEED + r (default {PRACTICE_SEED}, far from the seeds "
                   "one evaluates on)")
    p.add_argument("--fidelity", choices=FIDELITIES, default="fast",
                   help="the world plans are executed in: fast (default) or full (the arm under physics)")
    p.add_argument("--explore", type=Count(0, 10_000), default=PracticeConfig.explore, metavar="ACTIONS",
                   help="from every state a round visited, run up to this many other goal-oriented actions beside the "
                   f"plan and learn from them too (default {PracticeConfig.explore}: the executed steps alone)")
    p.add_argument("--members", type=Count(1, 64), default=PracticeConfig.members,
                   help=f"ensemble members of the Dynamics Model (default {PracticeConfig.members})")
    p.add_argument("--extra-share", type=fraction, default=PracticeConfig.extra_share,
                   help=f"share of each member's resample drawn from the practice data (default "
                   f"{PracticeConfig.extra_share})")
    p.add_argument("--epochs", type=positive_int, default=PracticeConfig.epochs,
                   help=f"at most this many epochs per member and round (default {PracticeConfig.epochs}); a warm "
                   "start's validation error falls slowly, so this bounds a round's training time")
    p.add_argument("--patience", type=positive_int, default=PracticeConfig.patience,
                   help=f"a member stops after this many epochs without a better validation error (default "
                   f"{PracticeConfig.patience})")
    p.add_argument("--batch-size", type=Count(1, 1 << 20), default=PracticeConfig.batch_size,
                   help=f"the members' training batch (default {PracticeConfig.batch_size})")
    p.add_argument("--precision", choices=("float32", "bfloat16"), default=PracticeConfig.precision,
                   help=f"the members' training precision (default {PracticeConfig.precision}, the bundled model's)")
    p.add_argument("--effect-loss", choices=("squared", "distance"), default=PracticeConfig.effect_loss,
                   help=f"the members' effect loss (default {PracticeConfig.effect_loss}, the bundled model's: the "
                   "mean of a step's outcomes; distance: a median, tamp train --effect-loss)")
    p.add_argument("--only-moved", action="store_true",
                   help="train the members on the transitions that moved their picked block alone, random and "
                   "practised (tamp train --only-moved), as the default set's Dynamics Model was fine-tuned; "
                   "without it every transition, which teaches such a model partial moves again")
    p.add_argument("--workers", type=Count(1, WORKERS_LIMIT), default=2,
                   help="worker processes of the evaluation, and members trained at once (default 2)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="the evaluation's workers: a local process pool (default) or Ray")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_practice)
