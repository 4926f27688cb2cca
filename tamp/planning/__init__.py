"""The bilevel planner and what it needs, free of Drake: `import tamp.planning` loads no pydrake,
ompl or ur_analytic_ik (the simulator reaches the planner only through
`structs.KinematicFeasibility`)."""
