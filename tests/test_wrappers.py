"""The training wrappers on a toy environment: FreshStartAutoReset draws a new start state at every
episode boundary; LastReturn keeps the latest finished episodes' returns."""

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import Env, State

from hexa_mjx.engines import wrappers


class Toy(Env):
    """x starts uniform in [0, 1) and moves by the action; the episode ends when x > 10."""

    def restart(self, data, rng):
        return {"x": jax.random.uniform(rng, (1,)), "t": jp.zeros(())}

    def observe(self, data):
        return jp.concatenate([data["x"], data["t"][None]])

    def reset(self, rng):
        data = self.restart(None, rng)
        return State(data, self.observe(data), jp.zeros(()), jp.zeros(()), {}, {})

    def step(self, state, action):
        data = {"x": state.pipeline_state["x"] + action, "t": state.pipeline_state["t"] + 1}
        return state.replace(pipeline_state=data, obs=self.observe(data), reward=action[0],
                             done=(data["x"][0] > 10).astype(float))

    @property
    def observation_size(self):
        return 2

    @property
    def action_size(self):
        return 1

    @property
    def backend(self):
        return "toy"


def test_every_episode_starts_from_a_fresh_draw():
    env = wrappers.wrap_for_training(Toy(), episode_length=100)
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(0), 2))
    step = jax.jit(env.step)
    first = np.asarray(state.pipeline_state["x"][:, 0])
    push = jp.array([[20.0], [0.0]])  # env 0 ends its episode every step, env 1 never
    starts = []
    for _ in range(3):
        state = step(state, push)
        np.testing.assert_array_equal(state.done, [1.0, 0.0])
        x, t = np.asarray(state.pipeline_state["x"][:, 0]), np.asarray(state.pipeline_state["t"])
        assert 0 <= x[0] < 1 and t[0] == 0  # env 0 restarted
        np.testing.assert_array_equal(state.obs, np.stack([x, t], axis=1))  # observation of the new start
        starts.append(x[0])
        assert x[1] == first[1] and t[1] == len(starts)  # env 1 untouched
        np.testing.assert_array_equal(state.info["steps"], [1.0, len(starts)])  # brax: steps of the ended episode
    assert len({first[0], *starts}) == 4  # four episodes, four different starts


def test_zero_noise_uses_brax_wrappers():
    import hexa_mjx
    from hexa_mjx.training import loop as training

    assert training.wrap_env_fn(hexa_mjx.make_env()) is None  # the report's fixed start
    assert training.wrap_env_fn(hexa_mjx.make_env(start_yaw_noise=0.1)) is wrappers.wrap_for_training
    assert training.wrap_env_fn(hexa_mjx.make_env(task="navigate")) is wrappers.wrap_for_training  # random headings


def test_last_return_keeps_each_environments_latest_finished_episode():
    env = wrappers.wrap_for_training(Toy(), episode_length=3, track_returns=True)
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(0), 2))
    step = jax.jit(env.step)
    # A stepped state has the reset state's types, weak types included: the update compiles once.
    typeof = lambda s: [(x.shape, x.dtype, x.weak_type) for x in jax.tree.leaves(jax.tree.map(jax.typeof, s))]  # noqa: E731
    assert typeof(jax.eval_shape(env.step, state, jp.zeros((2, 1)))) == typeof(state)
    assert np.isnan(wrappers.mean_last_return(state))  # no episode has finished
    # env 0 ends every step with return 20; env 1 earns 1 per step and ends at its 3-step limit.
    state = step(state, jp.array([[20.0], [1.0]]))
    np.testing.assert_array_equal(np.isnan(state.info["last_return"]), [False, True])
    assert wrappers.mean_last_return(state) == 20.0  # only env 0 has finished
    for _ in range(2):
        state = step(state, jp.array([[20.0], [1.0]]))
    np.testing.assert_allclose(state.info["last_return"], [20.0, 3.0])
    assert wrappers.mean_last_return(state) == 11.5


def test_returns_are_tracked_on_brax_auto_reset_too():
    import hexa_mjx
    from brax.envs.wrappers import training as brax_training

    from hexa_mjx.training import loop as training

    wrap = training.wrap_env_fn(hexa_mjx.make_env(), track_returns=True)  # fixed start: brax's auto-reset
    env = wrap(hexa_mjx.make_env(), episode_length=10)
    assert isinstance(env, wrappers.LastReturn) and isinstance(env.env, brax_training.AutoResetWrapper)
