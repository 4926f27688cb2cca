"""The attentive effect predictor of the paper (Symbolic and Dynamics Model share it).

    u_i      = act(MLP_u(x_i))                        unary symbol, d_z bits
    s_k(i,j) = act(q_k(x_i) . k_k(x_j) / sqrt(d_key))  relation k of K (self-attention heads), or with
               relations="pairwise": act(MLP_r(x_i, x_j, x_j - x_i)_k), which sees the offset directly,
               and s_k(i,i) = 1 (each object always hears itself; the diagonal is no learned bit)
    z_i      = MLP_z([u_i, a_i])                       a_i: per-object action encoding (with type_symbol,
               u_i ends with the block's given type bit, so that no learned bit or relation must carry it;
               with whole_action, the picked block's and the target's a_i carry both offsets and the other's type)
    h_i^k    = sum_j s_k(i,j) z_j                      (padded j excluded)
    e_i      = MLP_e([h_i^1, ..., h_i^K])              effect, metres (see ``effects``)

``act`` is the bottleneck activation: ``gumbel_sigmoid`` (Symbolic Model; logistic noise at
temperature T while training, hard 0/1 in eval mode), ``sigmoid`` (Dynamics Model), ``tanh`` or
``none``. Discrete symbols are ``logit > 0`` for every activation (= rounding the sigmoid).
The 1/sqrt(d_key) scale only conditions the initialisation; it is a constant inside act.
Positions are normalised with training-set statistics kept as buffers (so in checkpoints), and
effects are predicted in units of ``effect_scale``.
"""
from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields

import numpy as np
import torch
from torch import nn

from .effects import STATE_DIM, action_encoding_dim, arm_shift, as_action_array, check_actions, encode_actions

ACTIVATIONS = ("gumbel_sigmoid", "sigmoid", "tanh", "none")
RELATIONS = ("attention", "pairwise")
POSITION_AXES = ("xy", "x")
OFFSET_SCALE_M = 0.05  # `reconstruct_offsets` reads tanh(offset / 5 cm): which side and whether touching, not how far
SPREAD_FLOOR_M = 0.001  # the least spread a ``spread`` head predicts per axis: observations are not finer than 1 mm
SELF_LOGIT = 30.0  # pairwise r_k(i, i): a logit whose Gumbel-Sigmoid sample is 1 but for ~1e-13 of draws


@dataclass
class ModelConfig:
    """Architecture; everything needed to rebuild an EffectModel (JSON-able)."""
    n_max: int = 4               # largest object count the model is trained / used for
    d_z: int = 8                 # unary symbol bits per object
    heads: int = 4               # K relation types (attention heads)
    d_key: int = 16              # query/key width per head
    d_msg: int = 64              # width of z_i
    hidden: int = 128            # MLP hidden width
    layers: int = 2              # hidden layers per MLP
    activation: str = "sigmoid"  # one of ACTIVATIONS
    temperature: float = 1.0     # Gumbel-Sigmoid temperature
    arm_input: bool = True       # arm_xy in the action encoding (False: symbols carry the geometry)
    # relation encoder: "attention" (the paper's q_k(x_i) . k_k(x_j)) or "pairwise" (an MLP of x_i, x_j
    # and x_j - x_i, so a relation can be a threshold on an offset: on, aligned, near; r_k(i, i) = 1)
    relations: str = "attention"
    # the block type (large or not, from the state's one-hot) as a given unary symbol after the d_z learned
    # bits: the decoder reads it directly, so no learned bit has to spend itself on what the input says
    type_symbol: bool = False
    # a head that reads each pair's offset x_j - x_i back from the pair's relation bits (both ways) and
    # both objects' unary bits, trained with `TrainConfig.offset_weight`: the effect loss alone never
    # asks where blocks stand on the table, this asks the bits to say it coarsely (planners never call it)
    offset_decoder: bool = False
    # the offset head reads the pair's relations only, not the unary bits: the relations alone must then
    # say where j stands from i, every axis (height too), which the unary "elevated" bit otherwise says
    offset_from_relations: bool = False
    # a head that reads each block's place on the table, tanh of its normalised (x, y), back from its unary
    # bits, trained with `TrainConfig.position_weight`: a unary bit can then say in which part of the table
    # a block stands, a symbol that only the moved block's step changes (planners never call the head)
    position_decoder: bool = False
    # the table axes the position head reads back: "xy", or "x" alone (the skill's grasp and release offsets
    # are along y, so a block placed at a target lands at the target's x: x-only places are predictable)
    position_axes: str = "xy"
    # a head that predicts the bits after a step from the bits before it and the action (each object's
    # unary bits and each pair's relations, seeing how the pair stands to the picked block and the
    # target), trained with `TrainConfig.transition_weight`: bits an operator can predict (planners never call it)
    transition_decoder: bool = False
    # a head that predicts how widely each object's effect scatters about the mean (a variance per axis), read
    # from the decoder's features (gradient stopped) and the action, trained by the Gaussian likelihood of the mean's
    # residual (`TrainConfig` trains it whenever it is there): the mean stays the paper's Eq. 1 prediction
    spread: bool = False
    # both objects of an action read all of it (the picked block the release offset and the target's type, the
    #   target the grasp offset and the picked block's type), so the picked block knows where it lands (False: the
    #   paper's encoding)
    whole_action: bool = False
    # each message z_ij = MLP(u_j, a_j, x_j - x_i) reads where j stands from i, so that an offset reaches the
    #   decoder exactly, not only through the bits (a Dynamics Model option: it would pass a Symbolic Model's
    #   bottleneck by); h_i^k = sum_j s_k(i,j) z_ij (False: the paper's z_j)
    relative_messages: bool = False

    @property
    def action_dim(self) -> int:
        """Width of the per-object action encoding (`learned.effects.action_encoding_dim`)."""
        return action_encoding_dim(self.whole_action)

    @property
    def n_unary(self) -> int:
        """Unary symbols per object: the d_z learned bits, then the given type bit (type_symbol)."""
        return self.d_z + int(self.type_symbol)

    def __post_init__(self):
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation {self.activation!r} not in {ACTIVATIONS}")
        if self.relations not in RELATIONS:
            raise ValueError(f"relations {self.relations!r} not in {RELATIONS}")
        if self.position_axes not in POSITION_AXES:
            raise ValueError(f"position_axes {self.position_axes!r} not in {POSITION_AXES}")
        for setting in fields(self):  # a checkpoint's config comes from a file: "yes" is no switch, 4.5 no width
            kind = {"bool": (bool, "true or false"), "int": (int, "a whole number")}.get(str(setting.type))
            value = getattr(self, setting.name)
            if kind is not None and type(value) is not kind[0]:
                raise ValueError(f"{setting.name} must be {kind[1]}, got {value!r}")
        if self.relative_messages and self.activation == "gumbel_sigmoid":
            raise ValueError("relative_messages gives the decoder each pair's offset past the symbols: a Dynamics "
                             "Model option, not one for a Symbolic Model (gumbel_sigmoid)")
        if self.offset_from_relations and not self.offset_decoder:
            raise ValueError("offset_from_relations needs offset_decoder=True (the head it changes)")
        for f in ("n_max", "d_z", "heads", "d_key", "d_msg", "hidden", "layers"):
            if int(getattr(self, f)) < 1:
                raise ValueError(f"{f} must be >= 1")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ModelConfig":
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown model config keys {sorted(unknown)}")
        return cls(**d)


def with_whole_action(state: dict[str, torch.Tensor], config: ModelConfig) -> dict[str, torch.Tensor]:
    """A state dict of a network with the paper's action encoding, for the same network with `whole_action`:
    the first layers that read the action encoding (it ends their input) get zero weights for the columns
    `whole_action` adds, so the widened network predicts exactly what the given one did until it trains."""
    if config.transition_decoder:
        raise ValueError("whole_action cannot widen a network with a transition decoder (its action columns "
                         "sit inside its input)")
    extra = config.action_dim - action_encoding_dim(False)
    out = dict(state)
    for name in ("object_mlp.0.weight", "spread_head.0.weight"):
        if name in out:
            w = out[name]
            out[name] = torch.cat([w, w.new_zeros(w.shape[0], extra)], dim=1)
    return out


def mlp(sizes: Sequence[int]) -> nn.Sequential:
    """Linear layers with ReLU between them (none after the last)."""
    mods: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        mods.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            mods.append(nn.ReLU())
    return nn.Sequential(*mods)


class Bottleneck(nn.Module):
    """The bottleneck activation applied to unary and relational logits."""

    def __init__(self, activation: str, temperature: float = 1.0):
        super().__init__()
        self.activation, self.temperature = activation, temperature

    def forward(self, logits: torch.Tensor) -> torch.Tensor:
        if self.activation == "gumbel_sigmoid":
            if not self.training:
                return (logits > 0).to(logits.dtype)
            logits = logits.float()  # the noise in float32 also under bfloat16 autocast
            u = torch.rand_like(logits).clamp_(1e-6, 1 - 1e-6)
            return torch.sigmoid((logits + torch.log(u) - torch.log1p(-u)) / self.temperature)
        if self.activation == "sigmoid":
            return torch.sigmoid(logits)
        if self.activation == "tanh":
            return torch.tanh(logits)
        return logits


class EffectModel(nn.Module):
    """Predicts per-object effects of a pick-place from (X, action); see module docstring."""

    # buffers (register_buffer in __init__)
    pos_mean: torch.Tensor
    pos_std: torch.Tensor
    effect_scale: torch.Tensor
    arm_scale: torch.Tensor

    def __init__(self, config: ModelConfig):
        super().__init__()
        c = self.config = config
        hid = [c.hidden] * c.layers
        self.unary = mlp([STATE_DIM, *hid, c.d_z])
        if c.relations == "attention":
            self.pre_attention = nn.Sequential(mlp([STATE_DIM, *hid]), nn.ReLU())
            self.query = nn.Linear(c.hidden, c.heads * c.d_key)
            self.key = nn.Linear(c.hidden, c.heads * c.d_key)
        else:  # pairwise: [x_i, x_j, (x_j - x_i)[:3]] per ordered pair, K logits out
            self.pair = mlp([2 * STATE_DIM + 3, *hid, c.heads])
        self.object_mlp = mlp([c.n_unary + c.action_dim + 3 * c.relative_messages, *hid, c.d_msg])
        self.decoder = mlp([c.heads * c.d_msg, *hid, 3])
        if c.spread:
            self.spread_head = mlp([c.heads * c.d_msg + c.action_dim, *hid, 3])
        if c.offset_decoder:
            self.offset_head = mlp([(0 if c.offset_from_relations else 2 * c.n_unary) + 2 * c.heads, *hid, 3])
        if c.position_decoder:
            self.position_head = mlp([c.n_unary, *hid, len(c.position_axes)])
        if c.transition_decoder:  # per object: [u_i, a_i, context_i]; per pair: both of those and r_.(i, j), r_.(j, i)
            context = 4 * c.heads + 2 * c.n_unary  # the object's relations both ways to the pick and the target; theirs
            self.next_unary_head = mlp([c.n_unary + c.action_dim + context, *hid, c.d_z])
            self.next_relation_head = mlp([2 * (c.n_unary + c.action_dim + context) + 2 * c.heads, *hid, c.heads])
        self.bottleneck = Bottleneck(c.activation, c.temperature)
        # Normalisation statistics (metres), set from training data by ``set_normalisation``.
        self.register_buffer("pos_mean", torch.zeros(3))
        self.register_buffer("pos_std", torch.ones(3))
        self.register_buffer("effect_scale", torch.ones(()))
        self.register_buffer("arm_scale", torch.ones(()))

    def set_normalisation(self, pos_mean, pos_std, effect_scale: float, arm_scale: float) -> None:
        self.pos_mean.copy_(torch.as_tensor(pos_mean, dtype=torch.float32))
        self.pos_std.copy_(torch.as_tensor(pos_std, dtype=torch.float32))
        self.effect_scale.fill_(float(effect_scale))
        self.arm_scale.fill_(float(arm_scale))

    # -- encoders -----------------------------------------------------------------------
    def encode_actions(self, X: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(B, N, config.action_dim) each object's action encoding (`learned.effects.encode_actions`)."""
        return encode_actions(X, action, self.arm_scale, arm=self.config.arm_input, whole=self.config.whole_action)

    def _normalise(self, X: torch.Tensor) -> torch.Tensor:
        return torch.cat([(X[..., :3] - self.pos_mean) / self.pos_std, X[..., 3:]], dim=-1)

    def unary_logits(self, X: torch.Tensor) -> torch.Tensor:
        """(B, N, d_z) pre-activation unary symbols (the learned ones)."""
        return self.unary(self._normalise(X))

    def _with_type(self, u: torch.Tensor, X: torch.Tensor) -> torch.Tensor:
        """The unary symbols (B, N, d_z) followed by the given type bit (1: large) with type_symbol."""
        return torch.cat([u, X[..., 4:5].to(u.dtype)], dim=-1) if self.config.type_symbol else u

    def relation_logits(self, X: torch.Tensor) -> torch.Tensor:
        """(B, K, N, N) pre-activation relations: q_k(x_i) . k_k(x_j), or MLP_r(x_i, x_j, x_j - x_i)."""
        B, N, _ = X.shape
        c = self.config
        if c.relations == "pairwise":
            x = self._normalise(X)
            offset = self.pair_offsets(X) / self.pos_std  # [b, i, j] = x_j - x_i
            pair = torch.cat([x[:, :, None].expand(B, N, N, STATE_DIM), x[:, None].expand(B, N, N, STATE_DIM),
                              offset], dim=-1)
            logits = self.pair(pair).permute(0, 3, 1, 2)
            # r_k(i, i) = 1: every head hears the object itself; the diagonal carries no learned bit
            eye = torch.eye(N, dtype=torch.bool, device=X.device)
            return logits.masked_fill(eye, SELF_LOGIT)
        f = self.pre_attention(self._normalise(X))
        q = self.query(f).view(B, N, c.heads, c.d_key).transpose(1, 2)
        k = self.key(f).view(B, N, c.heads, c.d_key).transpose(1, 2)
        return q @ k.transpose(-1, -2) / math.sqrt(c.d_key)

    # -- forward ------------------------------------------------------------------------
    def encode(self, X: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Bottleneck outputs: unary (B, N, n_unary) and relations (B, K, N, N), padded j zeroed."""
        return self.encode_logits(X, mask)[:2]

    def encode_logits(self, X: torch.Tensor, mask: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """`encode`'s outputs and the logits they come from: unary (B, N, d_z), relations (B, K, N, N)."""
        unary, relation = self.unary_logits(X), self.relation_logits(X)
        u = self._with_type(self.bottleneck(unary), X)
        r = self.bottleneck(relation) * mask.to(X.dtype)[:, None, None, :]
        return u, r, unary, relation

    def decode(self, X: torch.Tensor, action: torch.Tensor, mask: torch.Tensor, u: torch.Tensor,
               r: torch.Tensor) -> torch.Tensor:
        """Effects (B, N, 3) in metres from the symbols and the action (see ``forward``)."""
        return self._effect(self.messages(X, action, mask, u, r), X, mask)

    def decode_spread(self, X: torch.Tensor, action: torch.Tensor, mask: torch.Tensor, u: torch.Tensor,
                      r: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Effects (B, N, 3) in metres, as `decode`, and the log-variance of each about it, per axis, in
        units of ``effect_scale`` squared (the ``spread`` head: it reads the features with their gradient
        stopped, so training it leaves the mean alone, and each object's action encoding)."""
        h = self.messages(X, action, mask, u, r)
        return self._effect(h, X, mask), self.spread_head(self.spread_input(h, X, action))

    def spread_input(self, h: torch.Tensor, X: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """What the spread head reads: the decoder's features (gradient stopped) and the object's action encoding."""
        return torch.cat([h.detach(), self.encode_actions(X, action).to(h.dtype)], dim=-1)

    def messages(self, X: torch.Tensor, action: torch.Tensor, mask: torch.Tensor, u: torch.Tensor,
                 r: torch.Tensor) -> torch.Tensor:
        """The decoder's input (B, N, K d_msg): h_i^k = sum_j s_k(i,j) z_j for every head k (z_ij with
        `relative_messages`)."""
        B, N, _ = X.shape
        a = self.encode_actions(X, action)
        f = torch.cat([u.expand(B, -1, -1), a], dim=-1)
        if self.config.relative_messages:  # z[b, i, j] = MLP(f_j, (x_j - x_i) / std)
            offsets = (self.pair_offsets(X) / self.pos_std).to(f.dtype)
            z_pairs = self.object_mlp(torch.cat([f[:, None].expand(B, N, N, f.shape[-1]), offsets], dim=-1))
            return torch.einsum("bkij,bijd->bikd", r, z_pairs).reshape(B, N, -1)
        z = self.object_mlp(f)
        # h_i^k = sum_j s_k(i,j) z_j as one (K*N x N) @ (N x d_msg) product per scene: this op trains
        # 2-4x faster than broadcasting r (B, K, N, N) against z (B, 1, N, d_msg); same sums, but
        # float32 gradients differ from that form's in the last bits
        K = r.shape[1]
        return (r.reshape(r.shape[0], K * N, N) @ z).view(B, K, N, -1).transpose(1, 2).reshape(B, N, -1)

    def _effect(self, h: torch.Tensor, X: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return self.decoder(h) * self.effect_scale * mask.to(X.dtype)[..., None]

    @staticmethod
    def pair_offsets(X: torch.Tensor) -> torch.Tensor:
        """(B, N, N, 3) offsets x_j - x_i of every ordered pair [b, i, j], metres."""
        return X[:, None, :, :3] - X[:, :, None, :3]

    def squashed_offsets(self, X: torch.Tensor) -> torch.Tensor:
        """(B, N, N, 3) tanh((x_j - x_i) / OFFSET_SCALE_M): -1 or 1 a block's width or more to either side,
        between when the blocks touch or overlap; what `reconstruct_offsets` learns to read back."""
        return torch.tanh(self.pair_offsets(X) / OFFSET_SCALE_M)

    def squashed_positions(self, X: torch.Tensor) -> torch.Tensor:
        """(B, N, axes) tanh of each block's normalised place on the table, (x, y) or x (``position_axes``):
        what `reconstruct_positions` learns to read back."""
        axes = len(self.config.position_axes)
        return torch.tanh((X[..., :axes] - self.pos_mean[:axes]) / self.pos_std[:axes])

    def reconstruct_positions(self, u: torch.Tensor) -> torch.Tensor:
        """(B, N, axes) `squashed_positions` read back from each block's unary bits alone (``position_decoder``)."""
        return self.position_head(u)

    def reconstruct_offsets(self, u: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        """(B, N, N, 3) `squashed_offsets` read back from the bits alone (``offset_decoder``): from
        [u_i, u_j, r_.(i, j), r_.(j, i)], or [r_.(i, j), r_.(j, i)] with ``offset_from_relations``."""
        B, N, d = u.shape
        rij = r.permute(0, 2, 3, 1)  # (B, N, N, K)
        unary = [] if self.config.offset_from_relations else [u[:, :, None].expand(B, N, N, d),
                                                               u[:, None].expand(B, N, N, d)]
        pair = torch.cat([*unary, rij, rij.transpose(1, 2)], dim=-1)
        return self.offset_head(pair)

    def predict_next_logits(self, X: torch.Tensor, action: torch.Tensor, u: torch.Tensor, r: torch.Tensor
                            ) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits of the learned bits after the action, (B, N, d_z) and (B, K, N, N), from the bits before
        it (u: (B, N, n_unary), r: (B, K, N, N)) and the action alone (``transition_decoder``): each object
        is seen with its action encoding, its relations both ways to the picked block and to the target,
        and their unary bits; each pair with both objects' and its own two relations."""
        B, N, _ = X.shape
        a = self.encode_actions(X, action)
        batch = torch.arange(B, device=X.device)
        rij = r.permute(0, 2, 3, 1)  # (B, N, N, K)
        pick, target = action[:, 0], action[:, 2]
        context = torch.cat([rij[batch, :, pick], rij[batch, pick], rij[batch, :, target], rij[batch, target],
                             u[batch, pick][:, None].expand(B, N, -1), u[batch, target][:, None].expand(B, N, -1)],
                            dim=-1)
        obj = torch.cat([u.expand(B, -1, -1), a.to(u.dtype), context.to(u.dtype)], dim=-1)
        F = obj.shape[-1]
        pair = torch.cat([obj[:, :, None].expand(B, N, N, F), obj[:, None].expand(B, N, N, F), rij,
                          rij.transpose(1, 2)], dim=-1)
        return self.next_unary_head(obj), self.next_relation_head(pair).permute(0, 3, 1, 2)

    def forward(self, X: torch.Tensor, action: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Effect target (B, N, 3) in metres, arm motion of the pick object removed; 0 if padded.

        X: (B, N, 5) metres / one-hot, zero-padded; action: (B, 4) long; mask: (B, N) bool.
        """
        u, r = self.encode(X, mask)
        return self.decode(X, action, mask, u, r)

    # -- planner API --------------------------------------------------------------------
    @contextmanager
    def _eval_mode(self) -> Iterator[None]:
        """Eval mode for a planner call, restoring training mode after. Switching modes walks every
        submodule, so it is skipped when the model is already in eval mode (loaded models are):
        it was a fifth of the continuous search's time."""
        if not self.training:
            yield
            return
        self.eval()
        try:
            yield
        finally:
            self.train()

    def _scene(self, X: np.ndarray) -> torch.Tensor:
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != STATE_DIM:
            raise ValueError(f"X must have shape (n, {STATE_DIM}), got {X.shape}")
        if X.shape[0] > self.config.n_max:
            raise ValueError(f"scene has {X.shape[0]} objects, model built for n_max="
                             f"{self.config.n_max}")
        return torch.as_tensor(X, dtype=torch.float32)[None]

    @torch.inference_mode()
    def predict_effect(self, X: np.ndarray, actions) -> np.ndarray:
        """Absolute position displacements (B, n, 3) in metres for B actions on one scene.

        ``X[:, :3] + e[b]`` is the predicted next position under ``actions[b]``; actions are a
        (B, 4) int array or a list of 4-tuples. One batched forward pass, eval mode.
        """
        Xt = self._scene(X)
        a = as_action_array(actions)
        n = Xt.shape[1]
        if a.shape[0] == 0:
            return np.zeros((0, n, 3))
        check_actions(a, n)
        with self._eval_mode():
            B = a.shape[0]
            Xb = Xt.expand(B, n, STATE_DIM)
            at = torch.from_numpy(a)
            mask = torch.ones(B, n, dtype=torch.bool)
            u, r = self.encode(Xt, mask[:1])  # the scene's symbols once, shared by all actions
            e = self.decode(Xb, at, mask, u, r).double()
            shift = arm_shift(torch.as_tensor(np.asarray(X, np.float64))[None].expand(B, n, 5), at)
        return (e + shift).numpy()

    @torch.inference_mode()
    def predict_effects(self, Xs: np.ndarray, actions) -> np.ndarray:
        """Displacements (B, n, 3) in metres for B different scenes Xs (B, n, 5), one action each.

        `predict_effect` shares one scene among its actions; this is its counterpart for many plans
        rolled out side by side (Level-1 verification): one forward pass for all B, same numbers.
        """
        return self._predict(Xs, actions, spread=False)[0]

    @torch.inference_mode()
    def predict_gaussian(self, Xs: np.ndarray, actions) -> tuple[np.ndarray, np.ndarray]:
        """`predict_effects` and each displacement's variance per axis (B, n, 3), metres squared: how widely
        the world scatters the outcome about the mean (the ``spread`` head; zeros for a model without one).
        Never below ``SPREAD_FLOOR_M`` squared for a real object."""
        return self._predict(Xs, actions, spread=self.config.spread)

    def _predict(self, Xs: np.ndarray, actions, spread: bool) -> tuple[np.ndarray, np.ndarray]:
        Xs = np.asarray(Xs, dtype=np.float64)
        a = as_action_array(actions)
        if Xs.ndim != 3 or Xs.shape[2] != STATE_DIM or Xs.shape[0] != a.shape[0]:
            raise ValueError(f"Xs must have shape (B, n, {STATE_DIM}) with one action per scene, "
                             f"got {Xs.shape} and {a.shape[0]} actions")
        B, n = Xs.shape[:2]
        if B == 0:
            return np.zeros((0, n, 3)), np.zeros((0, n, 3))
        if n > self.config.n_max:
            raise ValueError(f"scene has {n} objects, model built for n_max={self.config.n_max}")
        check_actions(a, n)
        with self._eval_mode():
            Xt, at = torch.as_tensor(Xs, dtype=torch.float32), torch.from_numpy(a)
            mask = torch.ones(B, n, dtype=torch.bool)
            # one encoding per run of identical scenes (beam searches and rollouts repeat each scene
            # for its actions): the symbols of a scene do not depend on the action
            new = np.ones(B, bool)
            new[1:] = np.any(Xs[1:] != Xs[:-1], axis=(1, 2))
            first = torch.from_numpy(np.flatnonzero(new))
            u, r = self.encode(Xt[first], mask[first])
            if len(first) < B:
                scene = torch.from_numpy(np.cumsum(new) - 1)
                u, r = u[scene], r[scene]
            if spread:
                e, log_var = self.decode_spread(Xt, at, mask, u, r)
                variance = (log_var.double().clamp(-30.0, 10.0).exp() * float(self.effect_scale) ** 2
                            + SPREAD_FLOOR_M ** 2).numpy()
            else:
                e, variance = self.decode(Xt, at, mask, u, r), np.zeros((B, n, 3))
            shift = arm_shift(torch.as_tensor(Xs), at)
        return (e.double() + shift).numpy(), variance

    @torch.inference_mode()
    def symbols(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Discrete symbols of one scene: unary bits (n, n_unary) and relation bits (K, n, n), uint8.

        Deterministic: bit = 1 iff the bottleneck logit > 0 (rounded activation).
        """
        Xt = self._scene(X)
        u, r = self.symbols_batch(Xt.numpy(), np.ones(Xt.shape[:2], dtype=bool))
        return u[0], r[0]

    @torch.inference_mode()
    def symbols_batch(self, X: np.ndarray, mask: np.ndarray, batch_size: int = 4096
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Symbols of many padded scenes: unary (S, N, n_unary) and relations (S, K, N, N), uint8.

        For converting whole datasets; padded objects get all-zero bits (in both roles).
        """
        Xt = torch.as_tensor(np.asarray(X), dtype=torch.float32)
        m = torch.as_tensor(np.asarray(mask), dtype=torch.bool)
        S, N = m.shape
        us = [torch.zeros(0, N, self.config.n_unary, dtype=torch.bool)]
        rs = [torch.zeros(0, self.config.heads, N, N, dtype=torch.bool)]
        for s in range(0, S, batch_size):
            Xb, mb = Xt[s:s + batch_size], m[s:s + batch_size]
            us.append((self._with_type((self.unary_logits(Xb) > 0).float(), Xb) > 0.5) & mb[..., None])
            pair = mb[:, None, :, None] & mb[:, None, None, :]
            rs.append((self.relation_logits(Xb) > 0) & pair)
        return (torch.cat(us).to(torch.uint8).numpy(), torch.cat(rs).to(torch.uint8).numpy())
