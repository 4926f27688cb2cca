"""`tamp perceive`: the camera rig's view of one problem's initial scene, each block's estimate against the truth."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tamp.app.args import seed
from tamp.app.settings import add_config_arguments, settings_of, source_of
from tamp.planning.vocabulary import TYPE_NAMES
from tamp.sim.perception_config import RIG_SLOTS

CLASS_WORDS = {"table": "on the table", "stack": "in a stack", "leaning": "leaning"}


def _cameras(text: str) -> tuple[str, ...]:
    """argparse type: comma-separated camera slots of the rig."""
    slots = tuple(s.strip() for s in text.split(","))
    unknown = [s for s in slots if s not in RIG_SLOTS]
    if unknown or not slots:
        raise argparse.ArgumentTypeError(f"expected cameras among {','.join(RIG_SLOTS)}, got {text!r}")
    return slots


def cmd_perceive(args: argparse.Namespace) -> int:
    """Set the world to the problem's initial scene (settled by physics), render the rig, perceive, compare."""
    from tamp.app.problem import pick_problem

    problem = pick_problem(args.problem, args.name)  # the file is checked before Drake loads
    config = settings_of(args).perception
    if args.cameras is not None:
        config = config.with_cameras(*args.cameras)
    if args.no_noise:
        config = config.without_noise()
    from tamp.sim.cameras import CameraRig
    from tamp.sim.perception_check import observe
    from tamp.sim.world import World

    world = World()
    world.reset(X=problem.X_init, seed=problem.seed)
    scene = world.scene
    assert scene is not None  # just reset
    rig = CameraRig(config)
    rig.render(scene)  # the renderer's first frame (about 0.5 s) is not the observation's time
    noise_seed = problem.seed if args.seed is None else args.seed
    seen = observe(rig, scene, np.random.default_rng(noise_seed), previous=problem.X_init)
    cameras = config.cameras()
    first = cameras[0][1]
    noise = f"noise on (seed {noise_seed})" if config.noise.on else "noise off"
    print(f"problem {problem.name or args.problem}: {problem.n} blocks; {len(cameras)} cameras "
          f"({', '.join(name for name, _ in cameras)}) at {first.width}x{first.height}, {noise}; "
          f"configuration: {source_of(args)}")
    for check, x in zip(seen.checks, scene.X()):
        truth = f"block {check.block} {TYPE_NAMES[check.type_true]:5s} {CLASS_WORDS[check.kind]:12s} at " \
                f"({x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}) m"
        if not check.found:
            print(f"  {truth}: NOT SEEN")
            continue
        assert check.position_error_m is not None and check.orientation_error_rad is not None  # found
        right = "right" if check.type_right else f"WRONG (seen as {TYPE_NAMES[int(check.type_seen or 0)]})"
        print(f"  {truth}: position {1000 * check.position_error_m:.1f} mm off, orientation "
              f"{np.degrees(check.orientation_error_rad):.1f} deg off, type {right}")
    for failure in seen.seen.failures:
        print(f"  said: {failure.kind.value}: {failure.reason}")
    found = sum(c.found for c in seen.checks)
    print(f"{found} of {problem.n} blocks found, {len(seen.seen.blocks)} estimates, {seen.seen.points} fused points; "
          f"render {1000 * seen.render_s:.0f} ms, perception {1000 * seen.perceive_s:.0f} ms "
          f"(sensor noise model {1000 * seen.noise_s:.0f} ms)")
    every = seen.count_right and all(c.type_right for c in seen.checks) and seen.seen.ok
    return 0 if every else 1


def add_perceive(sub) -> None:
    """`tamp perceive`."""
    p = sub.add_parser(
        "perceive",
        help="render a problem's initial scene with the camera rig and perceive its blocks from the depth images",
        description="Set the world to the problem's initial scene (settled by physics), render the rig's depth "
        "cameras (the configuration's [perception] section: four 640x480 cameras above, in front and to the sides "
        "of the table, a stereo sensor's noise), find the blocks from the depth images alone and print each one's "
        "estimate against the truth: position error, orientation error (the yaw for a block resting flat), type "
        "right or wrong, and every failure perception said (a block missing, an extra one, points no block "
        "explains). Exit 0 when every block was found with its type and nothing was said, 1 otherwise.",
    )
    p.add_argument("--problem", type=Path, required=True,
                   help="problem file (JSON: X_init, X_goal), or a problem set (JSON Lines; pick one with --name)")
    p.add_argument("--name", default=None, help="the problem of a problem set (e.g. n4-k3-002)")
    p.add_argument("--cameras", type=_cameras, default=None, metavar="SLOTS",
                   help=f"only these cameras of the rig, e.g. above,front (of {','.join(RIG_SLOTS)}; default: those "
                   "the configuration turns on)")
    p.add_argument("--no-noise", action="store_true", help="the rendered depth as it is, without the sensor's noise")
    p.add_argument("--seed", type=seed, default=None, help="seed of the sensor noise (default: the problem's seed)")
    add_config_arguments(p)
    p.set_defaults(func=cmd_perceive)


__all__ = ["add_perceive", "cmd_perceive"]
