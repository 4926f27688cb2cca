"""What a planning call reports of its stages: each stage's own time, whatever runs inside it."""
import pytest

from tamp.planning.results import Clock


def test_a_stage_opened_inside_another_pauses_it(monkeypatch):
    ticks = iter([0.0, 1.0, 3.0, 6.0, 6.5, 7.0])  # search opens, refine opens and closes, search closes, verify
    monkeypatch.setattr("tamp.planning.results.time.perf_counter", lambda: next(ticks))
    clock = Clock()
    with clock.stage("search"):
        with clock.stage("refine"):
            pass
    with clock.stage("verify"):
        pass
    assert clock.seconds == pytest.approx({"search": 4.0, "refine": 2.0, "verify": 0.5})


def test_a_stage_that_raises_is_still_timed_and_closed():
    clock = Clock()
    with pytest.raises(ValueError):
        with clock.stage("symbolic"):
            raise ValueError("no plan")
    with clock.stage("verify"):
        pass
    assert set(clock.seconds) == {"symbolic", "verify"} and all(s >= 0 for s in clock.seconds.values())
