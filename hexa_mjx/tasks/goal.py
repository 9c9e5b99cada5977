"""The report's task: walk to one goal `goal_distance` ahead (+x) of the start; world-frame observation."""

from __future__ import annotations

from hexa_mjx.mdp import observations, rewards
from hexa_mjx.robot.kinematics import namespace
from hexa_mjx.tasks.base import Task


class GoalTask(Task):
    """One goal on +x; the report's 52-value observation."""

    name = "goal"
    gym_id = "hexa_mjx/HexapodGoal-v0"
    summary = "the report's task: one goal 1.5 m ahead"
    rewards = {
        # Report section 3.2: approach the goal.
        "goal_directed": {**rewards.GOAL_TERMS, **rewards.SHAPING},
        # Report section 4.2 baseline: move along +x, no goal bonus.
        "forward_motion": {**{k: 0.0 for k in rewards.GOAL_TERMS}, "forward_progress": 1000.0,
                           "forward_velocity": 5.0, **rewards.SHAPING},
        # In the spirit of Fu et al. (CoRL 2021): the report's goal terms and the fall penalty, plus the
        # servos' mechanical power, and none of the hand-made gait shaping (posture, height, contacts).
        # 0.01 per W: the report policy's ~450 W of jittery stepping would cost about half its approach reward.
        "energy": {**rewards.GOAL_TERMS, "mechanical_power": -0.01, "stability": 0.0, "height": 0.0, "energy": 0.0,
                   "contact_quality": 0.0, "body_contact": 0.0, "termination": -200.0},
    }

    def first_goal(self, qpos, draws, key, level=0):
        xp = namespace(qpos)
        return xp.asarray(self.robot.start_xy, xp.float32) + xp.array([self.config.goal_distance, 0.0])

    def observe(self, qpos, qvel, ctrl, goal, heading, command):
        return observations.goal_observation(qpos, qvel, goal)

    @classmethod
    def layout(cls, joints):
        return observations.slices([
            ("torso position, world", "m", 3), ("torso quaternion (w, x, y, z), world", "", 4),
            ("torso linear velocity, world", "m/s", 3), ("torso angular velocity, world", "rad/s", 3),
            *observations.joint_slices(joints), ("goal minus torso (x, y), world", "m", 2), ("goal distance", "m", 1)])
