"""Independent tasks on workers that each hold one costly object (a World, an Evaluator): in this
process, in a local spawn pool, or on Ray actors (a local Ray cluster, or the one at `address`).

`tamp collect` and `tamp evaluate` share it. A worker is built once by `make(*args)` (a picklable
top-level function) and answers `worker.run(task)`; results come back in completion order. Pool
workers exit when their parent dies (kill -9 included), so no orphan keeps computing. Pool workers
ignore SIGINT from their first instruction on: Ctrl-C in a terminal reaches the whole process group,
and the parent alone answers it (it stops the pool, the command exits with status 130); a worker still
importing would otherwise print a KeyboardInterrupt traceback.
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import os
import signal
import threading
import time
from contextlib import contextmanager
from typing import Any, Callable, Generator, Iterator, Protocol, Sequence

from tamp.app.args import WORKERS_LIMIT, Count
from tamp.errors import UserError

BACKENDS = ("local", "ray")


class Worker(Protocol):
    def run(self, task: Any) -> Any: ...


def available_cpus() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def import_ray():
    """The ray module, or a UserError that says how to install it."""
    try:
        import ray
    except ImportError:
        raise UserError("--backend ray needs Ray: pip install 'bilevel-tamp[ray]' "
                        "(or pip install ray) into this environment") from None
    return ray


def run_tasks(tasks: Sequence[Any], make: Callable[..., Worker], args: tuple = (), *, workers: int | None = None,
              backend: str = "local", address: str | None = None) -> Generator[Any, None, None]:
    """`make(*args).run(task)` for every task, on `workers` workers (default: all CPUs, of the Ray
    cluster at `address` if given), in completion order. Close the generator to stop the workers
    (`contextlib.closing`), also when the caller is interrupted between two results."""
    if backend not in BACKENDS:
        raise UserError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if address and backend != "ray":
        raise UserError("--address joins a Ray cluster; use it with --backend ray")
    if not tasks:
        return _nothing()
    if backend == "ray":
        return _run_ray(tasks, make, args, workers, address)
    return _run_local(tasks, make, args, min(workers or available_cpus(), len(tasks)))


def _nothing() -> Generator[Any, None, None]:
    yield from ()


# --------------------------------------------------------------------------- local processes

_WORKER: Worker | None = None  # the one worker object of a pool process


def _init_pool_worker(make: Callable[..., Worker], args: tuple, parent_pid: int) -> None:
    """Pool initializer: build the worker, and exit if the parent dies. (SIGINT is ignored already, see
    `_children_ignore_sigint`; this covers a worker the pool starts again later.)"""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()
    global _WORKER
    _WORKER = make(*args)


def _pool_run(task: Any) -> Any:
    assert _WORKER is not None, "pool worker used before its initializer ran"
    return _WORKER.run(task)


def _run_local(tasks: Sequence[Any], make: Callable[..., Worker], args: tuple,
               workers: int) -> Generator[Any, None, None]:
    if workers == 1:
        worker = make(*args)
        for task in tasks:
            yield worker.run(task)
        return
    ctx = mp.get_context("spawn")
    with _children_ignore_sigint():
        pool = ctx.Pool(workers, initializer=_init_pool_worker, initargs=(make, args, os.getpid()))
    with pool:
        yield from pool.imap_unordered(_pool_run, tasks, chunksize=1)


@contextmanager
def _children_ignore_sigint() -> Iterator[None]:
    """Processes started in the block ignore SIGINT from their start: a spawned child inherits an ignored
    signal, and Python then installs no KeyboardInterrupt handler. The parent's handler is back after
    the block (a few milliseconds: the workers' fork and exec)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


# --------------------------------------------------------------------------- Ray

class _RayWorker:
    """A Ray actor (wrapped with ray.remote at run time) holding one worker object."""

    def __init__(self, make: Callable[..., Worker], args: tuple) -> None:
        self.worker = make(*args)

    def run(self, task: Any) -> Any:
        return self.worker.run(task)


def _run_ray(tasks: Sequence[Any], make: Callable[..., Worker], args: tuple, workers: int | None,
             address: str | None) -> Generator[Any, None, None]:
    """Every node of an existing cluster must have this package installed (same versions)."""
    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here:
        kwargs: dict[str, Any] = dict(include_dashboard=False, logging_level=logging.WARNING, log_to_driver=True)
        if address:
            ray.init(address=address, **kwargs)
        else:
            # Ray starts its worker processes at niceness 15, below everything else on the machine; here the actors
            # are the job itself, as the local pool's processes are, so they run at the user's priority (on a busy
            # 2-core machine the niced actor collected 4.7x slower). RAY_worker_niceness set by the user wins.
            os.environ.setdefault("RAY_worker_niceness", "0")
            ray.init(num_cpus=workers or available_cpus(), **kwargs)
    try:
        n_actors = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        Actor = ray.remote(num_cpus=1)(_RayWorker)
        actors = [Actor.remote(make, args) for _ in range(min(n_actors, len(tasks)))]
        todo, pending = iter(tasks), {}

        def submit(actor) -> None:
            task = next(todo, None)
            if task is not None:
                pending[actor.run.remote(task)] = actor

        for actor in actors * 2:  # two tasks in flight per actor hide the round trip
            submit(actor)
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            submit(pending.pop(done[0]))
            yield ray.get(done[0])
    finally:
        if started_here:
            ray.shutdown()


def add_arguments(p, workers_default: int | None = None) -> None:
    """--workers, --backend and --address, the same for collect, evaluate and reproduce."""
    default = "all CPUs, of the cluster with --address" if workers_default is None else str(workers_default)
    p.add_argument("--workers", type=Count(1, WORKERS_LIMIT), default=workers_default,
                   help=f"worker processes or Ray actors (default: {default})")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local process pool (default) or Ray actors (optional extra: pip install 'bilevel-tamp[ray]')")
    p.add_argument("--address", default=None,
                   help="with --backend ray: join this Ray cluster (e.g. auto or HOST:6379; every node needs this "
                   "package installed) instead of starting a local one")
