"""Training wrappers: brax's, except that every episode draws a fresh start state, and each
environment can step its own randomized physics model.

brax's AutoResetWrapper restarts a finished environment from the state of its first reset, so
start-state noise would be drawn once per environment, not once per episode. `FreshStartAutoReset`
draws it again at every episode boundary (`HexapodEnv.restart`), from a key kept per environment.
`RandomizedVmap` replaces brax's VmapWrapper when a `randomization_fn` gives one model per
environment (`hexa_mjx.mdp.randomization`). `LastReturn` keeps the returns the progress line reports.
`CriticObservation` gives the value network more than the policy sees (an asymmetric actor-critic).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import State, Wrapper
from brax.envs.wrappers import training as brax_training

from hexa_mjx.mdp.failure_schedule import LegFailureSchedule
from hexa_mjx.mdp.observations import failure_observation

POLICY_KEY, CRITIC_KEY = "state", "privileged_state"  # brax's names for the two observations


def _where_done(done, new, old):
    return jp.where(done.reshape(done.shape + (1,) * (new.ndim - done.ndim)), new, old)


class FreshStartAutoReset(Wrapper):
    """Auto-reset a batch of environments to a newly drawn start state when an episode ends."""

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        # Physics-state template the fresh starts are written into (same structure as every state).
        state.info["first_pipeline_state"] = state.pipeline_state
        state.info["restart_rng"] = jax.vmap(lambda k: jax.random.fold_in(k, 1))(rng)
        return state

    def step(self, state: State, action: jax.Array) -> State:
        if "steps" in state.info:
            state.info.update(steps=jp.where(state.done, 0, state.info["steps"]))
        state = self.env.step(state.replace(done=jp.zeros_like(state.done)), action)
        base = self.env.unwrapped
        keys = jax.vmap(jax.random.split)(state.info["restart_rng"])
        # An environment with a curriculum restarts at its level (hexa_mjx.mdp.curriculum).
        level = (state.info["level"],) if "level" in state.info else ()
        fresh = jax.vmap(base.restart)(state.info["first_pipeline_state"], keys[:, 1], *level)
        pipeline_state = jax.tree.map(lambda new, old: _where_done(state.done, new, old), fresh,
                                      state.pipeline_state)
        obs = _where_done(state.done, jax.vmap(base.observe)(fresh), state.obs)
        state.info["restart_rng"] = _where_done(state.done, keys[:, 0], state.info["restart_rng"])
        return state.replace(pipeline_state=pipeline_state, obs=obs)


class RandomizedVmap(Wrapper):
    """vmap over a batch of environments, each with its own mjx.Model (brax's
    DomainRandomizationVmapWrapper for an environment that keeps its model in `mjx_model`)."""

    def __init__(self, env, randomization_fn):
        super().__init__(env)
        self._models, self._in_axes = randomization_fn(env.unwrapped.mjx_model)

    def _with_model(self, model, fn, *args):
        base = self.env.unwrapped
        saved, base.mjx_model = base.mjx_model, model  # swapped while tracing, so each env sees its own
        try:
            return fn(*args)
        finally:
            base.mjx_model = saved

    def reset(self, rng: jax.Array) -> State:
        return jax.vmap(lambda m, k: self._with_model(m, self.env.reset, k), in_axes=(self._in_axes, 0))(
            self._models, rng)

    def step(self, state: State, action: jax.Array) -> State:
        return jax.vmap(lambda m, s, a: self._with_model(m, self.env.step, s, a), in_axes=(self._in_axes, 0, 0))(
            self._models, state, action)


class LastReturn(Wrapper):
    """Keeps each environment's latest finished episode return in `info["last_return"]` (NaN before
    its first), for the progress line: the host reads it between updates (`hexa_mjx.training.ppo`)."""

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        state.info["last_return"] = jp.full(rng.shape[:-1], jp.nan, jp.float32)  # not weak-typed: one compile
        return state

    def step(self, state: State, action: jax.Array) -> State:
        state = self.env.step(state, action)
        # brax's EpisodeWrapper holds the episode's sum on the step it ends (zeroed on the next).
        state.info["last_return"] = jp.where(state.info["episode_done"] > 0, state.info["episode_metrics"]["sum_reward"],
                                             state.info["last_return"])
        return state


class CriticObservation(Wrapper):
    """A batch's observation as two: `POLICY_KEY`, what the policy sees (noise included), and
    `CRITIC_KEY`, what the value network sees: the same observation without its noise, then which
    legs failed this episode and how (`failure_observation`), which the policy must infer from its
    joints. Training only: the policy, and so every evaluation and deployment, sees the first alone."""

    def __init__(self, env):
        super().__init__(env)
        base = env.unwrapped
        # Without observation noise the policy's observation is already the clean one.
        self._observe = jax.vmap(base.observe) if base.config.obs_noise else None
        # Where the failure mode is not "mixed", every failed leg fails the same way.
        self._locked = 1.0 if base.config.failure_mode == "locked" else 0.0

    @staticmethod
    def critic_size(env) -> int:
        """The length of the critic's observation of an (unwrapped) environment."""
        return env.observation_size + 2 * len(env.robot.legs)

    def _split(self, state: State) -> State:
        failed = state.info["failed_legs"]
        locked = state.info.get("failure_locked", jp.full(failed.shape[:-1], self._locked))
        clean = self._observe(state.pipeline_state) if self._observe else state.obs
        critic = jp.concatenate([clean,
                                 failure_observation(failed, locked[..., None].astype(failed.dtype))], axis=-1)
        return state.replace(obs={POLICY_KEY: state.obs, CRITIC_KEY: critic})

    def reset(self, rng: jax.Array) -> State:
        return self._split(self.env.reset(rng))

    def step(self, state: State, action: jax.Array) -> State:
        return self._split(self.env.step(state.replace(obs=state.obs[POLICY_KEY]), action))


def mean_last_return(state: State) -> float:
    """The mean of the environments' latest finished returns (NaN before any has finished)."""
    returns = np.asarray(state.info["last_return"])
    finished = np.isfinite(returns)
    return float(returns[finished].mean()) if finished.any() else math.nan


def wrap_for_training(env, episode_length: int = 1000, action_repeat: int = 1, randomization_fn=None,
                      track_returns: bool = False, fresh_starts: bool = True, failure_schedule: dict | None = None,
                      critic_observation: bool = False):
    """brax's `envs.training.wrap` with `FreshStartAutoReset` in place of its AutoResetWrapper
    (brax's with `fresh_starts=False`) and `RandomizedVmap` in place of its VmapWrapper when there
    is a `randomization_fn`. `failure_schedule` (keyword arguments of
    `failure_schedule.LegFailureSchedule`) schedules the training environments' leg failures. With
    `track_returns`, `LastReturn` keeps each environment's latest return. With `critic_observation`,
    `CriticObservation` gives the value network its own observation."""
    env = RandomizedVmap(env, randomization_fn) if randomization_fn else brax_training.VmapWrapper(env)
    env = brax_training.EpisodeWrapper(env, episode_length, action_repeat)
    env = FreshStartAutoReset(env) if fresh_starts else brax_training.AutoResetWrapper(env)
    env = LegFailureSchedule(env, **failure_schedule) if failure_schedule is not None else env
    env = LastReturn(env) if track_returns else env
    return CriticObservation(env) if critic_observation else env
