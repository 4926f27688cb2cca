"""Training: a short run beats the baselines on held-out data; checkpoints; exact resume."""
import numpy as np
import pytest
import torch

from learned import ModelConfig, TrainConfig, evaluate, load_model, train_model
from learned.synthetic import generate
from learned.train import last_path, split_indices

torch.set_num_threads(1)
SMALL = dict(hidden=64, d_msg=32, d_z=8, heads=4)


def untimed(history: list[dict]) -> list[dict]:
    """A training history without its wall-clock field."""
    return [{k: v for k, v in h.items() if k != "elapsed_s"} for h in history]


def fit(data, config, epochs, out, *, resume=False, progress=False, init=None, **train):
    """train_model with TrainConfig(epochs=epochs, **train)."""
    return train_model(data, config, TrainConfig(epochs=epochs, **train), out, resume=resume, progress=progress,
                       init=init)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "model.pt"
    data = generate(2000, seed=1)
    res = fit(data, ModelConfig(**SMALL), 100, out, max_steps=400, lr=1e-3, seed=0)
    return res, out, data


def test_short_training_beats_baselines_on_held_out_samples(trained):
    res, _, _ = trained
    test = generate(500, seed=2)
    ev = evaluate(res.model, test)
    # zero effect: nothing moves; arm only: the pick object follows the gripper, nothing else
    # moves (what an untrained model with the arm term added back roughly predicts).
    assert ev["err_cm"] < 0.6 * ev["zero_cm"], ev
    assert ev["err_cm"] < 0.8 * ev["arm_cm"], ev
    # The same through the planner API: absolute displacements on held-out scenes.
    err, zero = [], []
    for s in range(100):
        n = int(test.n[s])
        X, Xn = test.X[s, :n].astype(np.float64), test.X_next[s, :n].astype(np.float64)
        e = res.model.predict_effect(X, [tuple(test.action[s])])[0]
        err.append(np.linalg.norm(X[:, :3] + e - Xn[:, :3], axis=1).mean())
        zero.append(np.linalg.norm(X[:, :3] - Xn[:, :3], axis=1).mean())
    assert np.mean(err) < 0.6 * np.mean(zero)


def test_best_checkpoint_is_written_and_reloads(trained):
    res, out, data = trained
    assert out.exists() and last_path(out).exists()
    best_epoch = min(res.history, key=lambda h: h["val_err_cm"])["epoch"]
    assert res.best_epoch == best_epoch and res.steps == 400
    _, val_idx = split_indices(len(data), (0.1,), 0)
    reloaded = load_model(out)
    assert evaluate(reloaded, data.subset(val_idx))["err_cm"] == pytest.approx(res.best_val_cm,
                                                                              abs=1e-9)


def test_resume_continues_exactly(tmp_path):
    data = generate(300, seed=5)
    cfg = ModelConfig(hidden=16, d_msg=8, d_z=4, heads=2, activation="gumbel_sigmoid")
    kw = dict(batch_size=32, lr=1e-3, seed=3, progress=False)
    straight = fit(data, cfg, 4, tmp_path / "a.pt", **kw)
    fit(data, cfg, 2, tmp_path / "b.pt", **kw)
    resumed = fit(data, cfg, 4, tmp_path / "b.pt", resume=True, **kw)
    assert [h["epoch"] for h in resumed.history] == [0, 1, 2, 3]
    assert untimed(resumed.history) == untimed(straight.history)
    a, b = straight.model.state_dict(), resumed.model.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(ValueError, match="different config"):
        fit(data, ModelConfig(hidden=16, d_msg=8, d_z=5, heads=2), 6, tmp_path / "b.pt",
                    resume=True, **kw)
    # a run begun before a ModelConfig field existed (its checkpoints lack it) resumes with the field's default
    last = last_path(tmp_path / "b.pt")
    payload = torch.load(last, weights_only=True)
    del payload["config"]["position_axes"]
    torch.save(payload, last)
    assert [h["epoch"] for h in fit(data, cfg, 5, tmp_path / "b.pt", resume=True, **kw).history] == [0, 1, 2, 3, 4]


def test_the_symbolic_model_can_go_without_the_arm_displacement():
    """arm_input=False: the decoder never sees arm_xy (its scale changes nothing), with it it does."""
    from learned import EffectModel

    data = generate(50, seed=3)
    X, A, M = (torch.as_tensor(data.X).float(), torch.as_tensor(data.action).long(),
               torch.as_tensor(data.mask))
    for arm_input in (False, True):
        torch.manual_seed(0)
        model = EffectModel(ModelConfig(**SMALL, arm_input=arm_input)).eval()
        outputs = []
        for scale in (1e-3, 1e3):
            model.arm_scale.fill_(scale)
            outputs.append(model(X, A, M))
        assert torch.equal(*outputs) == (not arm_input)
    assert load_model_roundtrip(ModelConfig(**SMALL, arm_input=False)).config.arm_input is False


def load_model_roundtrip(config):
    import tempfile
    from pathlib import Path

    from learned import EffectModel, save_checkpoint

    with tempfile.TemporaryDirectory() as d:
        save_checkpoint(Path(d) / "m.pt", EffectModel(config))
        return load_model(Path(d) / "m.pt")


def test_only_moved_trains_on_the_transitions_that_moved_the_picked_block(tmp_path):
    from learned.effects import moved_picks

    data = generate(600, seed=4)
    moved = moved_picks(data.X, data.X_next, data.action)
    assert 0 < moved.sum() < len(data)  # the synthetic data grasps nothing now and then
    res = fit(data, ModelConfig(**SMALL), 1, tmp_path / "m.pt", max_steps=2, seed=0, only_moved=True)
    options = torch.load(tmp_path / "m.pt", weights_only=True)["train"]["options"]
    assert options["only_moved"] and options["num_train"] + options["num_val"] == moved.sum()
    assert res.best_epoch == 0


def test_the_bit_usage_penalty_counts_constant_bits_and_leaves_the_given_ones_out():
    from learned import EffectModel
    from learned.losses import bit_usage_penalty

    model = EffectModel(ModelConfig(hidden=8, layers=1, d_msg=8, d_z=2, heads=2, relations="pairwise",
                                    type_symbol=True))
    model.set_normalisation([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], effect_scale=0.05, arm_scale=0.2)
    with torch.no_grad():  # unary bit 0: x > 0, bit 1: never; relation 0: always, relation 1: x_j - x_i > 0.5
        for param in [*model.unary.parameters(), *model.pair.parameters()]:
            param.zero_()
        model.unary[0].weight[0, 0], model.unary[-1].weight[0, 0] = 1.0, 100.0  # logit 100 relu(x) - 1
        model.unary[-1].bias[0], model.unary[-1].bias[1] = -1.0, -100.0
        model.pair[0].weight[0, 10] = 1.0  # hidden unit 0 = relu(x_j - x_i)
        model.pair[-1].bias[0] = 100.0
        model.pair[-1].weight[1, 0], model.pair[-1].bias[1] = 100.0, -50.0
    X = torch.zeros(4, 4, 5)
    X[..., 0] = torch.tensor([-1.0, 1.0, 2.0, 9.0])  # object 3 is padding: it does not count
    X[..., 4] = 1.0  # all large: the given type bit is constant, but it is no learned bit
    # unary bit 1 and relation 0 are constant
    mask = torch.tensor([[True, True, True, False]] * 4)
    assert float(bit_usage_penalty(*model.encode_logits(X, mask)[2:], mask).detach()) == pytest.approx(2.0, abs=1e-3)
    X[..., 0] = torch.tensor([0.0, 0.1, 0.2, 9.0])  # no real pair 0.5 apart: relation 1 is never set
    assert float(bit_usage_penalty(*model.encode_logits(X, mask)[2:], mask).detach()) == pytest.approx(3.0, abs=1e-3)


def test_the_bit_usage_penalty_keeps_relations_the_effect_loss_leaves_constant(tmp_path):
    """On the synthetic data the effect loss alone leaves every pairwise relation at 0; with the
    penalty each one is set on some pairs, and the checkpoint records the weight."""
    data = generate(600, seed=5)
    pairs = data.mask[:, :, None] & data.mask[:, None, :] & ~np.eye(data.mask.shape[1], dtype=bool)
    config = ModelConfig(hidden=32, d_msg=16, d_z=2, heads=3, activation="gumbel_sigmoid", relations="pairwise")
    rates = {}
    for weight in (0.0, 1.0):
        fit(data, config, 30, tmp_path / f"m{weight}.pt", lr=3e-3, seed=0, bit_usage=weight)
        _, r = load_model(tmp_path / f"m{weight}.pt").symbols_batch(data.X, data.mask)
        rates[weight] = [float(r[:, k][pairs].mean()) for k in range(3)]
    assert max(rates[0.0]) < 0.01, rates
    assert min(rates[1.0]) > 0.03, rates
    assert torch.load(tmp_path / "m1.0.pt", weights_only=True)["train"]["options"]["bit_usage"] == 1.0
    assert "bit_usage" not in torch.load(tmp_path / "m0.0.pt", weights_only=True)["train"]["options"]


def test_the_offset_loss_makes_relations_say_on_which_side_of_a_block_another_stands(tmp_path):
    """On the synthetic data the effects do not depend on where blocks stand on the table, and the effect
    loss leaves every relation constant; with the offset loss some relation follows the side of i on which
    j stands (j beyond a line through i, one of 12 directions), and the checkpoint records the weight."""
    data = generate(600, seed=5)
    pairs = data.mask[:, :, None] & data.mask[:, None, :] & ~np.eye(data.mask.shape[1], dtype=bool)
    d = (data.X[:, None, :, :2] - data.X[:, :, None, :2])[pairs]  # x_j - x_i
    sides = [d @ np.array([np.cos(a), np.sin(a)]) > 0 for a in np.deg2rad(np.arange(0, 180, 15))]
    best = {}
    for weight in (0.0, 1.0):
        config = ModelConfig(hidden=32, d_msg=16, d_z=2, heads=3, activation="gumbel_sigmoid", relations="pairwise",
                             offset_decoder=bool(weight))
        fit(data, config, 30, tmp_path / f"m{weight}.pt", lr=3e-3, seed=0, offset_weight=weight)
        _, r = load_model(tmp_path / f"m{weight}.pt").symbols_batch(data.X, data.mask)
        bits = [r[:, k][pairs] for k in range(3)]
        best[weight] = max((abs(np.corrcoef(b, side)[0, 1]) for b in bits if b.std() for side in sides), default=0.0)
    assert best[0.0] < 0.2, best
    assert best[1.0] > 0.4, best
    assert torch.load(tmp_path / "m1.0.pt", weights_only=True)["train"]["options"]["offset_weight"] == 1.0
    with pytest.raises(ValueError, match="offset_decoder"):
        fit(data, ModelConfig(hidden=8, d_msg=8, d_z=1, heads=1), 1, tmp_path / "x.pt", offset_weight=1.0)


def test_an_offset_head_from_relations_reads_the_relations_alone():
    """With ``offset_from_relations`` the offset read back depends on the pair's relations and not on the
    unary bits, so the relations must carry every axis; the option needs the offset head."""
    from learned.model import EffectModel

    torch.manual_seed(0)
    for alone in (False, True):
        model = EffectModel(ModelConfig(hidden=8, d_msg=8, d_z=2, heads=3, relations="pairwise",
                                        offset_decoder=True, offset_from_relations=alone))
        u, r = torch.rand(1, 3, 2), torch.rand(1, 3, 3, 3)
        same_r = model.reconstruct_offsets(u, r), model.reconstruct_offsets(torch.rand(1, 3, 2), r)
        assert torch.equal(*same_r) == alone
        assert not torch.equal(same_r[0], model.reconstruct_offsets(u, torch.rand(1, 3, 3, 3)))
    with pytest.raises(ValueError, match="offset_decoder"):
        ModelConfig(offset_from_relations=True)


def test_the_offset_radius_asks_only_neighbours_where_they_stand():
    """With a radius, a pair farther apart on the table than it is to read back as no offset, a nearer pair
    as its squashed offset, as without a radius."""
    from learned.losses import offset_loss
    from learned.model import EffectModel

    torch.manual_seed(0)
    model = EffectModel(ModelConfig(hidden=8, d_msg=8, d_z=1, heads=2, relations="pairwise", offset_decoder=True))
    X = torch.zeros(1, 2, 5)
    X[0, 1, :3] = torch.tensor([0.3, 0.05, 0.0])  # 30 cm away
    mask, u, r = torch.ones(1, 2, dtype=torch.bool), torch.rand(1, 2, 1), torch.rand(1, 2, 2, 2)
    read = model.reconstruct_offsets(u, r)[0]
    far = (read[0, 1].pow(2).sum() + read[1, 0].pow(2).sum()) / 2
    assert torch.allclose(offset_loss(model, X, mask, u, r, radius_m=0.1), far)
    assert not torch.allclose(offset_loss(model, X, mask, u, r), far)
    assert torch.allclose(offset_loss(model, X, mask, u, r, radius_m=0.5), offset_loss(model, X, mask, u, r))


def test_the_position_loss_makes_a_unary_bit_say_where_a_block_stands(tmp_path):
    """Without the position loss, the synthetic effects make some unary bit follow one axis of the table
    and none the other; with it, both halves (x and y beyond the middle) have a bit that says them. The
    checkpoint records the weight, and the loss needs its head."""
    data = generate(600, seed=5)
    X = data.X[data.mask]
    sides = [X[:, a] > np.median(X[:, a]) for a in (0, 1)]
    best = {}
    for weight in (0.0, 1.0):
        config = ModelConfig(hidden=32, d_msg=16, d_z=3, heads=1, activation="gumbel_sigmoid", arm_input=False,
                             position_decoder=bool(weight))
        fit(data, config, 30, tmp_path / f"p{weight}.pt", lr=3e-3, seed=0, position_weight=weight)
        u, _ = load_model(tmp_path / f"p{weight}.pt").symbols_batch(data.X, data.mask)
        bits = [u[..., k][data.mask] for k in range(3)]
        best[weight] = [max((abs(np.corrcoef(b, side)[0, 1]) for b in bits if b.std()), default=0.0) for side in sides]
    assert min(best[1.0]) > 0.6 and min(best[1.0]) > min(best[0.0]) + 0.3, best
    assert torch.load(tmp_path / "p1.0.pt", weights_only=True)["train"]["options"]["position_weight"] == 1.0
    with pytest.raises(ValueError, match="position_decoder"):
        fit(data, ModelConfig(hidden=8, d_msg=8, d_z=1, heads=1), 1, tmp_path / "x.pt", position_weight=1.0)


def test_the_position_loss_on_x_alone_reads_back_where_a_block_stands_along_x_only():
    """`position_axes="x"`: the head reads back x alone, so a block moved along y (the axis of the skill's
    grasp and release offsets) costs the position loss nothing and one moved along x does."""
    from learned.losses import position_loss
    from learned.model import EffectModel

    torch.manual_seed(0)
    model = EffectModel(ModelConfig(hidden=8, d_msg=8, d_z=2, heads=1, position_decoder=True, position_axes="x"))
    model.set_normalisation(torch.tensor([0.6, 0.0, 0.05]), torch.tensor([0.1, 0.2, 0.03]), 0.05, 0.3)
    X = torch.zeros(1, 2, 5)
    X[0, :, :3] = torch.tensor([[0.55, -0.1, 0.025], [0.7, 0.2, 0.025]])
    mask, u = torch.ones(1, 2, dtype=torch.bool), torch.rand(1, 2, 2)
    assert model.squashed_positions(X).shape == (1, 2, 1) and model.reconstruct_positions(u).shape == (1, 2, 1)
    along_y, along_x = X.clone(), X.clone()
    along_y[0, :, 1] += 0.075
    along_x[0, :, 0] += 0.075
    assert torch.allclose(position_loss(model, along_y, mask, u), position_loss(model, X, mask, u))
    assert not torch.allclose(position_loss(model, along_x, mask, u), position_loss(model, X, mask, u))
    with pytest.raises(ValueError, match="position_axes"):
        ModelConfig(position_axes="z")


def test_the_transition_loss_asks_for_bits_a_step_can_be_predicted_in(tmp_path):
    """`transition_decoder`: a head predicts the bits after a step from the bits before and the action; the
    loss reads the bits on X_next, so its gradient reaches the encoder through them as well. Training records
    the weight, and the loss needs its head."""
    from learned.losses import transition_loss
    from learned.model import EffectModel

    torch.manual_seed(0)
    model = EffectModel(ModelConfig(hidden=8, d_msg=8, d_z=2, heads=2, relations="pairwise", transition_decoder=True))
    X = torch.zeros(1, 3, 5)
    X[0, :, :3] = torch.tensor([[0.55, -0.1, 0.025], [0.7, 0.2, 0.025], [0.6, 0.0, 0.025]])
    X[0, :, 3] = 1
    X_next = X.clone()
    X_next[0, 0, :3] = torch.tensor([0.7, 0.2, 0.075])  # block 0 put on block 1
    action, mask = torch.tensor([[0, 0, 1, 0]]), torch.ones(1, 3, dtype=torch.bool)
    u, r = model.encode(X, mask)
    unary, relation = model.predict_next_logits(X, action, u, r)
    assert unary.shape == (1, 3, 2) and relation.shape == (1, 2, 3, 3)
    loss = transition_loss(model, X, X_next, action, mask, u, r)
    assert not torch.allclose(loss, transition_loss(model, X, X, action, mask, u, r))
    model.zero_grad()
    transition_loss(model, X, X_next, action, mask, u.detach(), r.detach()).backward()
    assert model.unary[0].weight.grad.abs().sum() > 0  # through the bits read after the step
    data = generate(200, seed=3)
    config = ModelConfig(hidden=8, d_msg=8, d_z=2, heads=1, activation="gumbel_sigmoid", transition_decoder=True)
    fit(data, config, 1, tmp_path / "t.pt", transition_weight=0.5)
    assert torch.load(tmp_path / "t.pt", weights_only=True)["train"]["options"]["transition_weight"] == 0.5
    with pytest.raises(ValueError, match="transition_decoder"):
        fit(data, ModelConfig(hidden=8, d_msg=8, d_z=1, heads=1), 1, tmp_path / "x.pt", transition_weight=1.0)


TINY = ModelConfig(hidden=16, d_msg=8, d_z=4, heads=2, activation="gumbel_sigmoid")


def _same_weights(a, b):
    sa, sb = a.model.state_dict(), b.model.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_k_epochs_then_resume_equals_one_sitting(tmp_path, precision):
    """Fast settings (bfloat16 autocast, early stopping armed): N epochs in one call == k, then resume to N."""
    data = generate(400, seed=6)
    kw = dict(batch_size=64, lr=3e-3, seed=2, progress=False, precision=precision, patience_epochs=50,
              min_delta_cm=0.01, threads=1)
    straight = fit(data, TINY, 6, tmp_path / "a.pt", **kw)
    first = fit(data, TINY, 3, tmp_path / "b.pt", **kw)
    assert first.stop_reason.value == "max_epochs" and first.epochs_reached == 3 and first.finished
    resumed = fit(data, TINY, 6, tmp_path / "b.pt", resume=True, **kw)
    assert resumed.best_val_cm == straight.best_val_cm and resumed.best_epoch == straight.best_epoch
    assert resumed.epochs_reached == straight.epochs_reached == 6 and resumed.steps == straight.steps
    assert _same_weights(resumed, straight)
    assert untimed(resumed.history) == untimed(straight.history)
    assert [h.get("stop_reason") for h in resumed.history] == [None] * 5 + ["max_epochs"]
    with pytest.raises(ValueError, match="different config/options"):  # the precision is part of the result
        fit(data, TINY, 8, tmp_path / "b.pt", resume=True,
                    **{**kw, "precision": "bfloat16" if precision == "float32" else "float32"})


def test_early_stopping_stops_on_a_plateau_and_resuming_it_is_a_no_op(tmp_path):
    """With a min_delta the tiny set cannot keep beating, training stops `patience` epochs after the last
    improvement; the reason is in the result, both checkpoints and the history; a resume trains nothing."""
    data = generate(300, seed=7)
    kw = dict(batch_size=64, lr=1e-3, seed=0, progress=False, patience_epochs=3, min_delta_cm=0.5, threads=1)
    res = fit(data, TINY, 200, tmp_path / "m.pt", **kw)
    assert res.stop_reason.value == "converged" and res.finished and res.epochs_reached < 200
    vals = [h["val_err_cm"] for h in res.history]
    ref, last = float("inf"), -1  # the last epoch that beat the previous such one by min_delta
    for e, v in enumerate(vals):
        if v < ref - 0.5:
            ref, last = v, e
    assert res.epochs_reached - 1 - last == 3
    assert res.history[-1]["stop_reason"] == "converged" and res.best_val_cm == min(vals)
    for path in (tmp_path / "m.pt", last_path(tmp_path / "m.pt")):
        st = torch.load(path, weights_only=True)["train"]
        assert (st["stop_reason"], st["finished"], st["epochs_reached"]) == ("converged", True, res.epochs_reached)
    again = fit(data, TINY, 400, tmp_path / "m.pt", resume=True, **kw)
    assert again.stop_reason.value == "converged" and again.epochs_reached == res.epochs_reached
    assert again.steps == res.steps and again.best_val_cm == res.best_val_cm and _same_weights(again, res)


def test_a_time_limited_run_is_unfinished_and_resumes_to_the_one_sitting_result(tmp_path):
    data = generate(300, seed=8)
    kw = dict(batch_size=64, lr=1e-3, seed=1, progress=False, threads=1)
    straight = fit(data, TINY, 4, tmp_path / "a.pt", **kw)
    out, calls = tmp_path / "b.pt", 0
    res = fit(data, TINY, 4, out, time_limit_s=1e-9, **kw)  # one epoch per call, whatever the time
    while not res.finished:
        assert res.stop_reason.value == "time_limit" and res.epochs_reached == calls + 1
        st = torch.load(out, weights_only=True)["train"]
        assert st["finished"] is False and st["stop_reason"] == "time_limit"
        calls += 1
        res = fit(data, TINY, 4, out, time_limit_s=1e-9, resume=True, **kw)
    assert calls == 3 and res.stop_reason.value == "max_epochs" and res.epochs_reached == 4
    assert torch.load(out, weights_only=True)["train"]["finished"] is True
    assert res.best_val_cm == straight.best_val_cm and _same_weights(res, straight)


def test_train_settings_scale_the_learning_rate_with_the_batch():
    from learned.train_config import PAPER_LR, TrainConfig, scaled_lr

    assert scaled_lr(128) == PAPER_LR and scaled_lr(1024) == pytest.approx(8 * PAPER_LR)
    assert TrainConfig.fast(512).lr == pytest.approx(4e-4)
    assert TrainConfig.fast(512, lr=1e-3).lr == 1e-3
    paper = TrainConfig()
    assert (paper.batch_size, paper.lr, paper.precision, paper.patience_epochs) == (128, 1e-4, "float32", None)
    with pytest.raises(ValueError, match="precision"):
        TrainConfig(precision="float16")


def test_fine_tuning_starts_from_the_checkpoint_and_takes_the_data_object_limit(trained, tmp_path):
    """init=: the weights and input normalisation are the checkpoint's (not recomputed from the new
    data), the network settings too, and the object limit is the new data's (here 6)."""
    _, ckpt, _ = trained
    start = load_model(ckpt)
    more = generate(300, seed=7, n_choices=(5, 6), n_max=6)
    tuned = train_model(more, None, TrainConfig(epochs=1, lr=1e-12, seed=0), tmp_path / "t.pt", progress=False,
                        init=ckpt).model
    assert tuned.config.n_max == 6 and {**tuned.config.to_dict(), "n_max": 4} == start.config.to_dict()
    for name, value in start.state_dict().items():  # lr 1e-12: nothing moved
        torch.testing.assert_close(tuned.state_dict()[name], value, atol=1e-6, rtol=0, msg=name)
    fresh = train_model(more, ModelConfig(n_max=6, **SMALL), TrainConfig(epochs=1, lr=1e-12, seed=0), tmp_path / "f.pt",
                        progress=False).model
    assert not torch.equal(fresh.pos_mean, start.pos_mean)  # a fresh run's normalisation is the data's
    assert evaluate(tuned, more)["err_cm"] < evaluate(fresh, more)["err_cm"]
    assert load_model(tmp_path / "t.pt").config.n_max == 6


def test_fine_tuning_refuses_other_network_settings_and_resumes_only_from_the_same_start(trained, tmp_path):
    _, ckpt, data = trained
    differ = r"other settings than asked for: activation 'gumbel_sigmoid' \(its 'sigmoid'\)"
    with pytest.raises(ValueError, match=differ):
        train_model(data, ModelConfig(**{**SMALL, "activation": "gumbel_sigmoid"}), TrainConfig(epochs=1),
                    tmp_path / "m.pt", progress=False, init=ckpt)
    fit(data, None, 1, tmp_path / "m.pt", init=ckpt)
    with pytest.raises(ValueError, match="refusing to resume"):
        fit(data, ModelConfig(**SMALL), 2, tmp_path / "m.pt", resume=True)


def two_outcomes(num_samples: int, seed: int, on_top: float = 0.7):
    """Two cubes, block 0 placed on block 1: it comes to rest on top (5 cm up) in `on_top` of the steps, else
    beside it on the table; nothing in X tells which."""
    from learned.dataset import Transitions, pack_samples
    from learned.synthetic import STATUS_CODES, random_scene

    rng = np.random.default_rng(seed)
    samples = []
    for _ in range(num_samples):
        X = random_scene(rng, 2)
        X[:, 3:] = (1.0, 0.0)  # two cubes
        X_next = X.copy()
        X_next[0, :3] = X[1, :3] + ((0.0, 0.0, 0.05) if rng.random() < on_top else (0.06, 0.0, 0.0))
        samples.append({"X": X, "action": (0, 0, 1, 0), "X_next": X_next, "grasped": 0, "status": 0})
    meta = {"format": "tamp-transitions/1", "n_max": 2, "seed": seed, "status_codes": STATUS_CODES,
            "world_config": {"synthetic": True}}
    return Transitions(**pack_samples(samples, 2), meta=meta)


def test_the_distance_loss_predicts_the_more_frequent_outcome_where_the_squared_loss_predicts_between(tmp_path):
    """A block that rests on a cube 7 times in 10 and beside it otherwise: the paper's squared loss predicts it
    between the two (the mean: 3.5 cm up), the distance loss near the top (5 cm up), and records its choice."""
    data = two_outcomes(1500, seed=3)
    X = two_outcomes(1, seed=99).X[0, :2].astype(np.float64)
    heights = {}
    for loss in ("squared", "distance"):
        res = fit(data, ModelConfig(**SMALL), 40, tmp_path / f"{loss}.pt", lr=1e-3, seed=0, effect_loss=loss)
        heights[loss] = float(res.model.predict_effect(X, [(0, 0, 1, 0)])[0][0, 2] + X[0, 2] - X[1, 2])
    assert 0.025 < heights["squared"] < 0.045, heights
    assert heights["distance"] > 0.045, heights
    assert torch.load(tmp_path / "distance.pt", weights_only=True)["train"]["options"]["effect_loss"] == "distance"
    assert "effect_loss" not in torch.load(tmp_path / "squared.pt", weights_only=True)["train"]["options"]
