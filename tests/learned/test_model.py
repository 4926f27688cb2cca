"""EffectModel: equivariance, padding, the planner API, symbols, checkpoints."""
import numpy as np
import pytest
import torch

from learned import EffectModel, ModelConfig, load_model, save_checkpoint
from learned.effects import arm_shift
from learned.synthetic import random_scene

torch.set_num_threads(1)


def make_model(activation="sigmoid", seed=0, **kw) -> EffectModel:
    torch.manual_seed(seed)
    m = EffectModel(ModelConfig(hidden=32, d_msg=16, d_z=6, heads=3, activation=activation, **kw))
    m.set_normalisation([0.65, 0.0, 0.05], [0.12, 0.2, 0.03], effect_scale=0.05, arm_scale=0.2)
    with torch.no_grad():  # sharper relations than at init, so every head matters
        if m.config.relations == "attention":
            m.query.weight.mul_(4)
            m.key.weight.mul_(4)
        else:
            m.pair[-1].weight.mul_(4)
    return m.eval()


def scene(n, seed=0):
    return random_scene(np.random.default_rng(seed), n, stack_prob=1.0)


def all_actions(n):
    return [(i, d, j, r) for i in range(n) for d in (-1, 0, 1) for j in range(n) for r in (-1, 0, 1)]


@pytest.mark.parametrize("activation,relations", [("sigmoid", "attention"), ("gumbel_sigmoid", "attention"),
                                                  ("tanh", "attention"), ("none", "attention"),
                                                  ("gumbel_sigmoid", "pairwise"), ("sigmoid", "pairwise"),
                                                  ("gumbel_sigmoid", "pairwise+type"),
                                                  ("sigmoid", "attention+relative")])
def test_permuting_objects_permutes_effects_and_symbols(activation, relations):
    typed, relative = relations.endswith("+type"), relations.endswith("+relative")
    m = make_model(activation, seed=1, relations=relations.split("+")[0], type_symbol=typed,
                   relative_messages=relative)
    X = scene(4, seed=2)
    acts = np.array(all_actions(4))
    perm = np.array([2, 0, 3, 1])          # new object k is old object perm[k]
    inv = np.argsort(perm)
    Xp = X[perm]
    acts_p = acts.copy()
    acts_p[:, 0], acts_p[:, 2] = inv[acts[:, 0]], inv[acts[:, 2]]
    e, e_p = m.predict_effect(X, acts), m.predict_effect(Xp, acts_p)
    np.testing.assert_allclose(e_p, e[:, perm], atol=1e-7)
    learned_part = e - arm_shift(torch.tensor(X)[None].expand(len(acts), 4, 5),
                                 torch.tensor(acts)).numpy()
    assert np.ptp(learned_part, axis=(0, 1)).min() > 1e-4  # varies 1000x above the tolerance
    u, r = m.symbols(X)
    u_p, r_p = m.symbols(Xp)
    assert 0 < u.mean() < 1 and 0 < r.mean() < 1, "symbols too uniform for a meaningful test"
    np.testing.assert_array_equal(u_p, u[perm])
    np.testing.assert_array_equal(r_p, r[:, perm][:, :, perm])
    assert u.shape[1] == m.config.n_unary == m.config.d_z + typed
    if typed:  # the last unary symbol is the given type: 1 for a large block
        np.testing.assert_array_equal(u[:, -1], X[:, 4])


@pytest.mark.parametrize("activation,relations,typed", [("sigmoid", "attention", False),
                                                        ("gumbel_sigmoid", "attention", False),
                                                        ("gumbel_sigmoid", "pairwise", True),
                                                        ("sigmoid", "attention+relative", False)])
def test_padding_does_not_change_predictions(activation, relations, typed):
    m = make_model(activation, seed=3, relations=relations.split("+")[0], type_symbol=typed,
                   relative_messages=relations.endswith("+relative"))
    X = torch.tensor(scene(2, seed=4), dtype=torch.float32)[None]
    acts = torch.tensor(all_actions(2))
    B = acts.shape[0]
    X2 = X.expand(B, 2, 5)
    X4 = torch.cat([X2, torch.randn(B, 2, 5)], dim=1)  # garbage in the padded rows
    mask4 = torch.tensor([True, True, False, False]).expand(B, 4)
    with torch.no_grad():
        e2 = m(X2, acts, torch.ones(B, 2, dtype=torch.bool))
        e4 = m(X4, acts, mask4)
    torch.testing.assert_close(e4[:, :2], e2, rtol=0, atol=1e-6)
    assert torch.all(e4[:, 2:] == 0)
    assert e2.abs().max() > 1e-3  # a non-trivial prediction was compared
    u, r = m.symbols_batch(X4[:1].numpy(), mask4[:1].numpy())
    u2, r2 = m.symbols(X[0].numpy())
    np.testing.assert_array_equal(u[0, :2], u2)
    np.testing.assert_array_equal(r[0][:, :2, :2], r2)
    assert not u[0, 2:].any() and not r[0][:, 2:].any() and not r[0][:, :, 2:].any()


def test_relative_messages_read_where_the_other_block_stands():
    """With relative_messages the message from j to i reads x_j - x_i: moving one block changes what a
    block that does not move hears, beyond what its bits change (so offsets reach the decoder)."""
    m = make_model(seed=7, relative_messages=True)
    X = torch.tensor(scene(3, seed=8), dtype=torch.float32)[None]
    a, mask = torch.tensor([[0, 0, 1, 0]]), torch.ones(1, 3, dtype=torch.bool)
    with torch.no_grad():
        u, r = m.encode(X, mask)
        moved = X.clone()
        moved[0, 2, 0] += 0.05  # block 2, 5 cm along x: the bits are held fixed below
        h, h_moved = m.messages(X, a, mask, u, r), m.messages(moved, a, mask, u, r)
        paper = make_model(seed=7)
        same = paper.messages(X, a, mask, u, r), paper.messages(moved, a, mask, u, r)
    assert (h_moved - h).abs().max() > 1e-3
    torch.testing.assert_close(*same)  # the paper's messages read the bits and the action only
    with pytest.raises(ValueError, match="Dynamics Model option"):
        ModelConfig(activation="gumbel_sigmoid", relative_messages=True)


def test_predict_effect_is_absolute_and_batched():
    m = make_model(seed=5)
    X = scene(3, seed=6)
    acts = all_actions(3)
    e = m.predict_effect(X, acts)
    assert e.shape == (81, 3, 3) and e.dtype == np.float64
    np.testing.assert_array_equal(m.predict_effect(X, np.array(acts)), e)
    one = np.stack([m.predict_effect(X, [a])[0] for a in acts])
    np.testing.assert_allclose(one, e, atol=1e-6)
    Xt = torch.tensor(X, dtype=torch.float32)[None].expand(81, 3, 5)
    at = torch.tensor(acts)
    with torch.no_grad():
        target = m(Xt, at, torch.ones(81, 3, dtype=torch.bool)).double()
    shift = arm_shift(torch.tensor(X)[None].expand(81, 3, 5), at)
    np.testing.assert_allclose(e, (target + shift).numpy(), atol=1e-9)
    # The pick object's prediction includes the gripper's lateral motion.
    assert np.abs(shift.numpy()).max() > 0.05
    assert m.predict_effect(X, np.zeros((0, 4), int)).shape == (0, 3, 3)
    with pytest.raises(ValueError, match="out of range"):
        m.predict_effect(X, [(3, 0, 0, 0)])
    with pytest.raises(ValueError, match="offsets"):
        m.predict_effect(X, [(0, 2, 1, 0)])
    with pytest.raises(ValueError, match="n_max"):
        m.predict_effect(scene(5, seed=1), [(0, 0, 1, 0)])


def test_predict_effects_rolls_many_scenes_out_in_one_pass_with_the_same_numbers():
    m = make_model(seed=7)
    scenes = np.stack([scene(3, seed=s) for s in range(6)])
    acts = np.array(all_actions(3))[[0, 5, 17, 40, 62, 80]]
    e = m.predict_effects(scenes, acts)
    assert e.shape == (6, 3, 3) and e.dtype == np.float64
    one = np.stack([m.predict_effect(X, [a])[0] for X, a in zip(scenes, acts)])
    np.testing.assert_allclose(e, one, atol=1e-6)
    assert m.predict_effects(scenes[:0], acts[:0]).shape == (0, 3, 3)
    with pytest.raises(ValueError, match="one action per scene"):
        m.predict_effects(scenes, acts[:2])
    with pytest.raises(ValueError, match="out of range"):
        m.predict_effects(scenes[:1], [(3, 0, 0, 0)])


def test_gumbel_is_stochastic_in_training_and_binary_at_inference():
    m = make_model("gumbel_sigmoid", seed=7)
    X = torch.tensor(scene(3, seed=8), dtype=torch.float32)[None]
    logits = m.unary_logits(X)
    m.train()
    a, b = m.bottleneck(logits), m.bottleneck(logits)
    assert not torch.equal(a, b) and ((a > 0) & (a < 1)).any()
    m.eval()
    hard = m.bottleneck(logits)
    assert torch.equal(hard, (logits > 0).float())
    np.testing.assert_array_equal(m.symbols(X[0].numpy())[0], hard[0].to(torch.uint8).numpy())
    acts = all_actions(3)
    np.testing.assert_array_equal(m.predict_effect(X[0].numpy(), acts),
                                  m.predict_effect(X[0].numpy(), acts))
    # A model still training predicts deterministically too, and stays in training mode.
    expected = m.predict_effect(X[0].numpy(), acts)
    m.train()
    np.testing.assert_array_equal(m.predict_effect(X[0].numpy(), acts), expected)
    np.testing.assert_allclose(m.predict_effects(np.repeat(X.numpy(), 2, 0), acts[:2]), expected[:2], atol=1e-6)
    assert m.training and m.bottleneck.training


@pytest.mark.parametrize("relations", ["attention", "pairwise"])
def test_checkpoint_round_trips_exactly(tmp_path, relations):
    m = make_model("tanh", seed=9, relations=relations)
    path = tmp_path / "m.pt"
    save_checkpoint(path, m)
    m2 = load_model(path)
    assert m2.config == m.config and not m2.training
    sd, sd2 = m.state_dict(), m2.state_dict()
    assert sd.keys() == sd2.keys() and all(torch.equal(sd[k], sd2[k]) for k in sd)
    X = scene(4, seed=10)
    np.testing.assert_array_equal(m2.predict_effect(X, all_actions(4)),
                                  m.predict_effect(X, all_actions(4)))
    for a, b in zip(m.symbols(X), m2.symbols(X)):
        np.testing.assert_array_equal(a, b)


def test_pairwise_relations_read_the_offset_between_two_objects():
    """A pairwise relation is a function of (x_i, x_j, x_j - x_i): one whose last layer reads only the
    offset's height is "j higher than i" exactly, which the attention form q(x_i) . k(x_j) cannot be."""
    torch.manual_seed(0)
    m = EffectModel(ModelConfig(hidden=8, layers=1, d_z=1, heads=1, activation="gumbel_sigmoid",
                                relations="pairwise"))
    m.set_normalisation([0.65, 0.0, 0.05], [0.12, 0.2, 0.03], effect_scale=0.05, arm_scale=0.2)
    # offsets are read in units of pos_std (z: 3 cm); hidden unit 0 = relu(dz), unit 1 = relu(-dz);
    # logit = unit 0 - unit 1 - 0.5
    with torch.no_grad():
        for param in m.pair.parameters():
            param.zero_()
        m.pair[0].weight[0, 12], m.pair[0].weight[1, 12] = 1.0, -1.0
        m.pair[-1].weight[0, 0], m.pair[-1].weight[0, 1], m.pair[-1].bias[0] = 1.0, -1.0, -0.5
    X = scene(4, seed=11)
    X[:, 2] = [0.025, 0.075, 0.125, 0.025]
    _, r = m.eval().symbols(X)
    expected = (X[None, :, 2] - X[:, None, 2] > 0.5 * 0.03).astype(np.uint8)
    np.fill_diagonal(expected, 1)  # r(i, i) = 1 by construction: each object hears itself
    np.testing.assert_array_equal(r[0], expected)
    with pytest.raises(ValueError, match="relations"):
        ModelConfig(relations="dense")


def test_foreign_or_corrupt_checkpoints_give_clear_errors(tmp_path):
    m = make_model(seed=11)
    good = tmp_path / "good.pt"
    save_checkpoint(good, m)
    payload = torch.load(good, weights_only=True)

    other_arch = tmp_path / "other_arch.pt"   # config says d_z=12, weights are for d_z=6
    torch.save({**payload, "config": {**payload["config"], "d_z": 12}}, other_arch)
    with pytest.raises(ValueError, match="other_arch.pt.*does not match"):
        load_model(other_arch)

    foreign = tmp_path / "foreign.pt"          # some other network's plain state dict
    torch.save(torch.nn.Linear(5, 3).state_dict(), foreign)
    with pytest.raises(ValueError, match="foreign.pt.*not an effect-model checkpoint"):
        load_model(foreign)

    unknown_key = tmp_path / "unknown_key.pt"
    torch.save({**payload, "config": {**payload["config"], "layers_x": 3}}, unknown_key)
    with pytest.raises(ValueError, match="unknown_key.pt"):
        load_model(unknown_key)

    for key, value in (("whole_action", "yes"), ("spread", 1), ("d_z", 6.0)):  # a switch or width of another type
        mistyped = tmp_path / f"mistyped_{key}.pt"
        torch.save({**payload, "config": {**payload["config"], key: value}}, mistyped)
        with pytest.raises(ValueError, match=f"mistyped_{key}.pt.*{key} must be"):
            load_model(mistyped)

    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good.read_bytes()[:2000])
    with pytest.raises(ValueError, match="truncated.pt.*not a readable checkpoint"):
        load_model(truncated)

    pickled = tmp_path / "pickled.pt"         # arbitrary pickled objects are refused
    torch.save({"format": "learned-effect-model/1", "obj": np.random.default_rng(0)}, pickled)
    with pytest.raises(ValueError, match="pickled.pt"):
        load_model(pickled)


def test_the_whole_action_tells_the_picked_block_the_release_offset_and_the_targets_type():
    """whole=True: the picked object reads the release offset and the target's type, the target the grasp offset
    and the picked object's type (the paper's columns unchanged); a bystander reads nothing of the action."""
    from learned.effects import action_encoding_dim, encode_actions

    X = torch.tensor(scene(3, seed=4))[None].float()
    X[0, :, 3:] = torch.tensor([[0.0, 1.0], [1.0, 0.0], [1.0, 0.0]])  # a bar, then two cubes
    action = torch.tensor([[0, 1, 1, -1]])  # the bar, grasped at +1, released at -1 on cube 1
    paper, whole = encode_actions(X, action), encode_actions(X, action, whole=True)
    assert paper.shape[-1] == action_encoding_dim(False) and whole.shape[-1] == action_encoding_dim(True)
    torch.testing.assert_close(whole[..., :paper.shape[-1]], paper)
    extra = whole[0, :, paper.shape[-1]:]
    torch.testing.assert_close(extra[0], torch.tensor([1.0, 0, 0, 1, 0, 0, 0, 0, 0, 0]))  # release -1; on a cube
    torch.testing.assert_close(extra[1], torch.tensor([0.0, 0, 0, 0, 0, 0, 0, 1, 0, 1]))  # grasp +1; a bar
    assert not extra[2].any()


def test_a_network_widened_to_the_whole_action_predicts_as_before_until_it_trains():
    from learned.model import with_whole_action

    m = make_model(seed=3, spread=True)
    config = ModelConfig(**{**m.config.to_dict(), "whole_action": True})
    wide = EffectModel(config)
    wide.load_state_dict(with_whole_action(m.state_dict(), config))
    wide.eval()
    X, acts = scene(4, seed=5), np.array(all_actions(4))
    for a, b in zip(m.predict_gaussian(X[None].repeat(len(acts), 0), acts),
                    wide.predict_gaussian(X[None].repeat(len(acts), 0), acts)):
        np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-9)
