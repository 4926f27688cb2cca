"""`tamp simulate`: text and JSON output, the Meshcat replay, and clear errors for bad arguments."""
import json

import pytest

from tamp.app.cli import main


@pytest.mark.sim
def test_simulate_prints_one_line_per_action_and_writes_replay(tmp_path, capsys):
    out = tmp_path / "replay.html"
    assert main(["simulate", "--objects", "3", "--seed", "1", "--steps", "3", "--replay", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    steps = [line for line in lines if line.startswith("step ")]
    assert len(steps) == 3
    assert all("ms (IK" in line for line in steps)
    html = out.read_text()
    assert out.stat().st_size > 100_000  # self-contained: scripts and geometry inlined
    assert "<html" in html.lower() and "meshcat" in html.lower()
    assert "localhost" not in html.split("<script", 1)[0]  # nothing loaded from a server


@pytest.mark.sim
def test_simulate_json_is_reproducible(capsys):
    assert main(["simulate", "--objects", "2", "--seed", "4", "--steps", "3", "--json"]) == 0
    first = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert main(["simulate", "--objects", "2", "--seed", "4", "--steps", "3", "--json"]) == 0
    second = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(first) == 4 and "X" in first[0]
    strip = lambda rows: [{k: v for k, v in r.items() if k != "timings"} for r in rows]  # noqa: E731
    assert strip(first) == strip(second)
    assert {r["status"] for r in first[1:]} <= {"ok", "ik_failure", "motion_failure", "nothing_grasped"}


@pytest.mark.sim
@pytest.mark.parametrize("argv, message", [
    (["simulate", "--objects", "9"], "n_objects must be an integer in 1..8"),
])
def test_simulate_user_errors_exit_2_without_traceback(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_simulate_rejects_non_html_replay(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "--replay", "out.txt"])
    assert exit_info.value.code == 2
    assert "ending in .html" in capsys.readouterr().err
