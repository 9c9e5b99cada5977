"""Training wrappers: brax's, except that every episode draws a fresh start state, and each
environment can step its own randomized physics model.

brax's AutoResetWrapper restarts a finished environment from the state of its first reset, so
start-state noise would be drawn once per environment, not once per episode. `FreshStartAutoReset`
draws it again at every episode boundary (`HexapodEnv.restart`), from a key kept per environment.
`RandomizedVmap` replaces brax's VmapWrapper when a `randomization_fn` gives one model per
environment (`hexa_mjx.randomization`). `ProgressTap` tells the host how far training has got.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.envs.base import State, Wrapper
from brax.envs.wrappers import training as brax_training

from hexa_mjx.curriculum import LevelTap
from hexa_mjx.failure_schedule import LegFailureSchedule


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
        # An environment with a curriculum restarts at its level (hexa_mjx.curriculum).
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


class ProgressTap(Wrapper):
    """Every `every` steps, calls `record(steps, return_sum, episodes)` on the host: the steps each
    environment has taken, and the sum and count of the returns of each environment's latest
    finished episode. A few scalars now and then, where brax's `log_training_metrics` copies every
    environment's episode metrics to the host on every update (docs/RESULTS.md: 22% slower)."""

    def __init__(self, env, record, every: int):
        super().__init__(env)
        self.record, self.every = record, every

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        state.info["progress_clock"] = jp.zeros(rng.shape[:-1], jp.int32)
        state.info["last_return"] = jp.full(rng.shape[:-1], jp.nan, jp.float32)  # not weak-typed: one compile
        return state

    def step(self, state: State, action: jax.Array) -> State:
        state = self.env.step(state, action)
        clock = state.info["progress_clock"] + 1
        # brax's EpisodeWrapper holds the episode's sum on the step it ends (zeroed on the next).
        last = jp.where(state.info["episode_done"] > 0, state.info["episode_metrics"]["sum_reward"],
                        state.info["last_return"])
        state.info.update(progress_clock=clock, last_return=last)
        finished = jp.isfinite(last)
        report = (clock[0], jp.sum(jp.where(finished, last, 0.0)), jp.sum(finished))
        jax.lax.cond(clock[0] % self.every == 0, lambda r: jax.debug.callback(self.record, *r), lambda r: None,
                     report)
        return state


def wrap_for_training(env, episode_length: int = 1000, action_repeat: int = 1, randomization_fn=None,
                      level_record=None, progress_record=None, progress_every: int = 64,
                      fresh_starts: bool = True, failure_schedule: dict | None = None):
    """brax's `envs.training.wrap` with `FreshStartAutoReset` in place of its AutoResetWrapper
    (brax's with `fresh_starts=False`) and `RandomizedVmap` in place of its VmapWrapper when there
    is a `randomization_fn`. `failure_schedule` (keyword arguments of
    `failure_schedule.LegFailureSchedule`) schedules the training environments' leg failures. With a
    curriculum and a `level_record` callback, `curriculum.LevelTap` reports the levels to it; with a
    `progress_record`, `ProgressTap` reports every `progress_every` steps."""
    env = RandomizedVmap(env, randomization_fn) if randomization_fn else brax_training.VmapWrapper(env)
    env = brax_training.EpisodeWrapper(env, episode_length, action_repeat)
    env = FreshStartAutoReset(env) if fresh_starts else brax_training.AutoResetWrapper(env)
    env = LegFailureSchedule(env, **failure_schedule) if failure_schedule is not None else env
    levels = env.unwrapped.config.curriculum_levels if level_record else 0  # brax's eval env has none
    env = LevelTap(env, levels, level_record) if levels else env
    return ProgressTap(env, progress_record, progress_every) if progress_record else env
