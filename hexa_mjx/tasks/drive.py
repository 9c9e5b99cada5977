"""Drive: one policy for velocity commands and for goals, each episode in one of the two modes.

A share `goal_mode_share` of the episodes are in goal mode: the navigate task's goals (every
bearing, chained; or a waypoint path, which is always walked in goal mode), its reward terms and
its success figures. The rest are in command mode: the velocity task's commands, tracking terms
and figures. The mode is physics state like the command: the userdata's last value (the velocity
task's heading-mode flag) is GOAL_MODE in goal mode, so play.py's keyboard and the path follower,
which write (vx, vy, yaw rate, 0), drive a drive policy in command mode.

The observation is the navigate task's with the mode appended (1 in goal mode, 0 in command
mode), and its first three values hold what the mode asks for: the goal's direction and distance
in goal mode, the commanded (vx, vy, yaw rate) in command mode, where the velocity task holds it.
Both tasks' policies thus start a drive run (`--init_from`): their first layer gains zero weights
on the mode (hexa_mjx.training.warm_start). A navigation policy starts command mode where the
velocity recipe starts its whole training, reading the command where it read the goal; a first
design that appended the command after zeroed goal slots left it as unused as a policy trained
from scratch (docs/RESULTS.md, "The drive task").
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.mdp import rewards
from hexa_mjx.robot.kinematics import namespace
from hexa_mjx.tasks.base import Task
from hexa_mjx.tasks.navigate import NavigateTask
from hexa_mjx.tasks.velocity import VelocityTask

GOAL_MODE = 2.0  # the userdata's last value in goal mode (the velocity task's heading mode is 1)
LEAD = 3  # the observation's first values: the goal's direction (2) and distance (1), or the command
GOAL_TERMS = frozenset(rewards.GOAL_TERMS)  # paid in goal mode only
COMMAND_TERMS = frozenset(VelocityTask.terms)  # paid in command mode only
# What the checkpoint choice weighs goals by: 10 goals per episode, about the shipped navigation
# policy's rate, count as much as tracking every command perfectly.
GOALS_PER_TRACKING = 10.0


def in_goal_mode(command):
    """Whether a command (the userdata) puts the drive task in goal mode."""
    return command[..., 3] > (GOAL_MODE + 1.0) / 2


class DriveTask(VelocityTask):
    """Velocity commands or goals, drawn per episode; one observation for both."""

    name = "drive"
    gym_id = "hexa_mjx/HexapodDrive-v0"
    summary = "velocity commands or navigation goals, one policy: each episode in one mode"
    # The velocity task's terms and the navigate task's, whose body-contact weight is the larger.
    rewards = {"drive": {**VelocityTask.rewards["velocity"], **NavigateTask.rewards["navigate"]}}
    gait_window = "alive"
    follows_waypoints = True
    chains_goals = True
    has_goal = True
    targets = {**VelocityTask.targets, **NavigateTask.targets}

    def __init__(self, config, robot):
        super().__init__(config, robot)
        self.navigation = NavigateTask(config, robot)  # goal mode's goals, observation and figures

    @classmethod
    def check(cls, config) -> None:
        NavigateTask.check(config)

    # -- the episode ----------------------------------------------------------

    def first_goal(self, qpos, draws, key, level=0):
        return self.navigation.first_goal(qpos, draws, key, level)

    def next_goal(self, qpos, goal, goals, draws, key, level=0):
        return self.navigation.next_goal(qpos, goal, goals, draws, key, level)

    def reached(self, dist, qpos, heading, command):
        return (dist < self.config.success_radius) & in_goal_mode(command)

    def goal_completed(self, reached, goals):
        return reached  # as the navigate task: the next goal follows, a path's last one stays

    def first_command(self, qpos, draws, key):
        command, heading = self.draw_command(draws, key)
        goal_mode = bool(self.config.waypoints) or draws.uniform(draws.fold_in(key, 7), (), 0.0, 1.0) < \
            self.config.goal_mode_share
        xp = draws.xp
        return xp.where(goal_mode, xp.asarray([0.0, 0.0, 0.0, GOAL_MODE], xp.float32), command), heading

    def next_command(self, t, command, heading, draws, key, level=0):
        return draws.select(in_goal_mode(command), lambda: (command, heading),
                            lambda: super(DriveTask, self).next_command(t, command, heading, draws, key, level))

    def commanded(self, command, qpos, heading):
        """The (vx, vy, yaw rate) asked for: the velocity task's in command mode, zero in goal mode."""
        return namespace(qpos).where(in_goal_mode(command), 0.0, super().commanded(command, qpos, heading))

    def level_moves(self, completed, over, fell, goals, walking, command):
        """The navigate task's rule in goal mode (up for a goal), the velocity task's in command mode."""
        xp = namespace(over)
        goal_mode = in_goal_mode(command)
        by_goals = Task.level_moves(self, completed, over, fell, goals, walking, command)
        by_walking = super().level_moves(completed, over, fell, goals, walking, command)
        return tuple(xp.where(goal_mode, g, w) for g, w in zip(by_goals, by_walking))

    def mask_terms(self, terms: dict, command) -> dict:
        """Each mode's own terms and the shared ones; a command-mode step's all times
        `command_mode_gain`. The goal terms' spread is larger (a bonus per goal, progress at walking
        speed): at gain 1 the goal steps' advantages spread 1.8 to 2.6x as wide as the command
        steps', and PPO normalizes them over one batch (docs/RESULTS.md, "What holds the command
        mode back")."""
        goal_mode = in_goal_mode(command)
        xp = namespace(goal_mode)
        goal = goal_mode.astype(xp.float32)
        gain = (1.0 - goal) * self.config.command_mode_gain
        return {name: value * (goal if name in GOAL_TERMS else gain if name in COMMAND_TERMS else goal + gain)
                for name, value in terms.items()}

    # -- what the policy sees -------------------------------------------------

    def observe(self, qpos, qvel, ctrl, goal, heading, command):
        xp = namespace(qpos)
        seen = self.navigation.observe(qpos, qvel, ctrl, goal, heading, command)
        goal_mode = in_goal_mode(command)
        lead = xp.where(goal_mode, seen[:LEAD], self.commanded(command, qpos, heading).astype(seen.dtype))
        return xp.concatenate([lead, seen[LEAD:], goal_mode.astype(seen.dtype)[None]])

    @classmethod
    def layout(cls, joints):
        (_, _, direction, _), (_, _, distance, _), *rest = NavigateTask.layout(joints)
        end = rest[-1][1]
        return [(0, 2, f"goal mode: {direction}; command mode: the command's (vx, vy), heading frame", "- or m/s"),
                (2, 3, f"goal mode: {distance}; command mode: the command's yaw rate", "m or rad/s"),
                *rest, (end, end + 1, "mode: 1 in goal mode, 0 in command mode", "-")]

    def deployment_settings(self) -> dict:
        return self.navigation.deployment_settings()

    # -- figures --------------------------------------------------------------

    @classmethod
    def progress_figure(cls, row: dict, scales: dict) -> str:
        return f"{NavigateTask.progress_figure(row, scales)}  {VelocityTask.progress_figure(row, scales)}"

    @classmethod
    def paid_scales(cls, scales: dict, config) -> dict:
        """The command terms are paid in command mode alone, at their scale times command_mode_gain."""
        return {name: value * config.command_mode_gain if name in COMMAND_TERMS else value
                for name, value in scales.items()}

    @classmethod
    def selection_score(cls, row: dict, scales: dict) -> float:
        """Tracking over every step (goal-mode steps count 0) plus goals per episode over
        GOALS_PER_TRACKING, less the falls' share."""
        lin, ang = cls.tracking(row, scales)
        return ((lin + ang) / 2 + row["goals_per_episode"] / GOALS_PER_TRACKING) * (1.0 - row["fall_rate"])

    def evaluation(self, env, start_qpos, traj, alive, fell):
        """Each mode's figures over its own episodes: the navigate task's and the velocity task's."""
        goal_mode = np.asarray(in_goal_mode(traj["command"][0]))  # each episode's mode, from its first step
        summary = {"modes": {"goal": int(goal_mode.sum()), "command": int((~goal_mode).sum())}}
        per_episode = {"goal_mode": goal_mode.tolist()}
        for mode, evaluate in ((goal_mode, self.navigation.evaluation),
                               (~goal_mode, lambda *a: VelocityTask.evaluation(self, *a))):
            idx = np.flatnonzero(mode)
            if not len(idx):
                continue
            part = evaluate(env, start_qpos[idx], {k: v[:, idx] for k, v in traj.items()}, alive[:, idx],
                            np.asarray(fell)[idx])
            summary.update(part[0])
            whole = len(idx) == len(goal_mode)  # every episode in this mode: their numbers are the evaluation's
            per_episode.update({name: value if whole else _reindexed(value, idx) for name, value in part[1].items()})
        return summary, per_episode

    @classmethod
    def table_rows(cls, summary: dict) -> list[tuple[str, str]]:
        modes = summary.get("modes", {})
        rows = [("episodes in goal mode, command mode", f"{modes.get('goal', 0)}, {modes.get('command', 0)}")]
        if "navigation" in summary or "waypoints" in summary:
            rows += NavigateTask.table_rows(summary)
        return rows + (VelocityTask.table_rows(summary) if "tracking" in summary else [])

    def evaluation_settings(self) -> dict:
        return {**self.navigation.evaluation_settings(), **super().evaluation_settings(),
                "goal_mode_share": self.config.goal_mode_share}

    def plot(self, env, start_qpos, traj, out):
        return self.navigation.plot(env, start_qpos, traj, out)


def _reindexed(value, idx):
    """A mode's per-episode entry (`Task.evaluation`'s forms) with its episodes numbered as in the
    whole evaluation: records by their "episode", a list of one value per episode as
    {episode index: value}."""
    if isinstance(value, dict):
        return {k: _reindexed(v, idx) for k, v in value.items()}
    if isinstance(value, list) and all(isinstance(r, dict) and "episode" in r for r in value):
        return [{**record, "episode": int(idx[record["episode"]])} for record in value]
    if isinstance(value, list) and len(value) == len(idx):
        return {int(i): v for i, v in zip(idx, value)}
    raise ValueError(f"a per-episode entry is a list of {len(idx)} values or of records naming their episode; "
                     f"got a {type(value).__name__}" + (f" of {len(value)}" if isinstance(value, list) else ""))
