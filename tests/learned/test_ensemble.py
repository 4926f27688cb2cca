"""The ensemble Dynamics Model: spread heads fitted to how the world scatters, bootstrap members, their file,
the 95 % bound, warm starts and resuming."""
import numpy as np
import pytest
import torch

from learned import ModelConfig, TrainConfig, train_model
from learned.checkpoint import save_checkpoint
from learned.ensemble import EffectDistribution, EffectEnsemble, distribution_of, load_dynamics
from learned.ensemble_train import EnsembleConfig, member_path, resample, train_ensemble
from learned.spread import SpreadConfig, fit_spread
from learned.synthetic import generate

torch.set_num_threads(1)
SMALL = dict(hidden=32, d_msg=16, d_z=4, heads=2)


@pytest.fixture(scope="module")
def scattered():
    """Toy data whose picked block lands with 2 cm of noise per axis: the only scatter in the world."""
    return generate(1500, seed=3, noise_m=0.02), generate(400, seed=4, noise_m=0.02)


def test_the_spread_head_learns_where_the_world_scatters(scattered):
    data, val = scattered
    res = train_model(data, ModelConfig(hidden=64, d_msg=32, d_z=4, heads=2, spread=True),
                      TrainConfig(epochs=30, batch_size=128, lr=2e-3),
                      val_data=val, progress=False)
    figures = fit_spread(res.model, data, val, SpreadConfig(epochs=30, patience_epochs=10))
    assert 0.85 <= figures["val_coverage95"] <= 0.995, figures
    # objects that land far from the mean were predicted to scatter more than those that land on it
    spread, miss = [], []
    for s in range(len(val)):
        n = int(val.n[s])
        X = val.X[s, :n].astype(float)
        mean, var = res.model.predict_gaussian(X[None], val.action[s:s + 1])
        spread += np.sqrt(var[0].sum(-1)).tolist()
        miss += np.linalg.norm(X[:, :3] + mean[0] - val.X_next[s, :n, :3], axis=1).tolist()
    spread, miss = np.array(spread), np.array(miss)
    far, near = miss > np.quantile(miss, 0.75), miss < np.quantile(miss, 0.25)
    assert spread[far].mean() > 1.5 * spread[near].mean()  # a constant spread gives 1

def test_a_model_without_a_spread_head_predicts_no_spread():
    model = train_model(generate(200, seed=0), ModelConfig(**SMALL), TrainConfig(epochs=1), progress=False).model
    X = generate(1, seed=5).X[0, :2].astype(float)
    mean, var = model.predict_gaussian(X[None], np.array([[0, 0, 1, 0]]))
    assert np.all(var == 0) and np.allclose(mean, model.predict_effects(X[None], np.array([[0, 0, 1, 0]])))
    with pytest.raises(ValueError, match="no spread head"):
        fit_spread(model, generate(50, seed=1), generate(20, seed=2))


def test_the_bound_is_the_mixtures_quantile_and_deterministic():
    rng = np.random.default_rng(0)
    means = rng.normal(0, 0.01, (3, 2, 4, 3))
    narrow = EffectDistribution(means, np.full(means.shape, 1e-6))
    wide = EffectDistribution(means, np.full(means.shape, 1e-4))
    assert np.array_equal(narrow.bound(), narrow.bound())  # seeded
    assert np.all(wide.bound() > narrow.bound())
    assert np.all(narrow.bound() >= narrow.epistemic_m * 0.5)
    # one member, one block, one axis of variance s^2: the bound of |N(0, s^2)| along that axis is ~1.96 s
    one = EffectDistribution(np.zeros((1, 1, 1, 3)), np.array([[[[0.01 ** 2, 0.0, 0.0]]]]))
    assert one.bound(samples=20000)[0] == pytest.approx(0.0196, rel=0.05)
    with pytest.raises(ValueError, match="both be"):
        EffectDistribution(np.zeros((1, 2, 3, 3)), np.zeros((1, 2, 3)))


def test_an_ensemble_round_trips_through_its_file_and_predicts_its_members_mean(tmp_path):
    data, extra = generate(400, seed=0), generate(60, seed=1)
    res = train_ensemble(data, tmp_path / "dynamics.pt", extra=extra, config=ModelConfig(**SMALL),
                         train=TrainConfig(epochs=2, batch_size=64), ensemble=EnsembleConfig(members=3),
                         progress=False)
    model = load_dynamics(tmp_path / "dynamics.pt")
    assert isinstance(model, EffectEnsemble) and len(model) == 3 and model.config.spread
    assert [m["member"] for m in res.members] == [0, 1, 2]
    X = data.X[0, :int(data.n[0])].astype(float)
    actions = np.array([[0, 0, 1, 0], [1, 1, 0, -1]])
    members = np.stack([m.predict_effect(X, actions) for m in model.members])
    assert np.allclose(model.predict_effect(X, actions), members.mean(0))
    dist = distribution_of(model, np.repeat(X[None], 2, 0), actions)
    assert dist.means.shape == (3, 2, len(X), 3) and np.allclose(dist.mean, members.mean(0))
    assert np.all(dist.bound() > 0) and np.all(dist.epistemic_m > 0)  # bootstrap members disagree


def test_members_draw_their_share_of_the_extra_data_and_differ():
    data, extra = generate(300, seed=0), generate(30, seed=1)
    a, b = resample(data, extra, 0, 0, 0.2), resample(data, extra, 1, 0, 0.2)
    assert len(a) == len(data)
    assert not np.array_equal(a.X, b.X)
    extra_rows = {x.tobytes() for x in extra.X}
    assert sum(x.tobytes() in extra_rows for x in a.X) == pytest.approx(0.2 * len(data), abs=2)


def test_members_warm_start_from_a_model_without_a_spread_head_and_resume(tmp_path):
    data = generate(300, seed=0)
    single = train_model(data, ModelConfig(**SMALL, n_max=6), TrainConfig(epochs=1), progress=False).model
    save_checkpoint(tmp_path / "init.pt", single)
    kwargs = dict(train=TrainConfig(epochs=2, batch_size=64), ensemble=EnsembleConfig(members=2), progress=False)
    train_ensemble(data, tmp_path / "dyn.pt", init=tmp_path / "init.pt", **kwargs)
    first = load_dynamics(tmp_path / "dyn.pt")
    assert first.config.n_max == 6  # the limit of the model it started from, not the data's 4
    stamp = member_path(tmp_path / "dyn.pt", 0).stat().st_mtime_ns
    train_ensemble(data, tmp_path / "dyn.pt", init=tmp_path / "init.pt", **kwargs)  # members done: kept
    assert member_path(tmp_path / "dyn.pt", 0).stat().st_mtime_ns == stamp
    again = load_dynamics(tmp_path / "dyn.pt")
    for m, n in zip(first.members, again.members):
        assert all(torch.equal(m.state_dict()[k], n.state_dict()[k]) for k in m.state_dict())
    # an ensemble warm-starts the next: member m from its member m
    train_ensemble(data, tmp_path / "next.pt", init=tmp_path / "dyn.pt", **kwargs)
    assert len(load_dynamics(tmp_path / "next.pt")) == 2


def test_a_single_model_file_loads_as_a_dynamics_model_and_a_foreign_file_is_refused(tmp_path):
    model = train_model(generate(100, seed=0), ModelConfig(**SMALL), TrainConfig(epochs=1), progress=False).model
    save_checkpoint(tmp_path / "one.pt", model)
    assert not isinstance(load_dynamics(tmp_path / "one.pt"), EffectEnsemble)
    torch.save({"format": "something-else"}, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="not an effect-model checkpoint"):
        load_dynamics(tmp_path / "bad.pt")


def test_members_of_the_moving_steps_fit_their_spread_on_the_moving_steps(tmp_path, monkeypatch):
    """A member trained on the transitions that moved their picked block (`only_moved`) has its bound fitted on
    them too: fitted on every transition, the blocked motions it never learned would widen it everywhere."""
    import learned.ensemble_train as ensemble_train
    from learned.effects import moved_picks

    fitted = []

    def spy(model, train, val, config):
        fitted.append((moved_picks(train.X, train.X_next, train.action), moved_picks(val.X, val.X_next, val.action)))
        return fit_spread(model, train, val, config)

    monkeypatch.setattr(ensemble_train, "fit_spread", spy)
    data = generate(400, seed=0)
    assert not moved_picks(data.X, data.X_next, data.action).all()  # blocked motions and grasps of nothing too
    train_ensemble(data, tmp_path / "dyn.pt", config=ModelConfig(**SMALL),
                   train=TrainConfig(epochs=1, batch_size=64, only_moved=True), ensemble=EnsembleConfig(members=1),
                   progress=False)
    (train_moving, val_moving), = fitted
    assert train_moving.all() and val_moving.all() and len(train_moving) > 0
