"""The evaluation's writers on a full disk (ENOSPC): `tamp reproduce`, `pool`, `compare` and `refinability` end in
one line naming the path, with exit status 2, and leave the disk's folder as they found it."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests import test_no_data_loss as shared
from tests.tamp.app import test_outputs as outputs
from tests.test_no_data_loss import refused_on_full_disk

pytestmark = pytest.mark.sim
full_disk = shared.full_disk
problem, results = outputs.problem, outputs.results  # a one-action problem and its one-row results directory


def test_full_disk_reproduce(capsys, full_disk, tmp_path):
    refused_on_full_disk(capsys, full_disk, ["reproduce", "--out", str(full_disk / "rep"), "--models", "pretrained",
                                             "--workers", "1"])


def test_full_disk_pool_and_compare(capsys, full_disk, tmp_path, results: Path):
    first, second = tmp_path / "a", tmp_path / "b"
    shutil.copytree(results, first)
    shutil.copytree(results, second)
    refused_on_full_disk(capsys, full_disk, ["pool", str(full_disk / "pooled"), str(first), str(second)])
    refused_on_full_disk(capsys, full_disk, ["compare", str(first), str(second), "--out", str(full_disk / "c.md")])


def test_full_disk_refinability(capsys, full_disk, problem: Path):
    refused_on_full_disk(capsys, full_disk, ["refinability", "--models", "pretrained", "--problems", str(problem),
                                             "--out", str(full_disk / "r"), "--methods", "cfs", "--quiet"])
