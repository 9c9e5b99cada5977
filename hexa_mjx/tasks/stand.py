"""Stand: hold the start spot and turn on it to face a given heading.

Each episode starts from a heading uniform over 360 degrees and asks for another, drawn the same
way, shown as the goal marker's orientation. The observation is in the heading frame, as the
navigation task's: where the spot is, how far the torso is turned from the asked heading, and the
proprioception. Success: at some step within `success_radius` of the spot and within
HEADING_TOLERANCE of the heading. The module is also the example of how to add a task (docs/TASKS.md).
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.mdp import observations, rewards
from hexa_mjx.robot.kinematics import namespace, to_heading_frame, yaw
from hexa_mjx.tasks.base import Task

HEADING_TOLERANCE = 0.2  # rad (about 11 degrees): facing the asked heading
SPOT_SIGMA = 0.01  # m^2: the spot term is 1/e at 0.1 m from the spot
HEADING_SIGMA = 0.25  # rad^2: the field's tracking width (exp(-error^2 / 0.25))


def heading_error(qpos, heading):
    """The torso's yaw minus the asked heading, wrapped to [-pi, pi], rad."""
    xp = namespace(qpos)
    diff = yaw(qpos[3:7]) - heading
    return xp.arctan2(xp.sin(diff), xp.cos(diff))


def spot_tracking(prev_qpos, qpos, qvel, goal, heading, command):
    """exp(-d^2 / SPOT_SIGMA) of the torso's planar distance d (m) from the spot: 1 on it."""
    xp = namespace(qpos)
    offset = goal - qpos[:2]
    return xp.exp(-(offset @ offset) / SPOT_SIGMA)


def heading_tracking(prev_qpos, qpos, qvel, goal, heading, command):
    """exp(-e^2 / HEADING_SIGMA) of the heading error e (rad): 1 facing the asked heading."""
    return namespace(qpos).exp(-heading_error(qpos, heading) ** 2 / HEADING_SIGMA)


class StandTask(Task):
    """Stay on the start spot, turned to the goal marker's heading."""

    name = "stand"
    gym_id = "hexa_mjx/HexapodStand-v0"
    summary = "hold the start spot and turn on it to a given heading"
    terms = {"spot_tracking": spot_tracking, "heading_tracking": heading_tracking}
    rewards = {"stand": {"spot_tracking": 2.0, "heading_tracking": 2.0, **rewards.SHAPING}}
    gait_window = "alive"
    uses_heading = True

    @property
    def start_yaw_range(self) -> float:
        return np.pi

    def first_goal(self, qpos, draws, key, level=0):
        return qpos[:2]

    def goal_heading(self, qpos, draws, key):
        return draws.uniform(key, (), -np.pi, np.pi)

    def reached(self, dist, qpos, heading, command):
        return (dist < self.config.success_radius) & (abs(heading_error(qpos, heading)) < HEADING_TOLERANCE)

    def observe(self, qpos, qvel, ctrl, goal, heading, command):
        xp = namespace(qpos)
        error = heading_error(qpos, heading)
        return xp.concatenate([to_heading_frame(goal - qpos[:2], yaw(qpos[3:7])), xp.stack([xp.cos(error),
                               xp.sin(error)]), qpos[2:3],
                               observations.proprioception(qpos, qvel, ctrl, self.robot.ctrl_lo, self.robot.ctrl_hi)])

    @classmethod
    def layout(cls, joints):
        return observations.slices([
            ("spot minus torso (x, y), heading frame", "m", 2),
            ("heading error (cos, sin), torso yaw minus the asked heading", "", 2), ("torso height", "m", 1),
            *observations.proprioception_slices(joints)])

    @classmethod
    def progress_figure(cls, row: dict, scales: dict) -> str:
        return f"heading and spot held {row['success_rate']:.0%}"
