"""The report's task: walk to one goal `goal_distance` ahead (+x) of the start, world-frame observation."""

from __future__ import annotations

import jax
import jax.numpy as jp
from mujoco import mjx

from hexa_mjx.env import HexapodEnv, rotate


class GoalEnv(HexapodEnv):
    """One goal on +x; the report's 52-D observation (README, "Observation")."""

    name = "goal"
    rewards = ("goal_directed", "forward_motion")

    def first_goal(self, qpos: jax.Array, rng: jax.Array) -> jax.Array:
        return self._start_xy + jp.array([self.config.goal_distance, 0.0])

    def observe(self, data: mjx.Data) -> jax.Array:
        """Torso position and quaternion, world-frame linear and angular velocity, joint angles and
        velocities, goal vector and distance: 3 + 4 + 3 + 3 + 18 + 18 + 2 + 1 = 52."""
        goal_vec = self.goal(data) - data.qpos[:2]
        angvel_world = rotate(data.qvel[3:6], data.qpos[3:7])  # free-joint angular velocity is body-frame
        return jp.concatenate([data.qpos[:3], data.qpos[3:7], data.qvel[:3], angvel_world,
                               data.qpos[7:], data.qvel[6:], goal_vec, jp.linalg.norm(goal_vec)[None]])
