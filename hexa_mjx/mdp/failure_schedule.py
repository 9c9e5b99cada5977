"""When training fails legs, and which: failures from a step count on, and the failed leg drawn by its cost.

Two training-only settings of `--leg_failure random` (evaluation always draws as configured):

- `--leg_failure_after N`: no leg fails in the first N environment steps, so the policy first
  learns to walk intact (a run that failed legs from step 0 had not learnt to reach goals
  within the hour; fine-tuning a walking policy had, docs/RESULTS.md "Walking on with a failed leg").
- `--leg_failure_adaptive`: the failed leg is drawn by how much losing it costs the policy now,
  instead of uniformly. The cost of leg k is its deficit in progress per episode against the
  intact episodes, 1 - progress_k / progress_intact, over the training batch's finished episodes
  (decayed with a half-life of HALF_LIFE control steps). Progress is the goals reached in a task
  with goals, and in a task with commands the metres walked along them (the commanded velocity's
  direction, as the terrain curriculum measures it): commands are drawn alike with or without a
  failure, so a leg whose loss slows the walk, or ends it in a fall, walks fewer metres.
  UNIFORM_SHARE of the draws are uniform over the legs; the rest go to each leg in proportion to
  max(deficit, FLOOR) ** 2: twice the deficit, four times the practice. The uniform share keeps
  every leg in practice, as prioritized
  replay keeps a floor: a deficit-only draw starved the legs a gait did not use yet and spent most
  of the practice on legs it could not yet learn to lose (docs/RESULTS.md, "One run with a failure schedule"). In the
  navigation task goals per episode measure both speed and falls (a fall ends the episode); in the
  report's task, with one goal, they are the success rate.

`LegFailureSchedule` is a batch wrapper: it writes the rate and the leg probabilities into every
environment's `info`, where `HexapodEnv.step` reads them for the next episode's draw.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import State, Wrapper

FLOOR = 0.05  # smallest deficit a leg is weighed by
UNIFORM_SHARE = 0.5  # of the failures, drawn uniformly over the legs whatever their deficits
HALF_LIFE = 1000  # control steps per environment over which a finished episode's weight halves
DECAY = 0.5 ** (1 / HALF_LIFE)


def leg_probabilities(stats: jax.Array) -> jax.Array:
    """Probability of each leg being the failed one from `stats` (1 + legs, 2): the (decayed) sums of
    progress (goals reached, or metres walked) and of episodes, intact first, then with leg 1, 2, ...
    failed."""
    mean = stats[:, 0] / jp.maximum(stats[:, 1], 1e-9)
    deficit = jp.clip(1.0 - mean[1:] / jp.maximum(mean[0], 1e-9), FLOOR, 1.0)
    weight = deficit ** 2
    return UNIFORM_SHARE / weight.size + (1.0 - UNIFORM_SHARE) * weight / weight.sum()


def episode_stats(failed_legs: jax.Array, progress: jax.Array, ended: jax.Array) -> jax.Array:
    """(1 + legs, 2) sums over a batch of [progress, episodes] of the episodes that `ended`, by
    condition: intact, then each failed leg. `failed_legs` (batch, legs) is 0/1."""
    intact = (failed_legs.sum(-1, keepdims=True) == 0).astype(jp.float32)
    condition = jp.concatenate([intact, failed_legs], axis=-1)  # two failed legs count for each
    weight = ended.astype(jp.float32)[:, None] * condition
    return jp.stack([(weight * progress[:, None]).sum(0), weight.sum(0)], axis=-1)


class LegFailureSchedule(Wrapper):
    """Training environments' leg failures: none before `start_after` control steps per environment,
    then at the configured rate, the leg drawn by `leg_probabilities` when `adaptive`."""

    def __init__(self, env, start_after: int = 0, adaptive: bool = False):
        super().__init__(env)
        self.start_after, self.adaptive = start_after, adaptive
        base = env.unwrapped
        self.walks = base.task.uses_command  # progress: metres walked along the commands, not goals
        self._walking = jax.vmap(lambda data: base.task.walking(data.qpos, data.qvel, base.command(data),
                                                                base.heading(data)))
        self.dt = base.dt
        config = base.config
        self.rate = config.leg_failure_rate
        legs = len(base.robot.legs)
        weights = np.asarray(config.leg_failure_weights or [1.0] * legs, np.float32)
        self.base_p = weights / weights.sum()

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        batch = rng.shape[:-1]
        legs = self.base_p.size
        state.info["failure_clock"] = jp.zeros(batch, jp.int32)
        state.info["leg_failure_rate"] = jp.full(batch, self.rate if self.start_after == 0 else 0.0, jp.float32)
        state.info["leg_failure_p"] = jp.broadcast_to(jp.asarray(self.base_p), batch + (legs,))
        # A prior of one episode with one unit of progress (a goal, a metre) in each condition: every
        # leg alike until episodes end.
        state.info["leg_failure_stats"] = jp.ones(batch + (legs + 1, 2), jp.float32)
        if self.walks:
            state.info["leg_failure_walked_m"] = jp.zeros(batch, jp.float32)
        if self.start_after:
            state.info["failed_legs"] = jp.zeros_like(state.info["failed_legs"])
        return state

    def step(self, state: State, action: jax.Array) -> State:
        before = state
        state = self.env.step(state, action)
        clock = state.info["failure_clock"] + 1
        ended = state.info["t"] == 0  # HexapodEnv zeroes its step count when an episode ends
        if self.walks:  # this step counted at the velocity it starts from: the state after may be a reset's
            _, along = self._walking(before.pipeline_state)
            progress = before.info["leg_failure_walked_m"] + along * self.dt
            state.info["leg_failure_walked_m"] = jp.where(ended, 0.0, progress)
        else:
            progress = before.info["goals"] + state.metrics["goals_reached"]
        stats = DECAY * state.info["leg_failure_stats"][0] + episode_stats(before.info["failed_legs"], progress, ended)
        p = leg_probabilities(stats) if self.adaptive else jp.asarray(self.base_p)
        rate = jp.where(clock[0] >= self.start_after, self.rate, 0.0)
        batch = clock.shape
        state.info.update(failure_clock=clock, leg_failure_rate=jp.full(batch, rate, jp.float32),
                          leg_failure_p=jp.broadcast_to(p, batch + p.shape),
                          leg_failure_stats=jp.broadcast_to(stats, batch + stats.shape))
        return state


def schedule_summary(info) -> dict:
    """{"leg_failure/rate", "leg_failure/p_leg<k>", "leg_failure/progress_intact",
    "leg_failure/progress_leg<k>"} from the training environments' `info`, laid out (devices,
    environments per device, ...): the current rate and leg probabilities, and progress per
    finished episode in each condition (goals reached, or metres walked along the commands)."""
    stats = np.asarray(info["leg_failure_stats"])[:, 0].sum(0)  # each device's batch, summed
    p = np.asarray(info["leg_failure_p"])[:, 0].mean(0)
    progress = stats[:, 0] / np.maximum(stats[:, 1], 1e-9)
    return {"leg_failure/rate": float(np.asarray(info["leg_failure_rate"])[:, 0].mean()),
            "leg_failure/progress_intact": float(progress[0]),
            **{f"leg_failure/progress_leg{k}": float(g) for k, g in enumerate(progress[1:], start=1)},
            **{f"leg_failure/p_leg{k}": float(q) for k, q in enumerate(p, start=1)}}
