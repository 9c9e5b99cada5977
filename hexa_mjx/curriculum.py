"""The navigation curriculum: goals near and ahead first, widened per environment as it succeeds.

In the style of legged_gym's terrain curriculum, each training environment has a difficulty
level, kept in `state.info["level"]` across its episodes (brax's auto-reset carries `info` over).
With `curriculum_levels` = N, an environment at level l (0 to N-1) draws goals over a fraction
(l + 1) / N of the full ranges: bearings within +-180 deg x that fraction of its heading, and
distances from the range's start up to that fraction of the way to its end. Level N-1 is the
full task. Each goal reached moves the environment up one level; an episode that ends in a fall,
or without reaching any goal, moves it down one. Every environment starts at level 0.

Evaluation always uses the full ranges: the curriculum is a setting of the training environment
only. `LevelTap` hands the levels to the host now and then, so each evaluation row can say how the
environments are spread over the levels.
"""

from __future__ import annotations

import collections

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import State, Wrapper

TAP_EVERY = 500  # control steps of each environment between two level snapshots


def range_fraction(level, levels: int):
    """The fraction of the full bearing and distance ranges open at `level` (1 without a curriculum)."""
    if not levels:
        return 1.0
    return (level + 1) / levels


def next_level(level, levels: int, reached_goal, episode_over, episode_failed):
    """One environment's level after a step: +1 for a goal reached, -1 for an episode that ended in
    a fall or without a goal, kept within [0, levels - 1]."""
    change = reached_goal.astype(jp.int32) - (episode_over & episode_failed).astype(jp.int32)
    return jp.clip(level + change, 0, levels - 1)


class LevelTap(Wrapper):
    """Sends the batch's level histogram to `record` every TAP_EVERY steps (a host callback that
    keeps only a reference, as `hexa_mjx.optimizer_state` does, so no device waits on the host)."""

    def __init__(self, env, levels: int, record, every: int = TAP_EVERY):
        super().__init__(env)
        self.levels, self.record, self.every = levels, record, every

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        state.info["tap_clock"] = jp.zeros(rng.shape[:-1], jp.int32)
        return state

    def step(self, state: State, action: jax.Array) -> State:
        state = self.env.step(state, action)
        clock = state.info["tap_clock"] + 1
        state.info["tap_clock"] = clock
        counts = jp.zeros(self.levels, jp.int32).at[state.info["level"]].add(1)
        jax.lax.cond(clock[0] % self.every == 0, lambda c: jax.debug.callback(self.record, c), lambda c: None, counts)
        return state


class LevelHistogram:
    """Host side of `LevelTap`: the latest level counts of each device's environments."""

    def __init__(self, levels: int, devices: int):
        self.levels = levels
        self._latest = collections.deque(maxlen=devices)  # one snapshot per device, each its own batch

    def __call__(self, counts) -> None:
        self._latest.append(counts)  # a reference only (see LevelTap)

    def summary(self) -> dict:
        """{"curriculum/level_mean", "curriculum/top_level_share", "curriculum/level_<l>"} over the latest
        snapshots ({} before the first): shares of environments at each level."""
        jax.effects_barrier()
        if not self._latest:
            return {}
        counts = np.sum([np.asarray(c) for c in self._latest], axis=0).astype(float)
        share = counts / counts.sum()
        return {"curriculum/level_mean": float(share @ np.arange(self.levels)),
                "curriculum/top_level_share": float(share[-1]),
                **{f"curriculum/level_{level}": float(s) for level, s in enumerate(share)}}
