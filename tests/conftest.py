import os
import sys
from pathlib import Path

import pytest
from _pytest.mark.expression import Expression

# Keep the suite's torch and BLAS work on one thread each: the machine has 2 cores.
os.environ.setdefault("OMP_NUM_THREADS", "1")

SIM_FILE_MARK = "pytestmark = pytest.mark.sim"
_first_drake_test: list[str] = []  # the first test after which pydrake was loaded


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


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item):
    yield
    if not _first_drake_test and "pydrake" in sys.modules:
        _first_drake_test.append(item.nodeid)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Regression check of the markers: a session that leaves out the simulator tests
    (-m "not sim") must not load Drake; a test that does needs the `sim` marker."""
    if _excludes_sim(session.config) and "pydrake" in sys.modules:
        where = f"after {_first_drake_test[0]}" if _first_drake_test else "while collecting"
        session.config.get_terminal_writer().line(
            f"\nERROR: pydrake was imported in a session without the simulator tests ({where}); "
            "mark that test (or its file) with pytest.mark.sim", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
