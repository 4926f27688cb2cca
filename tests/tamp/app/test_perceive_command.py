"""`tamp perceive`: a problem's initial scene rendered by the rig, each block's estimate printed against the truth;
bad input refused in one line."""
import json

import pytest

from tamp.app.cli import main

pytestmark = pytest.mark.sim  # renders with Drake

PROBLEM = {"X_init": [[0.60, 0.15, 0.025, 1, 0], [0.70, -0.10, 0.025, 0, 1]],
           "X_goal": [[0.70, -0.10, 0.075, 1, 0], [0.70, -0.10, 0.025, 0, 1]], "k": 1, "seed": 7}


def test_perceive_prints_each_block_against_the_truth(tmp_path, capsys):
    path = tmp_path / "p.json"
    path.write_text(json.dumps(PROBLEM))
    assert main(["perceive", "--problem", str(path), "--cameras", "above,front"]) == 0
    out = capsys.readouterr().out
    assert "2 blocks; 2 cameras (above, front) at 640x480, noise on (seed 7)" in out
    assert out.count("type right") == 2 and "block 1 large on the table" in out
    assert "2 of 2 blocks found, 2 estimates" in out
    mm = [float(line.split("position ")[1].split(" mm")[0]) for line in out.splitlines() if "position " in line]
    assert len(mm) == 2 and max(mm) < 3.0


@pytest.mark.parametrize("argv, message", [
    (["--problem", "{missing}"], "no problem file at"),
    (["--problem", "{bad}"], "not valid JSON"),
    (["--problem", "{good}", "--cameras", "above,top"], "expected cameras among above,front,left,right"),
])
def test_bad_input_is_one_line(tmp_path, capsys, argv, message):
    (tmp_path / "bad.json").write_text("{")
    (tmp_path / "good.json").write_text(json.dumps(PROBLEM))
    paths = {"missing": tmp_path / "none.json", "bad": tmp_path / "bad.json", "good": tmp_path / "good.json"}
    argv = [a.format(**paths) for a in argv]
    try:
        code = main(["perceive", *argv])
    except SystemExit as exit:  # argparse refuses a bad flag value itself
        code = exit.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
