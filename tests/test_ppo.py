"""hexa_mjx.training.ppo runs brax's PPO: the same params as brax's `ppo.train` from the same seed, with the
host called back between updates instead of from inside the program."""

import dataclasses
import jax
import numpy as np
import pytest

from hexa_mjx.training import config, networks, ppo, loop as training

# A tiny rollout (8 envs x 4 steps x 2 minibatches = 64 env steps per update), two intervals of two
# updates, start noise drawn per episode (hexa_mjx's wrappers), two epochs of SGD, small networks.
CFG = config.TrainConfig(num_envs=8, batch_size=8, num_minibatches=2, unroll_length=4, episode_length=20,
                         update_epochs=2, hidden=[32, 32], start_joint_noise=0.05)


@pytest.fixture(scope="module")
def settings():
    env = config.make_env_for(CFG)
    return env, training.ppo_settings(CFG, num_timesteps=192, num_evals=3, seed=5, devices=2), dict(
        network_factory=networks.network_factory(CFG), wrap_env_fn=training.wrap_env_fn(env))


@pytest.fixture(scope="module")
def ours(settings):
    env, ppo_settings, kwargs = settings
    intervals, updates = [], []
    params = ppo.train(env, ppo_settings, **kwargs, on_interval=lambda step, _, p, adam, *rest: intervals.append((step, p, adam)),
                       on_update=lambda step, env_state: updates.append((step, env_state.obs.shape)))
    return params, intervals, updates


def test_same_params_as_brax_ppo_train(settings, ours):
    from brax.training.agents.ppo import train as brax_ppo

    env, ppo_settings, kwargs = settings
    _, reference, _ = brax_ppo.train(environment=env, run_evals=False, num_eval_envs=2,
                                     **dataclasses.asdict(ppo_settings), **kwargs)
    params, _, _ = ours
    assert jax.tree.structure(params) == jax.tree.structure(jax.tree.map(np.asarray, reference))
    jax.tree.map(np.testing.assert_array_equal, params, reference)


def test_host_sees_every_update_and_each_interval(ours):
    params, intervals, updates = ours
    # brax's rounding: 192 steps in 2 intervals of ceil(192 / 128) updates of 64 steps each.
    assert [step for step, _ in updates] == [64, 128, 192, 256]
    devices = len(jax.local_devices()[:2])
    assert {shape for _, shape in updates} == {(devices, 8 // devices, 52)}
    assert [step for step, _, _ in intervals] == [0, 128, 256]
    # Adam's step count: 2 epochs x 2 minibatches per update; its state is what a checkpoint saves.
    assert [int(adam[0].count) for _, _, adam in intervals] == [0, 8, 16]
    jax.tree.map(np.testing.assert_array_equal, intervals[-1][1], params)


def test_bad_shapes_are_refused_before_anything_compiles(settings):
    env, ppo_settings, kwargs = settings
    with pytest.raises(ValueError, match="num_envs 6 must divide"):
        ppo.train(env, dataclasses.replace(ppo_settings, num_envs=6), **kwargs)


def test_annealed_learning_rate_reaches_zero_at_the_end(settings, ours):
    """CleanRL's schedule: at the run's last step the learning rate is 0, so a run that starts
    there leaves the networks as they were, while the normalizer still learns."""
    env, ppo_settings, kwargs = settings
    intervals = []
    ppo.train(env, ppo_settings, **kwargs, anneal_lr=(256, 256),
              on_interval=lambda step, _, p, adam, *rest: intervals.append(p))
    (norm0, policy0, value0), (norm, policy, value) = intervals[0], intervals[-1]
    jax.tree.map(np.testing.assert_array_equal, (policy, value), (policy0, value0))
    assert not np.array_equal(norm.mean, norm0.mean)
    # From step 0 the schedule leaves most of the learning rate: the params move, but not as without it.
    moved = jax.tree.leaves(ppo.train(env, ppo_settings, **kwargs, anneal_lr=(0, 256))[1])
    for other in (policy0, ours[0][1]):
        assert not all(np.array_equal(a, b) for a, b in zip(moved, jax.tree.leaves(other)))


class Seen(Exception):
    """Raised by on_interval once it has seen the environments training starts from."""


def start_environments(settings, **extra):
    env, ppo_settings, kwargs = settings
    seen = []

    def on_interval(step, make_policy, params, adam, env_state, at):
        seen.append(jax.tree.map(np.asarray, env_state))
        raise Seen  # before the update compiles: only the environments' reset runs

    with pytest.raises(Seen):
        ppo.train(env, ppo_settings, **kwargs, on_interval=on_interval, **extra)
    return seen[0]


def test_saved_environments_carry_on_under_a_new_schedule(settings, capsys):
    """A resume that is not exact (a longer run) continues the environments it saved: their
    episodes, and a curriculum's levels, go on instead of starting over."""
    fresh = start_environments(settings)
    moved = [np.asarray(leaf) + 1 if np.issubdtype(np.asarray(leaf).dtype, np.floating) else np.asarray(leaf)
             for leaf in jax.tree.leaves(fresh)]
    carried = start_environments(settings, environments=moved)
    jax.tree.map(np.testing.assert_array_equal, jax.tree.leaves(carried), moved)
    # Saved from another count of environments: they start afresh, and the run says so.
    afresh = start_environments(settings, environments=[leaf[:, :1] for leaf in moved])
    jax.tree.map(np.testing.assert_array_equal, afresh, fresh)
    assert "the saved environments do not fit this run's: they start afresh" in capsys.readouterr().out


def test_saved_environments_are_read_for_the_same_count_of_environments():
    from hexa_mjx.training import resume

    arrays = {"local_key": np.zeros(2), "env_0001": np.ones(3), "env_0000": np.zeros(3)}
    facts = {"schedule": resume.schedule(CFG), "processes": 1}
    leaves = resume.saved_environments((arrays, facts), dataclasses.replace(CFG, num_timesteps=10 ** 7))
    assert [leaf.tolist() for leaf in leaves] == [[0.0] * 3, [1.0] * 3]  # in the state's leaf order
    assert resume.saved_environments((arrays, facts), dataclasses.replace(CFG, num_envs=16)) is None
    assert resume.saved_environments((arrays, {**facts, "processes": 2}), CFG) is None
    assert resume.saved_environments(None, CFG) is None
