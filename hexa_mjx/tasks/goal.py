"""The report's task: walk to one goal `goal_distance` ahead (+x) of the start, world-frame observation."""

from __future__ import annotations

import jax
import jax.numpy as jp
from mujoco import mjx

from hexa_mjx.env import HexapodEnv
from hexa_mjx.observations import goal_observation
from hexa_mjx.rewards import TASK_REWARDS


class GoalEnv(HexapodEnv):
    """One goal on +x; the report's 52-D observation (hexa_mjx.observations.layout)."""

    name = "goal"
    rewards = TASK_REWARDS["goal"]

    def first_goal(self, qpos: jax.Array, rng: jax.Array, level=0) -> jax.Array:
        return self._start_xy + jp.array([self.config.goal_distance, 0.0])

    def observe(self, data: mjx.Data) -> jax.Array:
        return goal_observation(data.qpos, data.qvel, self.goal(data))
