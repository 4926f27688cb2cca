"""TAMP for a UR10e, in three layers that import one way, app -> sim -> planning:

- `tamp.planning`: the bilevel planner, the continuous search, verification and the models'
  planning interface; numpy and torch, no Drake.
- `tamp.sim`: the Drake block world, the pick-place skill, kinematics, OMPL motions, refinement,
  time-parameterized trajectories and execution under physics.
- `tamp.app`: the `tamp` command line, the demo, data collection, problem files and the runners
  that plan, refine and execute.

Importing `tamp` alone loads none of them.
"""
