"""Learned effect models (Symbolic and Dynamics Model) for the pick-place TAMP system.

No Drake, no imports from tamp/, symbolic/ or evaluation/: actions cross the border as
4-tuples or (B, 4) int arrays, states as (n, 5) float arrays (see ``learned.effects``).
"""
from .ablation import ablate_activations, format_ablation_markdown, summarize_ablation_dir, write_ablation_report
from .checkpoint import load_model, save_checkpoint
from .dataset import DatasetWriter, ShardError, TransitionDataset, Transitions, load_transitions, read_meta
from .effects import arm_displacement, effect_targets, encode_actions, moved_picks
from .model import ACTIVATIONS, RELATIONS, EffectModel, ModelConfig
from .train import evaluate, train_model
from .train_config import TrainConfig, TrainResult

__all__ = [
    "ACTIVATIONS", "DatasetWriter", "EffectModel", "ModelConfig", "RELATIONS", "ShardError", "TrainConfig",
    "TrainResult",
    "TransitionDataset", "Transitions", "ablate_activations", "arm_displacement", "effect_targets",
    "encode_actions", "evaluate", "format_ablation_markdown", "load_model", "load_transitions", "moved_picks",
    "read_meta", "save_checkpoint", "summarize_ablation_dir", "train_model", "write_ablation_report",
]
