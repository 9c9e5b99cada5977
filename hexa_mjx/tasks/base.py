"""The task interface: everything that differs between tasks, engine-neutral.

A task is one module in `hexa_mjx.tasks` with one `Task` subclass, listed in the registry
(`hexa_mjx.tasks.TASKS`). Its methods take NumPy or JAX arrays and random `draws` from either
engine, so the MJX environment, native MuJoCo, Gymnasium, play.py and export all run the same code.

The goal is the model's `goal` mocap body: its (x, y) is where the task sends the robot, and its
heading (yaw, rad) what a task may ask the torso to face. A task's command (the velocity task's
(vx, vy, yaw rate, heading mode)) is the model's `userdata`. All three are part of the physics
state, so auto-resets restore them, trajectories carry them and videos draw them.
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.mdp import observations
from hexa_mjx.robot.kinematics import namespace


class Task:
    """A task's defaults: one goal that is never replaced, the configured start heading noise."""

    name = ""  # the key in hexa_mjx.tasks.TASKS
    gym_id = ""  # its Gymnasium id, "hexa_mjx/...-v0"
    summary = ""  # one line for --help and the tasks table
    # Reward variants: name -> scales table of hexa_mjx.mdp.rewards terms (and the task's own
    # `terms`); the first is the task's default.
    rewards: dict[str, dict[str, float]] = {}
    terms: dict = {}  # the task's own reward terms: name -> fn(prev_qpos, qpos, qvel, goal, heading, command)
    gait_window = "to_goal"  # eval.py's gait analysis reads the walk to the first goal, or "alive" steps
    uses_heading = False  # whether the goal marker's heading is part of the task
    follows_waypoints = False  # whether EnvConfig.waypoints set its goals
    chains_goals = False  # whether a reached goal is replaced by a new one (EnvConfig.goal_stay_share applies)
    uses_command = False  # whether the task draws commands (the model's userdata)
    has_goal = True  # whether the goal is a place to reach (distance and success figures mean something)
    # What a seed of the task's recipe must reach in eval.py's 256 episodes (its issue's targets):
    # a figure of hexa_mjx.studies.seed_summary -> (">=" or "<=", bound in that figure's unit).
    targets: dict[str, tuple[str, float]] = {}

    def __init__(self, config, robot):
        self.config, self.robot = config, robot

    @classmethod
    def check(cls, config) -> None:
        """Raise ValueError for settings this task cannot run (before anything is built)."""
        if config.curriculum_levels:
            raise ValueError(f"curriculum_levels grades the navigate task's random goals and the velocity task's "
                             f"terrain or commands; the {cls.name} task has none: leave it at 0")

    # -- the episode ----------------------------------------------------------

    @property
    def start_yaw_range(self) -> float:
        """The start heading is turned uniformly in +-this, rad."""
        return self.config.start_yaw_noise

    def first_goal(self, qpos, draws, key, level=0):
        """The goal (x, y), m, of an episode starting at `qpos`, at the curriculum's `level`."""
        raise NotImplementedError

    def goal_heading(self, qpos, draws, key):
        """The heading (rad) the goal marker asks for, for tasks with `uses_heading`."""
        return None

    def reached(self, dist, qpos, heading, command):
        """Whether the torso is where the task asks (`dist`: m from the goal): within `success_radius`."""
        return dist < self.config.success_radius

    def goal_completed(self, reached, goals):
        """Whether this step completes a goal, given that the torso is within the radius (`reached`)
        and `goals` were completed earlier in the episode. Default: goals are never replaced."""
        return namespace(reached).zeros((), bool)

    def level_moves(self, completed, over, fell, goals, walking, command):
        """(up, down) of the curriculum's level after a step (hexa_mjx.mdp.curriculum): up for a goal
        completed, down for an episode that ended in a fall (`fell`) or without a goal. `walking`:
        the episode's {"asked_m", "walked_m"} so far, for tasks with `uses_command` (`walking`);
        `command`: this step's command (the model's userdata)."""
        return completed, over & (fell | (goals == 0))

    def walking(self, qpos, qvel, command, heading):
        """(m/s asked for, m/s walked along it) this step: what a curriculum over commands sums."""
        raise NotImplementedError(f"the {self.name} task has no commands to walk")

    def next_goal(self, qpos, goal, goals, draws, key, level=0):
        """The goal that follows `goals` completed ones, from the state that completed the last."""
        return goal

    def first_command(self, qpos, draws, key):
        """(command, heading) of a new episode, for tasks with `uses_command`."""
        return None, None

    def next_command(self, t, command, heading, draws, key, level=0):
        """(command, heading) after control step `t` of the episode: a task with `uses_command`
        replaces them on its schedule (`level`: the environment's curriculum level)."""
        return command, heading

    def mask_terms(self, terms: dict, command) -> dict:
        """The reward terms that count this step under `command`: all of them, but for a task with
        modes (the drive task zeroes the other mode's terms)."""
        return terms

    def reward_terms(self, names, prev_qpos, qpos, qvel, goal, heading, command) -> dict:
        """Unscaled values of the task's own terms among `names`."""
        return {name: self.terms[name](prev_qpos, qpos, qvel, goal, heading, command)
                for name in names if name in self.terms}

    # -- what the policy sees -------------------------------------------------

    def observe(self, qpos, qvel, ctrl, goal, heading, command):
        """The policy's observation of a physics state (`command`: the userdata)."""
        raise NotImplementedError

    @classmethod
    def layout(cls, joints: int) -> list[tuple[int, int, str, str]]:
        """(start, end, what, units) of every slice of the observation, on a robot with `joints` joints."""
        raise NotImplementedError

    def noise_scale(self) -> np.ndarray:
        """Per-value half-width of observation noise at obs_noise=1."""
        return observations.noise_scale(self.layout(len(self.robot.ctrl_lo)))

    def deployment_settings(self) -> dict:
        """Settings the exported policy must run with that the config leaves implicit."""
        return {}

    # -- figures --------------------------------------------------------------

    @classmethod
    def paid_scales(cls, scales: dict, config) -> dict:
        """The weight each term is paid at where it is paid, for reading a run's rows: `scales`,
        but for a task that weighs some steps' terms again (the drive task's command_mode_gain)."""
        return scales

    @classmethod
    def progress_figure(cls, row: dict, scales: dict) -> str:
        """The task's figure on the progress line, from an evaluation row of a run trained with
        reward `scales`."""
        return f"goal bonus {row['goal_bonus']:7.1f}"

    @classmethod
    def selection_score(cls, row: dict, scales: dict) -> float:
        """How good an evaluation row is, higher better: what `RUN/best` picks a checkpoint by
        (hexa_mjx.training.selection). Here the share of episodes ended at the goal, less falls."""
        return row["success_rate"] - row["fall_rate"]

    def evaluation(self, env, start_qpos, traj, alive, fell) -> tuple[dict, dict]:
        """The task's own figures for eval.py: (summary entries, per-episode entries). A per-episode
        entry is a dict of them, a list with one value per episode, or a list of records each
        naming its episode's index under "episode" (the drive task renumbers each mode's)."""
        return {}, {}

    @classmethod
    def table_rows(cls, summary: dict) -> list[tuple[str, str]]:
        """eval.py's table rows of the task's own figures."""
        return []

    def evaluation_settings(self) -> dict:
        """The task's settings eval.py records with its figures."""
        return {}

    def plot(self, env, start_qpos, traj, out):
        """A plot of the rollout for eval.py (a path), or None."""
        return None
