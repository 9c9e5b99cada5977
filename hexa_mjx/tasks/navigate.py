"""Navigation: random headings, goals in every direction at any range, chained, or a waypoint path.

The observation is in the robot's heading frame (x forward, y left, z up, turned by the torso's
yaw only), so a policy sees the same thing whichever way it faces (docs/TASKS.md).
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.mdp import curriculum, observations, rewards
from hexa_mjx.robot.kinematics import namespace, yaw
from hexa_mjx.tasks.base import Task


class NavigateTask(Task):
    """Goals at a uniform bearing and distance; on arrival the next one is drawn."""

    name = "navigate"
    gym_id = "hexa_mjx/HexapodNavigate-v0"
    summary = "goals in every direction at 0.5 to 3 m, chained, or a waypoint path"
    # The report's goal terms toward the current goal, whose radius it leaves at once (so the
    # in-radius bonus is paid on the arrival step), plus a one-off bonus per goal reached. Body
    # contact weighs 10x the report's: walking at ~1 m/s earns ~27 per step, and at -1 a policy
    # kept its shins on the floor in 1.8% of steps (docs/RESULTS.md, navigation).
    rewards = {"navigate": {**rewards.GOAL_TERMS, "goal_reached": 400.0, **rewards.SHAPING, "body_contact": -10.0}}
    gait_window = "alive"  # the whole episode is walking
    follows_waypoints = True
    chains_goals = True
    targets = {"no fall": (">=", 98.0), "feet only": (">=", 99.0), "worst sector or band": (">=", 95.0)}

    @classmethod
    def check(cls, config) -> None:
        if config.curriculum_levels and config.waypoints:
            raise ValueError("curriculum_levels applies to the navigate task's random goals only; leave it at 0 "
                             "with waypoints")

    @property
    def start_yaw_range(self) -> float:
        return np.pi  # every episode starts from a heading uniform over 360 degrees

    @property
    def distance_cap(self) -> float:
        """m, the largest goal distance the policy observes (the trained range's end by default)."""
        return self.config.goal_distance_cap or self.config.goal_max_distance

    def first_goal(self, qpos, draws, key, level=0):
        if self.config.waypoints:
            return self._waypoint(qpos, 0)
        return self._draw_goal(qpos, draws, key, level)

    def goal_completed(self, reached, goals):
        return reached  # a waypoint path's last waypoint stays: hexa_mjx.mdp.episode caps the goals

    def next_goal(self, qpos, goal, goals, draws, key, level=0):
        if self.config.waypoints:
            return self._waypoint(qpos, namespace(qpos).minimum(goals, len(self.config.waypoints) - 1))
        return self._draw_goal(qpos, draws, key, level)

    def observe(self, qpos, qvel, ctrl, goal, heading, command):
        return observations.navigate_observation(qpos, qvel, ctrl, goal, self.robot.ctrl_lo, self.robot.ctrl_hi,
                                                 self.distance_cap)

    @classmethod
    def layout(cls, joints):
        return observations.slices([
            ("goal direction (x, y), heading frame, unit vector", "", 2),
            ("goal distance, capped at the trained range's end", "m", 1), ("torso height", "m", 1),
            *observations.proprioception_slices(joints)])

    def deployment_settings(self) -> dict:
        return {"goal_distance_cap": self.distance_cap}  # the policy keeps the cap it was trained with

    def _draw_goal(self, qpos, draws, key, level):
        """A goal at a bearing from the torso's heading and a distance drawn over the ranges open at
        the curriculum's `level` (the full ranges without a curriculum)."""
        xp = namespace(qpos)
        k_bearing, k_dist = draws.split(key)
        open_share = curriculum.range_fraction(level, self.config.curriculum_levels)
        bearing = yaw(qpos[3:7]) + open_share * draws.uniform(k_bearing, (), -np.pi, np.pi)
        near, far = self.config.goal_min_distance, self.config.goal_max_distance
        dist = draws.uniform(k_dist, (), near, near + open_share * (far - near))
        return qpos[:2] + dist * xp.stack([xp.cos(bearing), xp.sin(bearing)])

    def _waypoint(self, qpos, index):
        xp = namespace(qpos)
        return xp.asarray(self.robot.start_xy, xp.float32) + xp.asarray(self.config.waypoints, xp.float32)[index]

    # -- figures --------------------------------------------------------------

    @classmethod
    def progress_figure(cls, row: dict, scales: dict) -> str:
        return f"goals {row['goals_per_episode']:.2f}"

    @classmethod
    def selection_score(cls, row: dict, scales: dict) -> float:
        return row["goals_per_episode"] * (1.0 - row["fall_rate"])

    @classmethod
    def table_rows(cls, summary: dict) -> list[tuple[str, str]]:
        from hexa_mjx.evaluation import nav_metrics

        return nav_metrics.table_rows(summary)

    def evaluation_settings(self) -> dict:
        return {"goal_min_distance": self.config.goal_min_distance, "goal_max_distance": self.config.goal_max_distance,
                "waypoints": [list(p) for p in self.config.waypoints]}

    def evaluation(self, env, start_qpos, traj, alive, fell):
        from hexa_mjx.evaluation import nav_metrics  # evaluation-only figures

        args = (start_qpos, traj["qpos"], traj["goals_reached"], alive, np.asarray(fell))
        if self.config.waypoints:
            path = nav_metrics.waypoint_summary(*args, self.config.waypoints, env.dt)
            return {"waypoints": path}, {"waypoints": path.pop("per_episode")}
        records = nav_metrics.goals_of_episodes(start_qpos, traj["qpos"], traj["goal"], traj["goals_reached"],
                                                alive, fell, env.dt)
        summary = nav_metrics.navigation_summary(records, alive.shape[1], self.config.success_radius,
                                                 nav_metrics.body_length(env), self.config.goal_min_distance,
                                                 self.config.goal_max_distance)
        summary["falls"] = nav_metrics.fall_phases(records, fell, alive, self.config.success_radius, env.dt)
        return {"navigation": summary}, {"goals": records}

    def plot(self, env, start_qpos, traj, out):
        from hexa_mjx.evaluation import plots

        return plots.plot_tracks(env, start_qpos, traj, out / "paths.png")
