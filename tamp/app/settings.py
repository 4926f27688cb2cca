"""The configuration as data: one TOML file for the planner and the evaluation, and the shipped presets.

    settings = load_settings(preset="paper", config=Path("mine.toml"))   # the preset, then the file over it
    print(render_settings(settings))                                    # `tamp config show`

The file's tables are the planner's parts (`[level1]`, `[verify]`, `[search]`, `[kinematics]`, `[loop]`,
`tamp.planning.config`), `[evaluation]` and `[perception]` (the camera rig, `tamp.sim.perception_config`); a
key absent keeps its default, `false` switches an option off. Every command that plans takes `--config FILE`
and `--preset NAME` (`add_config_arguments`), and every output it writes records the resolved configuration
(`settings_record`).
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from guarded.config import build, read_toml, render
from tamp.planning.config import PLAN_SECTIONS, PlanConfig, overlay, preset_path, presets
from tamp.sim.perception_config import PerceptionConfig

FORMAT = "tamp-config/1"  # the version of the recorded configuration
OTHER_SECTIONS = ("evaluation", "perception")  # the file's tables beside the planner's


@dataclass(frozen=True)
class EvaluationSettings:
    """`tamp evaluate`'s own settings (how plans are judged, beside the planner's)."""

    oracle_max_plans: int = 20  # probabilistic_oracle: ranked plans executed at most, per problem

    def __post_init__(self) -> None:
        if isinstance(self.oracle_max_plans, bool) or self.oracle_max_plans < 1:
            raise ValueError(f"evaluation.oracle_max_plans must be a positive integer, got {self.oracle_max_plans}")


@dataclass(frozen=True)
class Settings:
    """The resolved configuration of a command: the planner's, the evaluation's and the camera rig's."""

    planner: PlanConfig = PlanConfig()
    evaluation: EvaluationSettings = EvaluationSettings()
    perception: PerceptionConfig = PerceptionConfig()


def load_settings(preset: str | None = None, config: Path | None = None) -> Settings:
    """The defaults, then the shipped `preset` over them, then the file `config` over that (each optional)."""
    settings = Settings()
    for path in ([preset_path(preset)] if preset is not None else []) + ([config] if config is not None else []):
        table = read_toml(path, "configuration file")
        planner = overlay(settings.planner, table, str(path), also=OTHER_SECTIONS)
        evaluation = build(EvaluationSettings, table.get("evaluation", {}), str(path), settings.evaluation,
                           "evaluation.")
        perception = build(PerceptionConfig, table.get("perception", {}), str(path), settings.perception,
                           "perception.")
        settings = Settings(planner, evaluation, perception)
    return settings


def render_settings(settings: Settings, source: str = "the defaults") -> str:
    """`settings` as the TOML file that gives it back, each field with its one-line comment."""
    tables = [render(getattr(settings.planner, part), part) for part in PLAN_SECTIONS]
    tables += [render(settings.evaluation, "evaluation"), render(settings.perception, "perception")]
    return f"# tamp configuration ({source}); an option that is off is false\n\n" + "\n\n".join(tables) + "\n"


def settings_record(settings: Settings) -> dict[str, Any]:
    """The resolved configuration as JSON-ready data, for every output that records what made it."""
    return {"format": FORMAT, **{part: dataclasses.asdict(getattr(settings.planner, part)) for part in PLAN_SECTIONS},
            "evaluation": dataclasses.asdict(settings.evaluation),
            "perception": dataclasses.asdict(settings.perception)}


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    """--config and --preset: where every setting without a flag of its own comes from."""
    p.add_argument("--preset", default=None, metavar="NAME",
                   help=f"a shipped configuration: {', '.join(presets())} (default: the defaults; "
                   "`tamp config show --preset NAME` prints it)")
    p.add_argument("--config", type=Path, default=None, metavar="FILE",
                   help="a TOML configuration file over the preset: the planner's and the evaluation's settings "
                   "(`tamp config show > FILE` writes one to edit)")


def settings_of(args: argparse.Namespace) -> Settings:
    """The Settings of `add_config_arguments`' flags, with --max-actions over them where the command has it."""
    settings = load_settings(args.preset, args.config)
    if getattr(args, "max_actions", None) is not None:
        loop = dataclasses.replace(settings.planner.loop, max_actions=args.max_actions)
        settings = dataclasses.replace(settings, planner=dataclasses.replace(settings.planner, loop=loop))
    return settings


def source_of(args: argparse.Namespace) -> str:
    """Where `settings_of(args)` came from, in words."""
    parts = ([f"preset {args.preset}"] if args.preset else []) + ([str(args.config)] if args.config else [])
    return " over ".join(reversed(parts)) or "the defaults"


def cmd_config_show(args: argparse.Namespace) -> int:
    """`tamp config show`: the resolved configuration as TOML."""
    print(render_settings(settings_of(args), source_of(args)), end="")
    return 0


def add_config(sub) -> None:
    """`tamp config`."""
    p = sub.add_parser("config", help="show the resolved configuration (the defaults, a preset, a file) as TOML",
                       description="The planner's and the evaluation's settings are one TOML file. `tamp config "
                       "show` prints the resolved configuration, each field with what it does; redirect it to a "
                       "file, edit it and give it to `tamp plan`, `tamp demo` or `tamp evaluate` with --config.")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    show = verbs.add_parser("show", help="print the resolved configuration as TOML",
                            description="Print the resolved configuration: the defaults, --preset over them, "
                            "--config over that.")
    add_config_arguments(show)
    show.set_defaults(func=cmd_config_show)


__all__ = ["EvaluationSettings", "Settings", "add_config", "add_config_arguments", "load_settings",
           "render_settings", "settings_of", "settings_record", "source_of"]
