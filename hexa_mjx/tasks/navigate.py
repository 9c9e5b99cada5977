"""Navigation: random headings, goals in every direction at any range, chained, or a waypoint path.

The observation is in the robot's heading frame (x forward, y left, z up, turned by the torso's
yaw only), so a policy sees the same thing whichever way it faces (README, "Navigation task").
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from mujoco import mjx

from hexa_mjx.env import HexapodEnv, rotate, yaw

GRAVITY_WORLD = np.array([0.0, 0.0, -1.0], np.float32)  # unit vector (NumPy: importing must not start JAX)


def to_heading_frame(vec_xy: jax.Array, heading: jax.Array) -> jax.Array:
    """A world-frame planar vector in the frame turned by `heading` (rad) about z."""
    c, s = jp.cos(heading), jp.sin(heading)
    return jp.stack([c * vec_xy[0] + s * vec_xy[1], -s * vec_xy[0] + c * vec_xy[1]])


class NavigateEnv(HexapodEnv):
    """Goals at a uniform bearing and distance; on arrival the next one is drawn."""

    name = "navigate"
    rewards = ("navigate",)
    start_yaw_range = np.pi  # every episode starts from a heading uniform over 360 degrees

    def first_goal(self, qpos: jax.Array, rng: jax.Array) -> jax.Array:
        if self.config.waypoints:
            return self._waypoint(0)
        return self._draw_goal(qpos[:2], rng)

    def goal_completed(self, reached: jax.Array, goals: jax.Array) -> jax.Array:
        if self.config.waypoints:  # the last waypoint, once reached, stays the goal
            return reached & (goals < len(self.config.waypoints))
        return reached

    def next_goal(self, data: mjx.Data, goals: jax.Array, rng: jax.Array) -> jax.Array:
        if self.config.waypoints:
            return self._waypoint(jp.minimum(goals, len(self.config.waypoints) - 1))
        return self._draw_goal(data.qpos[:2], rng)

    def observe(self, data: mjx.Data) -> jax.Array:
        """67 values, heading frame; the layout and units are in the README ("Navigation task")."""
        quat = data.qpos[3:7]
        heading = yaw(quat)
        goal_vec = to_heading_frame(self.goal(data) - data.qpos[:2], heading)
        dist = jp.linalg.norm(goal_vec)
        # Beyond the training range the distance reads as the range's end, so a farther goal looks
        # like the farthest goal trained on and the policy walks toward it until it is in range.
        seen = jp.minimum(dist, self.config.goal_distance_cap or self.config.goal_max_distance)
        conj = quat * jp.array([1.0, -1.0, -1.0, -1.0])
        last_action = 2.0 * (data.ctrl - self._ctrl_lo) / (self._ctrl_hi - self._ctrl_lo) - 1.0
        return jp.concatenate([
            goal_vec / jp.maximum(dist, 1e-6), seen[None],         # 0:2 direction, 2 distance (m)
            data.qpos[2:3],                                         # 3 torso height (m)
            to_heading_frame(data.qvel[:2], heading), data.qvel[2:3],  # 4:7 linear velocity (m/s)
            data.qvel[3:6],                                         # 7:10 angular velocity, body frame (rad/s)
            rotate(GRAVITY_WORLD, conj),                            # 10:13 gravity direction, body frame
            data.qpos[7:], data.qvel[6:],                           # 13:31 joint angles (rad), 31:49 (rad/s)
            last_action,                                            # 49:67 previous action
        ])

    def _draw_goal(self, xy: jax.Array, rng: jax.Array) -> jax.Array:
        k_bearing, k_dist = jax.random.split(rng)
        bearing = jax.random.uniform(k_bearing, minval=-jp.pi, maxval=jp.pi)
        dist = jax.random.uniform(k_dist, minval=self.config.goal_min_distance, maxval=self.config.goal_max_distance)
        return xy + dist * jp.stack([jp.cos(bearing), jp.sin(bearing)])

    def _waypoint(self, index) -> jax.Array:
        return self._start_xy + jp.asarray(self.config.waypoints, jp.float32)[index]
