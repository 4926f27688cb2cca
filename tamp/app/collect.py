"""Interaction data at scale: random pick-place exploration written as dataset shards.

The work unit is one *scene* k. Its seed is ``SeedSequence(seed, spawn_key=(k,))``; from it
come the object count n (uniform over ``objects``), the scene (``World.reset(seed=...)``) and
M = ``actions_per_scene`` uniformly random actions among the 9 n^2 (failing ones included),
chained: each action starts from the previous outcome. A sample is (X, a, X', n, grasped, status), so
a scene depends on (seed, k) alone, never on which worker ran it or what it ran before.

With ``sampling="graspable"`` each action is drawn among those whose grasp point closes the jaws on a
block (a third of uniform actions grasp nothing and move nothing): data of where things move, to add
to the paper's uniform data.

Shard j holds scenes [j K, (j + 1) K) with K = ``scenes_per_shard`` (the last scene and shard
are trimmed so the dataset has exactly ``samples`` samples). The layout is fixed by the
parameters, so the dataset is identical whatever the number of workers or the backend, and a
run that was stopped (even by ``kill -9``) is resumed by computing only the missing shards:
shards are written atomically by the parent (``learned.dataset.write_shard``), and on resume every
existing shard is validated; one that fails is reported by name, deleted and recomputed.

Workers only simulate (Drake, no torch): a local ``spawn`` process pool or Ray actors, each
keeping one ``World`` (and its cache of Drake plants per block-type layout) for its lifetime.
The parent packs, validates and writes the shards.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple, get_args

import numpy as np

from tamp.app.parallel import BACKENDS, import_ray, run_tasks
from tamp.errors import UserError
from tamp.inputs import SEED_LIMIT
from tamp.planning.validate import MAX_OBJECTS
from tamp.records import exclusive, output_dir, package_versions
from tamp.sim.world_types import STATUSES, StepStatus, WorldConfig

STATUS_CODES = {name: code for code, name in enumerate(STATUSES)}
LOCK_NAME = ".collect.lock"
# meta.json fields that define the data: a directory is resumed only if all of them match.
DEFINING_KEYS = ("format", "n_max", "world_config", "seed", "status_codes", "shard_size", "collection")
Sampling = Literal["uniform", "graspable"]
SAMPLINGS: tuple[str, ...] = get_args(Sampling)
ACTIONS_DRAWN = {"uniform": "uniform over the 9 n^2 actions, chained from the previous outcome",
                 "graspable": "uniform over the actions whose grasp point holds a block in the current state, "
                              "chained from the previous outcome"}


MAX_SAMPLES, MAX_ACTIONS_PER_SCENE, MAX_SCENES_PER_SHARD = 10_000_000, 10_000, 100_000  # what memory holds


@dataclass(frozen=True)
class CollectConfig:
    """What to collect. ``samples`` transitions from scenes of n in ``objects`` blocks."""

    samples: int
    objects: tuple[int, ...] = (2, 3, 4)
    seed: int = 0
    actions_per_scene: int = 10
    scenes_per_shard: int = 20
    world: WorldConfig = field(default_factory=WorldConfig)
    sampling: Sampling = "uniform"  # the paper's; "graspable" skips the actions that grasp nothing

    def __post_init__(self) -> None:
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or self.samples < 1:
            raise UserError(f"--samples must be a positive integer, got {self.samples!r}")
        for flag, value, limit in (("--samples", self.samples, MAX_SAMPLES),
                                   ("--actions-per-scene", self.actions_per_scene, MAX_ACTIONS_PER_SCENE),
                                   ("--scenes-per-shard", self.scenes_per_shard, MAX_SCENES_PER_SHARD)):
            if value > limit:  # the scenes' tasks are listed in memory, a shard is held in memory
                raise UserError(f"{flag} must be at most {limit:,}, got {value}")
        objects = tuple(int(n) for n in self.objects)
        if not objects:
            raise UserError("--objects needs at least one object count, e.g. 2,3,4")
        bad = [n for n in objects if not 1 <= n <= MAX_OBJECTS]
        if bad:
            raise UserError(f"--objects: object counts must be in 1..{MAX_OBJECTS}, got {bad[0]}")
        if len(set(objects)) != len(objects):
            raise UserError(f"--objects lists a count twice: {','.join(map(str, objects))}")
        object.__setattr__(self, "objects", tuple(sorted(objects)))
        if self.actions_per_scene < 1:
            raise UserError(f"--actions-per-scene must be at least 1, got {self.actions_per_scene}")
        if self.scenes_per_shard < 1:
            raise UserError(f"--scenes-per-shard must be at least 1, got {self.scenes_per_shard}")
        if not 0 <= self.seed < SEED_LIMIT:
            raise UserError(f"--seed must be in [0, 2^63), got {self.seed}")
        if self.sampling not in SAMPLINGS:
            raise UserError(f"--sampling must be one of {', '.join(SAMPLINGS)}, got {self.sampling!r}")

    @property
    def n_max(self) -> int:
        return max(self.objects)

    @property
    def n_scenes(self) -> int:
        return math.ceil(self.samples / self.actions_per_scene)

    @property
    def n_shards(self) -> int:
        return math.ceil(self.n_scenes / self.scenes_per_shard)

    @property
    def shard_size(self) -> int:
        """Samples per shard (all but possibly the last)."""
        return self.scenes_per_shard * self.actions_per_scene

    def shard_scenes(self, j: int) -> range:
        return range(j * self.scenes_per_shard, min((j + 1) * self.scenes_per_shard, self.n_scenes))

    def shard_samples(self, j: int) -> int:
        return min(self.shard_size, self.samples - j * self.shard_size)

    def scene_samples(self, k: int) -> int:
        return min(self.actions_per_scene, self.samples - k * self.actions_per_scene)

    def meta(self) -> dict[str, Any]:
        """meta.json content (format of learned.dataset), normalised through JSON."""
        from learned.dataset import FORMAT  # parent only; learned imports torch

        meta = {
            "format": FORMAT, "n_max": self.n_max, "world_config": self.world.to_dict(),
            "seed": self.seed, "status_codes": STATUS_CODES, "shard_size": self.shard_size,
            "versions": package_versions(),
            "collection": {
                "samples": self.samples, "objects": list(self.objects),
                "actions_per_scene": self.actions_per_scene, "scenes_per_shard": self.scenes_per_shard,
                "shards": self.n_shards, "scenes": self.n_scenes,
                "scene_seed": "numpy SeedSequence(seed, spawn_key=(k,)) for scene k; n, the scene "
                              "seed and the actions drawn from default_rng of it",
                "actions": ACTIONS_DRAWN[self.sampling],
                # only when not the paper's, so that directories collected before it resume
                **({"sampling": self.sampling} if self.sampling != "uniform" else {}),
            },
        }
        return json.loads(json.dumps(meta))


# --------------------------------------------------------------------------- one scene (workers)

class SceneTask(NamedTuple):
    seed: int
    k: int  # scene index
    objects: tuple[int, ...]
    samples: int  # actions to run in this scene (M, or fewer for the last scene)
    sampling: Sampling = "uniform"


@dataclass
class SceneResult:
    """The transitions of one scene; states are (m, n, 5), metres and one-hot type."""

    k: int
    X: np.ndarray
    action: np.ndarray  # (m, 4) int64
    X_next: np.ndarray
    grasped: np.ndarray  # (m,) int64, -1 if nothing was carried
    status: np.ndarray  # (m,) int64, codes of STATUS_CODES

    def __len__(self) -> int:
        return len(self.status)


def run_scene(world, task: SceneTask) -> SceneResult:
    """Random scene k and its chain of random actions; depends on (task.seed, task.k, task.sampling) alone."""
    rng = np.random.default_rng(np.random.SeedSequence(task.seed, spawn_key=(task.k,)))
    n = int(task.objects[rng.integers(len(task.objects))])
    X = world.reset(n_objects=n, seed=int(rng.integers(2**63)))
    every_action = world.actions()  # of n alone, so of the whole scene
    Xs, As, Xn, G, S = [], [], [], [], []
    for _ in range(task.samples):
        actions = every_action
        if task.sampling == "graspable":  # of the current state; if none (rare), any action, which changes nothing
            actions = world.graspable_actions() or every_action
        action = actions[rng.integers(len(actions))]
        X_next, info = world.step(action)
        Xs.append(X)
        As.append(tuple(action))
        Xn.append(X_next)
        G.append(info.grasped if info.status == StepStatus.OK else -1)
        S.append(STATUS_CODES[info.status])
        X = X_next
    return SceneResult(task.k, np.array(Xs), np.array(As, np.int64), np.array(Xn),
                       np.array(G, np.int64), np.array(S, np.int64))


class SceneWorker:
    """One worker's World (and its cache of Drake plants per block-type layout), kept for its lifetime."""

    def __init__(self, world_config: dict) -> None:
        from tamp.sim import World

        self.world = World(WorldConfig(**world_config))

    def run(self, task: SceneTask) -> SceneResult:
        return run_scene(self.world, task)


# --------------------------------------------------------------------------- the dataset directory

def shard_name(j: int) -> str:
    return f"shard-{j:06d}.npz"


def _warn(message: str) -> None:
    from tqdm import tqdm

    tqdm.write(f"warning: {message}", file=sys.stderr)


def _describe_difference(old: dict, new: dict) -> str:
    def short(value) -> str:
        text = repr(value)
        return text if len(text) <= 40 else text[:37] + "..."

    diffs = []
    for key in DEFINING_KEYS:
        a, b = old.get(key), new.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            diffs += [f"{key}.{k} {short(a.get(k))} -> {short(b.get(k))}" for k in sorted(set(a) | set(b))
                      if a.get(k) != b.get(k) and k not in ("scenes", "shards")]
        elif a != b:
            diffs.append(f"{key} {short(a)} -> {short(b)}")
    return "; ".join(diffs[:4]) + ("; ..." if len(diffs) > 4 else "")


def prepare_directory(out: Path, cfg: CollectConfig, meta: dict) -> tuple[set[int], list[str]]:
    """Create or check `out`; returns the indices of valid shards and the names of bad ones.

    Raises ValueError if `out` holds anything but a dataset of exactly these parameters.
    Bad shards (unreadable, invalid, wrong size) are deleted so they are recomputed.
    """
    from learned.dataset import META_NAME, SHARD_RE, ShardError, read_meta, read_shard, write_meta

    meta_path = out / META_NAME
    if meta_path.exists():
        old = read_meta(out)
        if any(old.get(k) != meta[k] for k in DEFINING_KEYS):
            raise UserError(f"{out} holds a dataset collected with other parameters "
                             f"({_describe_difference(old, meta)}); use a new --out directory, "
                             "or the same parameters to resume it")
        if old.get("versions") != meta["versions"]:
            _warn(f"{out} was started with other package versions ({old.get('versions')}); "
                  "resuming anyway, the new shards may differ from what those versions would give")
    elif out.exists() and any(not p.name.startswith(".") for p in out.iterdir()):
        raise UserError(f"{out} is not empty and has no {META_NAME}; give a new or empty --out directory")
    else:
        write_meta(out, meta)

    for stale in out.glob(".*.tmp-*"):  # temp files of a killed run (shards or meta.json)
        stale.unlink()
    status_values = sorted(STATUS_CODES.values())
    good, bad = set(), []
    for path in sorted(out.iterdir()):
        match = SHARD_RE.match(path.name)
        if not match:
            continue
        j = int(match.group(1))
        if j >= cfg.n_shards:
            raise UserError(f"{path} is beyond the {cfg.n_shards} shards of this dataset; "
                             "the directory was modified by hand")
        try:
            shard = read_shard(path, cfg.n_max, status_values)
            if len(shard) != cfg.shard_samples(j):
                raise ShardError(path, f"{len(shard)} samples, expected {cfg.shard_samples(j)}")
        except ShardError as error:
            _warn(f"corrupt shard {path.name} ({error}); deleting it, it will be re-collected")
            path.unlink()
            bad.append(path.name)
            continue
        good.add(j)
    return good, bad


def pack_shard(results: list[SceneResult], n_max: int) -> dict[str, np.ndarray]:
    """Shard arrays (learned.dataset layout, zero padding beyond n) from consecutive scenes."""
    S = sum(len(r) for r in results)
    arrays = {"X": np.zeros((S, n_max, 5), np.float32), "X_next": np.zeros((S, n_max, 5), np.float32),
              "mask": np.zeros((S, n_max), bool), "action": np.zeros((S, 4), np.int64),
              "n": np.zeros(S, np.int64), "grasped": np.zeros(S, np.int64), "status": np.zeros(S, np.int64)}
    s = 0
    for r in results:
        m, n = r.X.shape[:2]
        rows = slice(s, s + m)
        arrays["X"][rows, :n] = r.X
        arrays["X_next"][rows, :n] = r.X_next
        arrays["mask"][rows, :n] = True
        arrays["action"][rows] = r.action
        arrays["n"][rows] = n
        arrays["grasped"][rows] = r.grasped
        arrays["status"][rows] = r.status
        s += m
    return arrays


@dataclass
class CollectReport:
    directory: Path
    samples: int  # in the finished dataset
    new_samples: int  # computed by this run
    shards: int
    shards_written: int
    shards_recollected: list[str]  # names of corrupt shards found and recomputed
    seconds: float  # wall clock of this run
    progress: list[tuple[float, int]] = field(default_factory=list)  # (seconds, new samples so far)

    def rate(self, start_fraction: float = 0.0) -> float:
        """New samples per second, measured from `start_fraction` of this run's samples on."""
        if not self.progress or self.new_samples == 0:
            return 0.0
        t0, s0 = (0.0, 0)
        for t, s in self.progress:
            if s >= start_fraction * self.new_samples:
                break
            t0, s0 = t, s
        t1, s1 = self.progress[-1]
        return (s1 - s0) / max(t1 - t0, 1e-9)


def collect(out: str | Path, cfg: CollectConfig, workers: int | None = None, backend: str = "local",
            address: str | None = None, progress: bool = True) -> CollectReport:
    """Collect (or finish collecting) the dataset `cfg` into directory `out`.

    workers: local processes, or Ray actors (default: the CPUs of this machine, or of the Ray
    cluster at `address`). Returns what was done; the data do not depend on workers or backend.
    """
    from tqdm import tqdm

    from learned.dataset import write_shard

    if backend not in BACKENDS:
        raise UserError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if address and backend != "ray":
        raise UserError("--address joins a Ray cluster; use it with --backend ray")
    if workers is not None and workers < 1:
        raise UserError(f"--workers must be at least 1, got {workers}")
    if backend == "ray":
        import_ray()  # fail before touching the directory
    out = Path(out)
    t_start = time.perf_counter()
    meta = cfg.meta()
    with output_dir(out, "--out", own=("meta.json",), into_existing=True), exclusive(out, LOCK_NAME, "tamp collect"):
        good, bad = prepare_directory(out, cfg, meta)
        missing = [j for j in range(cfg.n_shards) if j not in good]
        done = sum(cfg.shard_samples(j) for j in good)
        tasks = [SceneTask(cfg.seed, k, cfg.objects, cfg.scene_samples(k), cfg.sampling) for j in missing
                 for k in cfg.shard_scenes(j)]
        report = CollectReport(out, cfg.samples, cfg.samples - done, cfg.n_shards, 0, bad, 0.0)
        if tasks:
            results = run_tasks(tasks, SceneWorker, (cfg.world.to_dict(),), workers=workers, backend=backend,
                                address=address)
            pending: dict[int, dict[int, SceneResult]] = {j: {} for j in missing}
            new = 0
            bar = tqdm(total=cfg.samples, initial=done, unit="sample", dynamic_ncols=True,
                       smoothing=0.05, disable=not progress, file=sys.stderr)
            t_run = time.perf_counter()
            try:
                for result in results:
                    j = result.k // cfg.scenes_per_shard
                    pending[j][result.k] = result
                    if len(pending[j]) == len(cfg.shard_scenes(j)):
                        by_scene = pending.pop(j)
                        scenes = [by_scene[k] for k in cfg.shard_scenes(j)]
                        write_shard(out / shard_name(j), pack_shard(scenes, cfg.n_max), cfg.n_max,
                                    sorted(STATUS_CODES.values()))
                        report.shards_written += 1
                    new += len(result)
                    report.progress.append((time.perf_counter() - t_run, new))
                    bar.update(len(result))
            finally:
                bar.close()
                if hasattr(results, "close"):
                    results.close()  # stops the pool or the Ray actors
    report.seconds = time.perf_counter() - t_start
    return report
