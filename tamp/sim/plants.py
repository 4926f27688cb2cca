"""Drake plants of the block world, built from our own model files in `drake_models/`.

Two plants, each built once per scene layout (block types):
- the motion plant (arm + gripper + table + free blocks) behind the `SceneGraphCollisionChecker`
  that validates OMPL motions, and behind forward kinematics and Meshcat replays;
- the physics plant (table + free blocks, hydroelastic contact) that decides what a released
  block does. The arm is not in it: in the `fast` fidelity the gripper leaves with its jaws open.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence, cast

import numpy as np
from pydrake.common import Parallelism
from pydrake.geometry import Box
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    CoulombFriction,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.multibody.tree import ModelInstanceIndex, QuaternionFloatingJoint, RigidBody, SpatialInertia
from pydrake.planning import RobotDiagramBuilder, SceneGraphCollisionChecker
from pydrake.systems.framework import Diagram, DiagramBuilder

from tamp.planning.vocabulary import LARGE, SMALL

logging.getLogger("drake").setLevel(logging.WARNING)  # keep Drake's INFO lines off the console

MODEL_DIR = Path(__file__).resolve().parents[2] / "drake_models"
ARM_FILE = MODEL_DIR / "ur10e.urdf"
GRIPPER_FILE = MODEL_DIR / "gripper.sdf"
TABLE_FILE = MODEL_DIR / "table.sdf"
BLOCK_FILES = {SMALL: MODEL_DIR / "small_block.sdf", LARGE: MODEL_DIR / "large_block.sdf"}

# The arm's base on the table, yawed so that the UR10e's DH frame 0 (arm along -x at q = 0) faces +x.
# (pydrake's stubs type vectors as ndarray[float64[3, 1]], which neither a list nor an array matches)
X_WBase = RigidTransform(RotationMatrix.MakeZRotation(np.pi), [0.0, 0.0, 0.0])  # type: ignore[call-overload]
# Grasp point (tcp) in the flange frame: see drake_models/gripper.sdf.
# (pydrake's stubs type vectors as ndarray[float64[3, 1]], which neither a list nor an array matches)
X_FlangeTcp = RigidTransform([0.0, 0.0, 0.125])  # type: ignore[call-overload]
ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


def add_arm_gripper_table(plant: MultibodyPlant, parser: Parser) -> tuple[ModelInstanceIndex, ModelInstanceIndex]:
    (arm,) = parser.AddModels(ARM_FILE)
    (gripper,) = parser.AddModels(GRIPPER_FILE)
    (table,) = parser.AddModels(TABLE_FILE)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm), X_WBase)
    plant.WeldFrames(plant.GetFrameByName("tool0", arm), plant.GetFrameByName("gripper_base", gripper))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("table_top", table))
    return arm, gripper


def add_blocks(parser: Parser, types: np.ndarray) -> list[ModelInstanceIndex]:
    parser.SetAutoRenaming(True)
    blocks = []
    for t in types:
        (block,) = parser.AddModels(BLOCK_FILES[int(t)])
        blocks.append(block)
    return blocks


@dataclass(frozen=True)
class StandIn:
    """A box that stands in for a carried block: a body on a floating joint to the gripper, so that a carried
    box is posed by setting joint positions instead of adding a shape to the collision checker (0.35 ms)."""

    size: tuple[float, float, float]  # metres
    body: RigidBody
    position_start: int  # its joint's 7 positions in the plant's (quaternion wxyz, then translation)


@dataclass
class MotionScene:
    """Arm, gripper, table and free blocks, with a collision checker over the full plant state."""

    diagram: Diagram
    plant: MultibodyPlant
    checker: SceneGraphCollisionChecker
    arm: ModelInstanceIndex
    gripper: ModelInstanceIndex
    blocks: list[ModelInstanceIndex]
    stand_ins: list[StandIn] = field(default_factory=list)

    @property
    def gripper_body(self):
        return self.plant.GetBodyByName("gripper_base", self.gripper)

    def block_body(self, i: int):
        return self.plant.get_body(self.plant.GetBodyIndices(self.blocks[i])[0])


def build_motion_scene(types: np.ndarray, padding: float, edge_step: float = 0.02,
                       stand_ins: Sequence[tuple[float, float, float]] = ()) -> MotionScene:
    """The motion plant for blocks of `types`; the checker's robot is the arm and its gripper, and one `StandIn`
    box of each size in `stand_ins` (metres) on a floating joint to the gripper. A stand-in collides as a shape
    attached to the gripper body would: not with the gripper, nor with what the gripper is filtered against,
    nor with the other stand-ins."""
    builder = RobotDiagramBuilder(time_step=0.0)
    plant = builder.plant()
    parser = builder.parser()
    arm, gripper = add_arm_gripper_table(plant, parser)
    blocks = add_blocks(parser, types)
    robot = [arm, gripper]
    joints = []
    if stand_ins:
        instance = plant.AddModelInstance("stand_ins")
        robot.append(instance)
        gripper_frame = plant.GetBodyByName("gripper_base", gripper).body_frame()
        for k, size in enumerate(stand_ins):
            body = plant.AddRigidBody(f"stand_in_{k}", instance, SpatialInertia.SolidBoxWithMass(0.1, *size))
            plant.RegisterCollisionGeometry(body, RigidTransform(), Box(*size), f"stand_in_{k}",
                                            CoulombFriction(0.5, 0.5))
            joint = plant.AddJoint(QuaternionFloatingJoint(f"stand_in_{k}", gripper_frame, body.body_frame()))
            sx, sy, sz = (float(v) for v in size)
            joints.append(((sx, sy, sz), body, joint))
    plant.Finalize()
    diagram = cast(Diagram, builder.Build())  # pydrake's stubs type Build() as object
    checker = SceneGraphCollisionChecker(  # type: ignore[call-arg]  # the stubs lack its keyword constructor
        model=diagram,
        robot_model_instances=robot,
        edge_step_size=edge_step,
        env_collision_padding=padding,
        self_collision_padding=0.0,
        implicit_context_parallelism=Parallelism(1),  # one thread per world; parallelism comes from processes
    )
    scene = MotionScene(diagram, plant, checker, arm, gripper, blocks,
                        [StandIn(size, body, joint.position_start()) for size, body, joint in joints])
    gripper_body = scene.gripper_body
    filtered = [plant.get_body(b) for b in plant.GetBodyIndices(arm) + plant.GetBodyIndices(gripper)
                if checker.IsCollisionFilteredBetween(gripper_body, plant.get_body(b))]
    for k, stand_in in enumerate(scene.stand_ins):
        for body in [gripper_body, *filtered, *(s.body for s in scene.stand_ins[:k])]:
            checker.SetCollisionFilteredBetween(stand_in.body, body, True)
    return scene


@dataclass
class PhysicsScene:
    """Table and free blocks under hydroelastic contact."""

    diagram: Diagram
    plant: MultibodyPlant
    blocks: list[ModelInstanceIndex]


def build_physics_scene(types: np.ndarray, time_step: float) -> PhysicsScene:
    """Box-on-box contact needs hydroelastic contact and the lagged solver (see BUILD_NOTES.md)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=time_step)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kLagged)
    from pydrake.multibody.plant import ContactModel

    plant.set_contact_model(ContactModel.kHydroelasticWithFallback)
    parser = Parser(plant)
    (table,) = parser.AddModels(TABLE_FILE)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("table_top", table))
    blocks = add_blocks(parser, types)
    plant.Finalize()
    diagram = builder.Build()
    return PhysicsScene(diagram, plant, blocks)
