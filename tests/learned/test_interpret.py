"""`tamp symbols` / learned.interpret: a bit that is a geometric fact is recognised as that fact; a
constant bit is not credited for agreeing with a rare fact; the CLI prints the table and writes
the PNG and JSON."""
import json

import numpy as np
import pytest

from learned.interpret import interpret_symbols, relation_facts, summarize_symbols, unary_facts

ON_BAR = np.array([[0.6, 0.0, 0.025, 0, 1], [0.6, 0.05, 0.075, 1, 0], [0.75, 0.2, 0.025, 1, 0]])
FLAT = np.array([[0.5, -0.1, 0.025, 1, 0], [0.7, 0.1, 0.025, 0, 1], [0.8, 0.3, 0.025, 1, 0]])


def test_facts_of_a_cube_on_a_bar():
    u = unary_facts(ON_BAR)
    assert u["on another block"].tolist() == [False, True, False]
    assert u["carries a block"].tolist() == [True, False, False]
    assert u["large (type)"].tolist() == [True, False, False]
    assert u["elevated (z > 4 cm)"].tolist() == [False, True, False]
    r = relation_facts(ON_BAR)
    assert np.argwhere(r["i on j"]).tolist() == [[1, 0]] and np.argwhere(r["j on i"]).tolist() == [[0, 1]]
    assert r["near (< 10 cm)"][0, 1] and not r["near (< 10 cm)"][0, 2]
    assert np.argwhere(r["i above j"]).tolist() == [[1, 0]] and np.argwhere(r["j above i"]).tolist() == [[0, 1]]
    assert r["z_j > z_i (j higher)"][0, 1] and not r["z_j > z_i (j higher)"][1, 0]
    assert r["aligned in x (|dx| < 2 cm)"][0, 1] and not r["aligned in x (|dx| < 2 cm)"][0, 2]
    assert r["same level (|dz| < 2 cm)"][0, 2] and not r["same level (|dz| < 2 cm)"][0, 1]
    assert not relation_facts(FLAT)["i on j"].any()


def test_a_fact_bit_is_recognised_and_a_constant_bit_is_not_credited():
    def symbols(X):
        u = np.stack([X[:, 2] > 0.04, np.zeros(len(X), bool)], axis=1)  # elevated; always 0
        return u.astype(np.uint8), relation_facts(X)["j on i"][None].astype(np.uint8)

    report = {b.name: b for b in interpret_symbols(symbols, [ON_BAR, FLAT] * 3)}
    assert report["u0"].best == "elevated (z > 4 cm)" and report["u0"].agreement["elevated (z > 4 cm)"] == 1.0
    assert report["u0"].phi["elevated (z > 4 cm)"] == pytest.approx(1.0) and report["u0"].rate == pytest.approx(1 / 6)
    # always 0: it 'agrees' with the rare fact 'on another block' on 5 of 6 objects, but phi is 0
    assert report["u1"].agreement["on another block"] == 5 / 6 and report["u1"].phi["on another block"] == 0.0
    assert report["r0"].best == "j on i" and report["r0"].phi["j on i"] == pytest.approx(1.0)
    assert report["r0"].count == 36
    assert report["r0"].phi["i on j"] < 0.0  # the reverse relation is not mistaken for it


def test_the_summary_counts_spatial_constant_and_type_bits_and_goals_that_read_like_their_scene():
    def symbols(X):
        r = relation_facts(X)
        rel = np.stack([r["j on i"], r["same type"], np.zeros((len(X), len(X)), bool)])
        return (X[:, 2:3] > 0.04).astype(np.uint8), rel.astype(np.uint8)

    report = interpret_symbols(symbols, [ON_BAR, FLAT] * 3)
    moved = FLAT.copy()
    moved[0, 0] += 0.2  # slid across the table: no fact above changes
    summary = summarize_symbols(report, symbols, [(FLAT, ON_BAR), (FLAT, moved)])
    assert summary.spatial == ["r0"]
    assert summary.typed == ["r1"]
    assert "r2" in summary.constant and "r0" not in summary.constant
    assert (summary.goals_like_init, summary.goals) == (1, 2)
    assert "1 of 2 (50.0 %)" in summary.lines()[-1]


def test_cli_prints_the_table_and_writes_png_and_json(tmp_path, capsys):
    import torch

    from evaluation.problems import write_problems
    from learned import EffectModel, ModelConfig, save_checkpoint
    from tamp.app.cli import main
    from tamp.app.problem import Problem

    torch.manual_seed(0)
    save_checkpoint(tmp_path / "sym.pt", EffectModel(ModelConfig(d_z=2, heads=1, activation="gumbel_sigmoid")))
    write_problems(tmp_path / "p.jsonl", [Problem(ON_BAR, ON_BAR, name="a"), Problem(FLAT, FLAT, name="b")])
    assert main(["symbols", "--model", str(tmp_path / "sym.pt"), "--problems", str(tmp_path / "p.jsonl"),
                 "--png", str(tmp_path / "s.png"), "--json", str(tmp_path / "s.json")]) == 0
    out = capsys.readouterr().out
    assert "read on 4 scenes" in out and "| u1 | 12 |" in out and "| r0 | 24 |" in out and "| r0(i,i) | 12 |" in out
    assert [b["name"] for b in json.loads((tmp_path / "s.json").read_text())] == ["u0", "u1", "r0", "r0(i,i)"]
    assert (tmp_path / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["symbols", "--model", str(tmp_path / "sym.pt")]) == 2
    assert "exactly one of --problems" in capsys.readouterr().err
