"""Full-fidelity execution: the arm follows the refined trajectory under Drake physics.

The plant holds the arm, the gripper, the table and the blocks, with hydroelastic contact. Each arm
joint is a PD-controlled actuator (Drake's implicit PD in the discrete solver) tracking the
trajectory's position and velocity; gravity is off for the arm and gripper, as a real UR's
controller compensates it, and the weight of the carried blocks is compensated by a feed-forward
torque J^T m g, as a UR compensates its configured payload (without it the loaded arm sags by a
millimetre or more, enough to set a block down on an edge it was planned to clear). The gripper
holds a block with a **weld constraint** activated when the jaws close and removed when they open:
the jaws are rigid and open (see drake_models/gripper.sdf), so a weld gives the firm grasp of a real
parallel gripper without finger contact dynamics. The weld holds the block at the planned grasp; if,
at the moment of closing, the block is not where the plan expects it between the jaws (more than
GRASP_TOLERANCE away), nothing is welded and the log says the grasp missed. Blocks resting on the
grasped one ride on it by contact. After each action the arm holds still until every block is at
rest (as in the `fast` world).

The diagram is built once per block layout and reused for every plan. Drake 1.51 fixes a weld
constraint's frames (X_AP, X_BQ) when it is added, before Finalize; only its active status lives in
the context. The grasp, which differs per action, is therefore a context parameter of its own: a
massless `grasp` body welded to the gripper at a `FixedOffsetFrame` whose pose in the gripper
(`SetPoseInParentFrame`) is set to each action's planned grasp, and one weld constraint per block
between that body and the block, all inactive until their block is grasped.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, ContactModel, DiscreteContactApproximation
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    JacobianWrtVariable,
    JointActuatorIndex,
    PdControllerGains,
    SpatialInertia,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from tamp.sim.observer import PhysicsFrame, WorldObserver
from tamp.sim.physics import blocks_at_rest
from tamp.sim.plants import X_FlangeTcp, add_arm_gripper_table, add_blocks
from tamp.sim.skill import Scene
from tamp.sim.trajectory import RefinedAction, RefinedPlan
from tamp.sim.world_types import ExecutedAction, WorldConfig

KP = np.array([4000.0, 4000.0, 2000.0, 500.0, 500.0, 300.0])  # N m / rad
KD = np.array([400.0, 400.0, 200.0, 50.0, 50.0, 30.0])  # N m s / rad
GRASP_TOLERANCE = 0.015  # metres between the planned and the actual grasped block position
FRAME_PERIOD = 1.0 / 30.0  # seconds between the physics frames reported to an observer


@dataclass
class ExecutionResult:
    X_final: np.ndarray
    scene: Scene  # exact final state
    q_final: np.ndarray
    log: list[ExecutedAction] = field(default_factory=list)

    @property
    def sim_time(self) -> float:
        return sum(a.sim_time for a in self.log)

    @property
    def wall_time(self) -> float:
        return sum(a.wall_time for a in self.log)


class Executor:
    """The Drake diagram of one block layout (block types), reused for every plan executed on it."""

    def __init__(self, types: np.ndarray, config: WorldConfig | None = None) -> None:
        self.config = config or WorldConfig()
        self.types = np.array(types)
        builder = DiagramBuilder()
        plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=self.config.time_step)
        plant.set_discrete_contact_approximation(DiscreteContactApproximation.kLagged)
        plant.set_contact_model(ContactModel.kHydroelasticWithFallback)
        parser = Parser(plant)
        arm, gripper = add_arm_gripper_table(plant, parser)
        self.blocks = add_blocks(parser, self.types)
        plant.set_gravity_enabled(arm, False)
        plant.set_gravity_enabled(gripper, False)
        # (GetJointActuatorIndices(arm) is empty before Finalize; the arm's actuators come first.)
        for k in range(6):
            actuator = plant.get_mutable_joint_actuator(JointActuatorIndex(k))
            assert actuator.model_instance() == arm
            actuator.set_controller_gains(PdControllerGains(p=KP[k], d=KD[k]))
        gripper_body = plant.GetBodyByName("gripper_base", gripper)
        self._block_bodies = [plant.get_body(plant.GetBodyIndices(b)[0]) for b in self.blocks]
        # The grasped block's pose in the gripper: a frame set per action (see the module docstring).
        self._grasp_frame = plant.AddFrame(FixedOffsetFrame("grasp", gripper_body.body_frame(), RigidTransform()))
        grasp_body = plant.AddRigidBody("grasp", gripper, SpatialInertia.Zero())
        plant.WeldFrames(self._grasp_frame, grasp_body.body_frame())
        self._welds = [plant.AddWeldConstraint(grasp_body, RigidTransform(), body, RigidTransform())
                       for body in self._block_bodies]
        plant.Finalize()
        # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches: ignored below)
        source = TrajectorySource(PiecewisePolynomial(np.zeros((6, 1))),  # type: ignore[arg-type]
                                  output_derivative_order=1, zero_derivatives_beyond_limits=True)
        builder.AddSystem(source)
        self._source = source
        builder.Connect(self._source.get_output_port(), plant.get_desired_state_input_port(arm))
        # Feed-forward joint torques (N m): the payload's, updated at every control tick.
        self._feedforward = ConstantVectorSource(np.zeros(6))  # type: ignore[arg-type]  # pydrake stubs
        builder.AddSystem(self._feedforward)
        builder.Connect(self._feedforward.get_output_port(), plant.get_actuation_input_port(arm))
        self.plant, self.arm, self.gripper_body = plant, arm, gripper_body
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self._feedforward_value = self._feedforward.get_mutable_source_value(
            self._feedforward.GetMyMutableContextFromRoot(self.context))
        arm_joints = [plant.get_joint(j) for j in plant.GetJointIndices(arm) if plant.get_joint(j).num_positions() == 1]
        self._arm_idx = np.array([joint.position_start() for joint in arm_joints])
        self._arm_v_idx = np.array([joint.velocity_start() for joint in arm_joints])
        self._payload: list[int] = []  # blocks whose weight the arm carries

    def _scene(self) -> Scene:
        poses = [self.plant.EvalBodyPoseInWorld(self.plant_context, b) for b in self._block_bodies]
        return Scene(self.types, poses)

    def _q_arm(self) -> np.ndarray:
        return self.plant.GetPositions(self.plant_context)[self._arm_idx]

    def run(self, refined: RefinedPlan, observer: WorldObserver | None = None) -> ExecutionResult:
        """Execute the refined plan's actions from its initial scene, reporting to `observer`."""
        if list(refined.scene_init.types) != list(self.types):
            raise ValueError(f"this executor's blocks are of types {self.types.tolist()}, the plan's "
                             f"{np.asarray(refined.scene_init.types).tolist()}")
        observer = observer if observer is not None else WorldObserver()
        plant, ctx = self.plant, self.plant_context
        self.diagram.SetDefaultContext(self.context)  # as built: no state or grasp left by an earlier plan
        for weld in self._welds:
            plant.SetConstraintActiveStatus(ctx, weld, False)
        self._payload = []
        scene0 = refined.scene_init
        for body, X_WB in zip(self._block_bodies, scene0.X_WB):
            plant.SetFreeBodyPose(ctx, body, X_WB)
        q = plant.GetPositions(ctx)
        q[self._arm_idx] = refined.q_init
        plant.SetPositions(ctx, q)
        plant.SetVelocities(ctx, np.zeros(plant.num_velocities()))
        observer.scene_started(scene0, refined.q_init)
        log = [self._run_action(k, step, observer) for k, step in enumerate(refined.steps)]
        scene = self._scene()
        return ExecutionResult(scene.X(), scene, self._q_arm(), log)

    def _run_action(self, k: int, step: RefinedAction, observer: WorldObserver) -> ExecutedAction:
        plant, ctx = self.plant, self.plant_context
        t_wall = time.perf_counter()
        X_before = self._scene().X()
        self._source.UpdateTrajectory(step.trajectory)
        self.context.SetTime(0.0)
        self.simulator.Initialize()
        observer.action_started()
        frames: list[PhysicsFrame] = []
        max_error = 0.0
        grasped, note = False, ""
        events = [(step.t_grasp, "grasp"), (step.t_release, "release"), (step.duration, "end")]
        t = 0.0
        for t_event, event in events:
            while t < t_event - 1e-9:
                t = min(t + FRAME_PERIOD, t_event)
                self._compensate_payload()
                self.simulator.AdvanceTo(t)
                max_error = max(max_error, float(np.max(np.abs(self._q_arm() - step.trajectory.value(t).ravel()))))
                frames.append(self._frame(t))
            if event == "grasp":
                grasped, note = self._close(step)
                self._payload = list(step.carried) if grasped else []
            elif event == "release":
                plant.SetConstraintActiveStatus(ctx, self._welds[step.grasped], False)
                self._payload = []
        self._compensate_payload()
        # Hold still until the blocks are at rest.
        cfg = self.config
        still_since, t_end = t, t
        settled = False
        while t < t_end + cfg.settle_max_time:
            t += 0.01
            self.simulator.AdvanceTo(t)
            if t - (frames[-1].t if frames else 0.0) >= FRAME_PERIOD - 1e-9:
                frames.append(self._frame(t))
            if self._at_rest():
                if t - still_since >= cfg.settle_window - 1e-9:
                    settled = True
                    break
            else:
                still_since = t
        observer.physics_frames(frames)
        scene = self._scene()
        return ExecutedAction(k, X_before, scene.X(), step.X_after, grasped, max_error, t - t_end, settled,
                              t, time.perf_counter() - t_wall, note)

    def _close(self, step: RefinedAction) -> tuple[bool, str]:
        """Weld the planned block at the planned grasp if it is between the jaws."""
        X_WG = self.plant.EvalBodyPoseInWorld(self.plant_context, self.gripper_body) @ X_FlangeTcp
        X_WB_expected = X_WG @ step.X_GC[0]
        X_WB = self.plant.EvalBodyPoseInWorld(self.plant_context, self._block_bodies[step.grasped])
        miss = float(np.linalg.norm(X_WB.translation() - X_WB_expected.translation()))
        if miss > GRASP_TOLERANCE:
            return False, f"grasp missed: object {step.grasped} was {miss * 100:.1f} cm from the planned grasp"
        self._grasp_frame.SetPoseInParentFrame(self.plant_context, X_FlangeTcp @ step.X_GC[0])
        self.plant.SetConstraintActiveStatus(self.plant_context, self._welds[step.grasped], True)
        return True, ""

    def _compensate_payload(self) -> None:
        """Set the feed-forward torques that hold the payload's weight at the current configuration:
        tau = sum over carried blocks of J_v(gripper at the block's centre of mass)^T m g z_W."""
        if not self._payload:
            self._feedforward_value.SetFromVector(np.zeros(6))  # type: ignore[arg-type]  # pydrake stubs
            return
        plant, ctx = self.plant, self.plant_context
        tau = np.zeros(6)
        X_GW = plant.EvalBodyPoseInWorld(ctx, self.gripper_body).inverse()
        for b in self._payload:
            body = self._block_bodies[b]
            p_WBcm = plant.EvalBodyPoseInWorld(ctx, body) @ body.CalcCenterOfMassInBodyFrame(ctx)
            J = plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, self.gripper_body.body_frame(),
                                                        X_GW @ p_WBcm, plant.world_frame(),
                                                        plant.world_frame())
            weight = body.get_mass(ctx) * -plant.gravity_field().gravity_vector()
            tau += J[:, self._arm_v_idx].T @ weight
        self._feedforward_value.SetFromVector(tau)  # type: ignore[arg-type]  # pydrake stubs

    def _at_rest(self) -> bool:
        return blocks_at_rest(self.plant, self.plant_context, self._block_bodies, self.config.settle_speed,
                              self.config.settle_angular_speed)

    def _frame(self, t: float) -> PhysicsFrame:
        return PhysicsFrame(t, self._q_arm(), self._scene().X_WB)


def execute(refined: RefinedPlan, config: WorldConfig | None = None, observer: WorldObserver | None = None,
            partial: bool = False) -> ExecutionResult:
    """Execute a refined plan with the arm under physics, reporting to `observer`; returns the final
    state and a per-action log. A plan whose refinement failed is not executed (ValueError) unless
    `partial`, in which case only the actions before the failure run."""
    if refined.failure is not None and not partial:
        raise ValueError(f"the plan could not be refined, so nothing was executed: {refined.failure}")
    if not refined.steps:
        scene = refined.scene_init
        return ExecutionResult(scene.X(), scene, np.array(refined.q_init), [])
    return Executor(refined.scene_init.types, config).run(refined, observer)
