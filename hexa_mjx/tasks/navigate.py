"""Navigation: random headings, goals in every direction at any range, chained, or a waypoint path.

The observation is in the robot's heading frame (x forward, y left, z up, turned by the torso's
yaw only), so a policy sees the same thing whichever way it faces (README, "Navigation task").
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from mujoco import mjx

from hexa_mjx.curriculum import range_fraction
from hexa_mjx.env import HexapodEnv
from hexa_mjx.kinematics import yaw
from hexa_mjx.observations import navigate_observation
from hexa_mjx.rewards import TASK_REWARDS

class NavigateEnv(HexapodEnv):
    """Goals at a uniform bearing and distance; on arrival the next one is drawn."""

    name = "navigate"
    rewards = TASK_REWARDS["navigate"]
    start_yaw_range = np.pi  # every episode starts from a heading uniform over 360 degrees

    def first_goal(self, qpos: jax.Array, rng: jax.Array, level=0) -> jax.Array:
        if self.config.waypoints:
            return self._waypoint(0)
        return self._draw_goal(qpos, rng, level)

    def goal_completed(self, reached: jax.Array, goals: jax.Array) -> jax.Array:
        if self.config.waypoints:  # the last waypoint, once reached, stays the goal
            return reached & (goals < len(self.config.waypoints))
        return reached

    def next_goal(self, data: mjx.Data, goals: jax.Array, rng: jax.Array, level=0) -> jax.Array:
        if self.config.waypoints:
            return self._waypoint(jp.minimum(goals, len(self.config.waypoints) - 1))
        return self._draw_goal(data.qpos, rng, level)

    def observe(self, data: mjx.Data) -> jax.Array:
        """67 values, heading frame (hexa_mjx.observations.layout)."""
        return navigate_observation(data.qpos, data.qvel, data.ctrl, self.goal(data), self.robot.ctrl_lo,
                                    self.robot.ctrl_hi, self.distance_cap)

    @property
    def distance_cap(self) -> float:
        """m, the largest goal distance the policy observes (the trained range's end by default)."""
        return self.config.goal_distance_cap or self.config.goal_max_distance

    def _draw_goal(self, qpos: jax.Array, rng: jax.Array, level) -> jax.Array:
        """A goal at a bearing from the torso's heading and a distance drawn over the ranges open at
        the curriculum's `level` (the full ranges without a curriculum)."""
        k_bearing, k_dist = jax.random.split(rng)
        open_share = range_fraction(level, self.config.curriculum_levels)
        bearing = yaw(qpos[3:7]) + open_share * jax.random.uniform(k_bearing, minval=-jp.pi, maxval=jp.pi)
        near, far = self.config.goal_min_distance, self.config.goal_max_distance
        dist = jax.random.uniform(k_dist, minval=near, maxval=near + open_share * (far - near))
        return qpos[:2] + dist * jp.stack([jp.cos(bearing), jp.sin(bearing)])

    def _waypoint(self, index) -> jax.Array:
        return self._start_xy + jp.asarray(self.config.waypoints, jp.float32)[index]
