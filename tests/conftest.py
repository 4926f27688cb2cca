import ast
import functools
import gc
import hashlib
import os
import sys
from pathlib import Path

import pytest
from _pytest.mark.expression import Expression

# Keep the suite's torch and BLAS work on one thread each: the machine has 2 cores.
os.environ.setdefault("OMP_NUM_THREADS", "1")

SIM_FILE_MARK = "pytestmark = pytest.mark.sim"
_first_drake_test: list[str] = []  # the first test after which pydrake was loaded
_workers_with_drake: list[str] = []  # under pytest-xdist: the same, of each worker that loaded it


@pytest.fixture(scope="session", autouse=True)
def _each_domain_read_once():
    """An operators file is parsed and checked once per test process: `symbolic.load_domain` (which
    `load_models` calls) gives the OperatorSet read before from a file of the same bytes (a copied domain and
    the bundled sets that share one domain included: the set does not depend on the file's path). The
    bundled domains take 1-4 s each to read, and the suite loads them about 90 times; a file that fails to
    load goes through the reader every time, so its error names it."""
    import symbolic.build

    read = symbolic.build.load_operators
    known: dict[bytes, object] = {}

    def load_operators(path):
        try:
            key = hashlib.blake2b(Path(path).read_bytes()).digest()
        except OSError:
            return read(path)  # the reader names what is missing
        if key not in known:
            known[key] = read(path)
        return known[key]

    symbolic.build.load_operators = load_operators
    yield
    symbolic.build.load_operators = read


def _selects(config: pytest.Config, marks: set[str]) -> bool:
    """Whether the session's -m expression keeps a test carrying exactly `marks`."""
    expression = config.getoption("markexpr")
    return not expression or Expression.compile(expression).evaluate(lambda name: name in marks)


def _excludes_sim(config: pytest.Config) -> bool:
    """True when -m leaves out every simulator test (with or without the other markers)."""
    return not any(_selects(config, {"sim", *others}) for others in (set(), {"slow"}))


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """Files marked sim as a whole are not even imported when -m leaves out the simulator tests
    (importing them would load pydrake)."""
    if collection_path.suffix == ".py" and collection_path.name.startswith("test_") and _excludes_sim(config):
        if SIM_FILE_MARK in collection_path.read_text():
            return True
    return None


@functools.cache
def _file_facts(path: Path) -> tuple[bool, frozenset[str] | None]:
    """Of a test file: whether it defines a module-scoped fixture (a World, a trained model, a collected
    dataset), and the names of its tests marked slow (None: all of them)."""
    shared, slow = False, set()
    tree = ast.parse(path.read_text()) if path.suffix == ".py" else ast.Module(body=[], type_ignores=[])
    for node in tree.body:
        if isinstance(node, ast.Assign) and "pytestmark" in map(ast.unparse, node.targets):
            slow = None if "mark.slow" in ast.unparse(node.value) else slow
        elif isinstance(node, ast.FunctionDef):
            decorators = [ast.unparse(d) for d in node.decorator_list]
            shared |= any(d.startswith("pytest.fixture(") and "scope='module'" in d for d in decorators)
            if slow is not None and any("mark.slow" in d for d in decorators):
                slow.add(node.name)
    return shared, None if slow is None else frozenset(slow)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """pytest-xdist's `load` distribution (`make test` runs `-n 2`) in units: the tests of a file with a
    module-scoped fixture go to one worker, which builds the fixture once; every other test is a unit of its
    own. Units with the most slow tests go first, so that no long test starts when the other worker is done.
    (xdist's own `--dist loadgroup` rewrites node ids, which pytest 9.2 no longer allows.)"""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    def facts(nodeid: str) -> tuple[bool, frozenset[str] | None]:
        return _file_facts(config.rootpath / nodeid.split("::", 1)[0])

    def cost(nodeid: str) -> int:
        slow = facts(nodeid)[1]
        return 10 if slow is None or nodeid.split("::")[-1].split("[")[0] in slow else 1

    class SharedFixtureScheduling(LoadScopeScheduling):
        ordered = False

        def _split_scope(self, nodeid: str) -> str:
            return nodeid.split("::", 1)[0] if facts(nodeid)[0] else nodeid

        def _assign_work_unit(self, node) -> None:
            if not self.ordered:
                self.ordered = True
                units = sorted(self.workqueue.items(), key=lambda unit: -sum(map(cost, unit[1])))
                self.workqueue.clear()
                self.workqueue.update(units)
            super()._assign_work_unit(node)

    return SharedFixtureScheduling(config, log)


def pytest_collection_finish(session: pytest.Session) -> None:
    """What is loaded by now (the packages, the collected tests) lives as long as the session: the cyclic garbage
    collector leaves it alone from here on (its full passes over it took a tenth of the suite's time)."""
    gc.freeze()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item):
    yield
    if not _first_drake_test and "pydrake" in sys.modules:
        _first_drake_test.append(item.nodeid)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:
    """pytest-xdist: the controller collects what each worker's session loaded (see pytest_sessionfinish)."""
    if getattr(node, "workeroutput", {}).get("pydrake_loaded"):
        _workers_with_drake.append(node.workeroutput.get("first_drake_test") or "")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Regression check of the markers: a session that leaves out the simulator tests
    (-m "not sim") must not load Drake; a test that does needs the `sim` marker. Under pytest-xdist the
    workers report to the controller, which makes the check."""
    loaded = "pydrake" in sys.modules
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:  # an xdist worker
        workeroutput["pydrake_loaded"] = loaded
        workeroutput["first_drake_test"] = _first_drake_test[0] if _first_drake_test else None
        return
    first = _first_drake_test[:1] or [name for name in _workers_with_drake if name][:1]
    if _excludes_sim(session.config) and (loaded or _workers_with_drake):
        where = f"after {first[0]}" if first else "while collecting"
        session.config.get_terminal_writer().line(
            f"\nERROR: pydrake was imported in a session without the simulator tests ({where}); "
            "mark that test (or its file) with pytest.mark.sim", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
