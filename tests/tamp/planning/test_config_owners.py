"""Every threshold of the planner has one owner, and a stage reads only the parts of the configuration it is given.

The stages (Level 1, Level 2 and its search, the kinematic check, verification) take their own part of
`PlanConfig` and `VerifyConfig` (what counts as the goal); only the planners that compose them hold the whole.
"""
import ast
from dataclasses import fields

from tamp.planning.config import PlanConfig
from tests.paths import ROOT

STAGES = ("level1.py", "level2.py", "search.py", "kinematic_check.py", "verify.py")
# LoopConfig.stall is the closed loop's own cut for its rounds' searches, in place of SearchConfig.stall
SHARED_ON_PURPOSE = {"stall"}


def test_no_setting_is_defined_in_two_parts_of_the_configuration():
    owners: dict[str, list[str]] = {}
    for part in fields(PlanConfig):
        for field in fields(getattr(PlanConfig(), part.name)):
            owners.setdefault(field.name, []).append(part.name)
    assert owners["eps"] == ["verify"] and owners["confident"] == ["verify"]
    assert {name for name, parts in owners.items() if len(parts) > 1} == SHARED_ON_PURPOSE


def test_stages_never_see_the_whole_configuration():
    for name in STAGES:
        tree = ast.parse((ROOT / "tamp" / "planning" / name).read_text())
        seen = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
        seen |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) for alias in node.names}
        assert "PlanConfig" not in seen, f"tamp/planning/{name} takes the whole PlanConfig"
