"""Velocity commands: walk at a commanded planar velocity and yaw rate, or stand still.

Each episode starts from a heading uniform over 360 degrees. A command (vx, vy, yaw rate), in the
heading frame (x forward, y left; yaw counter-clockwise), is drawn from the configured ranges
(EnvConfig.command_vx, command_vy, command_yaw_rate) and held for `command_interval` seconds. Each
command is of one class (CLASSES): a share `command_zero_share` are exactly zero (stand still), the
rest are pure forward, backward or sideways walking, turning on the spot, diagonal walking, or all
three at once in equal shares, each uniform in its ranges. A share
`command_heading_share` are in heading mode (legged_gym's): a heading to turn to, held in the goal
marker's orientation, whose yaw-rate command is HEADING_GAIN times the heading error, clipped to the
yaw-rate range. The command is physics state: the model's userdata holds
(vx, vy, yaw rate, heading mode).

Reward: the field's tracking terms, exp(-error^2 / sigma) for the planar velocity and the yaw rate
(legged_gym's and Playground's form and weights; each term's width its own setting, as Isaac Lab
has), plus the report's contact-aware shaping.
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.mdp import curriculum, observations, rewards
from hexa_mjx.mdp.config import EnvConfig
from hexa_mjx.robot.kinematics import namespace, rotate, to_heading_frame, yaw
from hexa_mjx.tasks.base import Task

# The terrain curriculum (level_moves): the share of the commanded planar path an episode walks
# to go up a level, and below which it goes down one (legged_gym's: half the commanded distance).
# The shipped velocity policy walks 0.93 to 0.99 of it on flat ground, by command class
# (docs/RESULTS.md, "The shipped velocity policy: the recipe's seed 2").
LEVEL_UP = 0.5
LEVEL_DOWN = 0.25
TRACKING_SIGMA = EnvConfig.tracking_sigma  # (m/s)^2 and (rad/s)^2: the default width, legged_gym's and Playground's
HEADING_GAIN = 1.0  # 1/s: heading mode's yaw-rate command per rad of heading error
# Command classes, drawn in equal shares but for "zero" (command_zero_share): pure forward,
# backward and sideways walking, turning on the spot, diagonal walking, and all three at once.
CLASSES = ("zero", "forward", "backward", "sideways", "turn", "diagonal", "walk and turn")
COMMAND_FIELDS = (("vx", "m/s", "forward velocity, heading frame"), ("vy", "m/s", "leftward velocity, heading frame"),
                  ("yaw_rate", "rad/s", "yaw rate, counter-clockwise positive"))


def planar_velocity(qpos, qvel):
    """The torso's planar velocity in the heading frame (forward, left), m/s."""
    return to_heading_frame(qvel[:2], yaw(qpos[3:7]))


def yaw_rate(qpos, qvel):
    """The torso's angular velocity about the world's z axis, rad/s (the free joint's is body-frame)."""
    return rotate(qvel[3:6], qpos[3:7])[2]


def tracking_lin_vel(prev_qpos, qpos, qvel, goal, heading, command, sigma=TRACKING_SIGMA):
    """exp(-|v_cmd - v|^2 / sigma) of the planar velocity, heading frame: 1 on the command."""
    xp = namespace(qpos)
    error = command[:2] - planar_velocity(qpos, qvel)
    return xp.exp(-(error @ error) / sigma)


def tracking_ang_vel(prev_qpos, qpos, qvel, goal, heading, command, sigma=TRACKING_SIGMA):
    """exp(-(w_cmd - w)^2 / sigma) of the yaw rate: 1 on the command."""
    return namespace(qpos).exp(-((command[2] - yaw_rate(qpos, qvel)) ** 2) / sigma)


class VelocityTask(Task):
    """Track (vx, vy, yaw rate) commands, resampled on an interval, some of them zero."""

    name = "velocity"
    gym_id = "hexa_mjx/HexapodVelocity-v0"
    summary = "follow velocity commands (vx, vy, yaw rate), resampled every few seconds, or stand still"
    terms = {"tracking_lin_vel": tracking_lin_vel, "tracking_ang_vel": tracking_ang_vel}
    # legged_gym's 2:1 weighting of the tracking terms, at 10x its scale: the report's shaping
    # terms are far larger than legged_gym's penalties, and at 1 and 0.5 their step-to-step noise
    # drowned the gain of a first slow step, so the policy stood still (docs/RESULTS.md, "Velocity
    # commands").
    rewards = {"velocity": {"tracking_lin_vel": 10.0, "tracking_ang_vel": 5.0, **rewards.SHAPING}}
    gait_window = "alive"
    uses_command = True
    has_goal = False
    targets = {"planar RMS error": ("<=", 0.10), "yaw-rate RMS error": ("<=", 0.25),
               "drift told to stand": ("<=", 0.05), "no fall": (">=", 98.0), "feet only": (">=", 99.0)}

    @classmethod
    def check(cls, config) -> None:
        pass  # curriculum_levels grade the terrain, or on flat ground the commands (command_share)

    def command_share(self, level):
        """The share of each command range open at curriculum `level`: on flat ground with
        curriculum_levels N, (level + 1) / N (legged_gym's command curriculum, on this task's
        walking rule); None (the full ranges, the draw left untouched) on a terrain, whose levels
        grade the ground, and without a curriculum."""
        cfg = self.config
        if not cfg.curriculum_levels or cfg.terrain != "flat":
            return None
        return curriculum.range_fraction(level, cfg.curriculum_levels)

    def level_moves(self, completed, over, fell, goals, walking, command):
        """legged_gym's rule on distances: up for an episode that ran its full length and walked at
        least LEVEL_UP of the commanded planar path, down for a fall or less than LEVEL_DOWN of it
        (standing still walks none). Lasting alone is no test: promoted for it, a policy learnt
        to stand on the hardest ground (docs/RESULTS.md, "One policy for all of it")."""
        walked, asked = walking["walked_m"], walking["asked_m"]
        return over & ~fell & (walked >= LEVEL_UP * asked), over & (fell | (walked < LEVEL_DOWN * asked))

    def walking(self, qpos, qvel, command, heading):
        """(m/s asked for, m/s walked along it): the commanded planar speed and the torso's velocity
        projected on the commanded direction (sway back and forth cancels out)."""
        xp = namespace(qpos)
        wanted = self.commanded(command, qpos, heading)[:2]
        speed = xp.linalg.norm(wanted)
        return speed, (wanted @ planar_velocity(qpos, qvel)) / xp.maximum(speed, 1e-6)

    @property
    def start_yaw_range(self) -> float:
        return np.pi

    @property
    def interval_steps(self) -> int:
        """Control steps each command holds."""
        return max(1, round(self.config.command_interval * self.config.ctrl_hz))

    def first_goal(self, qpos, draws, key, level=0):
        return qpos[:2]  # no goal: the marker stays at the start (the path follower moves it)

    def reached(self, dist, qpos, heading, command):
        return namespace(dist).zeros((), bool)  # no goal to reach: eval.py reports tracking instead

    def first_command(self, qpos, draws, key):
        return self.draw_command(draws, key)

    def next_command(self, t, command, heading, draws, key, level=0):
        return draws.select(t % self.interval_steps == 0, lambda: self.draw_command(draws, key, level),
                            lambda: (command, heading))

    def draw_command(self, draws, key, level=0):
        """A command of a class drawn with `command_zero_share` for "zero" and the rest shared
        equally (CLASSES), in the configured ranges (their `command_share` at a curriculum
        `level`), and its heading (heading mode)."""
        cfg, xp = self.config, draws.xp
        k = [draws.fold_in(key, i) for i in range(6)]
        share = (1.0 - cfg.command_zero_share) / (len(CLASSES) - 1)
        c = draws.choice(k[0], len(CLASSES), xp.asarray([cfg.command_zero_share] + [share] * (len(CLASSES) - 1)))
        u = [draws.uniform(k[i + 1], (), 0.0, 1.0) for i in range(3)]
        xlo, xhi = cfg.command_vx
        full = [lo + ui * (hi - lo) for ui, (lo, hi) in zip(u, (cfg.command_vx, cfg.command_vy, cfg.command_yaw_rate))]
        is_ = lambda *names: sum((c == CLASSES.index(n)) * 1.0 for n in names)  # noqa: E731
        vx = (is_("forward") * u[0] * max(xhi, 0.0) + is_("backward") * u[0] * min(xlo, 0.0)
              + is_("diagonal", "walk and turn") * full[0])
        vy = is_("sideways", "diagonal", "walk and turn") * full[1]
        wz = is_("turn", "walk and turn") * full[2]
        open_share = self.command_share(level)
        if open_share is not None:  # the ranges narrowed about zero: each component scaled alike
            vx, vy, wz = vx * open_share, vy * open_share, wz * open_share
        mode = (draws.uniform(k[4], (), 0.0, 1.0) < cfg.command_heading_share) * (1.0 - is_("zero"))
        heading = draws.uniform(k[5], (), -np.pi, np.pi)
        return xp.stack([vx, vy, wz * (1.0 - mode), mode]).astype(xp.float32), heading

    def commanded(self, command, qpos, heading):
        """The (vx, vy, yaw rate) the policy is asked for: in heading mode the yaw rate turns the
        torso toward the commanded heading."""
        xp = namespace(qpos)
        diff = heading - yaw(qpos[3:7])
        turn = xp.clip(HEADING_GAIN * xp.arctan2(xp.sin(diff), xp.cos(diff)), *self.config.command_yaw_rate)
        return xp.stack([command[0], command[1], xp.where(command[3] > 0.5, turn, command[2])])

    @staticmethod
    def measured(qpos, qvel):
        """The torso's (vx, vy, yaw rate) in the command's frame and units."""
        xp = namespace(qpos)
        return xp.concatenate([planar_velocity(qpos, qvel), yaw_rate(qpos, qvel)[None]])

    def widths(self) -> dict:
        """Each tracking term's width sigma: (m/s)^2 for the planar velocity, (rad/s)^2 for the yaw rate."""
        cfg = self.config
        return {"tracking_lin_vel": cfg.tracking_sigma, "tracking_ang_vel": cfg.yaw_tracking_sigma or cfg.tracking_sigma}

    def reward_terms(self, names, prev_qpos, qpos, qvel, goal, heading, command) -> dict:
        commanded, sigma = self.commanded(command, qpos, heading), self.widths()
        return {name: self.terms[name](prev_qpos, qpos, qvel, goal, heading, commanded, sigma[name])
                for name in names if name in self.terms}

    def observe(self, qpos, qvel, ctrl, goal, heading, command):
        xp = namespace(qpos)
        return xp.concatenate([self.commanded(command, qpos, heading).astype(qpos.dtype), qpos[2:3],
                               observations.proprioception(qpos, qvel, ctrl, self.robot.ctrl_lo, self.robot.ctrl_hi)])

    @classmethod
    def layout(cls, joints):
        return observations.slices([
            ("command (vx, vy, yaw rate), heading frame", "m/s, m/s, rad/s", 3), ("torso height", "m", 1),
            *observations.proprioception_slices(joints)])

    def command_fields(self) -> list[dict]:
        """The command's fields, units and trained ranges (the ONNX metadata's "command")."""
        cfg = self.config
        return [{"name": name, "units": units, "what": what, "range": list(bounds), "observation_index": i}
                for i, ((name, units, what), bounds) in
                enumerate(zip(COMMAND_FIELDS, (cfg.command_vx, cfg.command_vy, cfg.command_yaw_rate)))]

    @property
    def command_ranges(self) -> tuple:
        """((min, max) of vx, vy, yaw rate): what commands from outside are clipped to."""
        return self.config.command_vx, self.config.command_vy, self.config.command_yaw_rate

    def evaluation_settings(self) -> dict:
        cfg = self.config
        return {"command_vx": list(cfg.command_vx), "command_vy": list(cfg.command_vy),
                "command_yaw_rate": list(cfg.command_yaw_rate), "command_interval": cfg.command_interval,
                "command_zero_share": cfg.command_zero_share}

    # -- figures --------------------------------------------------------------

    @staticmethod
    def tracking(row: dict, scales: dict) -> tuple[float, float]:
        """The planar and yaw-rate tracking terms' mean per step (1: on the command) of an evaluation row."""
        steps = row.get("episode_length") or np.nan  # the row's terms are scaled: divided back
        lin = row.get("eval/episode_reward/tracking_lin_vel", np.nan) / scales["tracking_lin_vel"] / steps
        ang = row.get("eval/episode_reward/tracking_ang_vel", np.nan) / scales["tracking_ang_vel"] / steps
        return lin, ang

    @classmethod
    def progress_figure(cls, row: dict, scales: dict) -> str:
        lin, ang = cls.tracking(row, scales)
        return f"tracking v {lin:.2f} yaw {ang:.2f}"

    @classmethod
    def selection_score(cls, row: dict, scales: dict) -> float:
        lin, ang = cls.tracking(row, scales)
        return (lin + ang) / 2 * (1.0 - row["fall_rate"])

    def evaluation(self, env, start_qpos, traj, alive, fell):
        from hexa_mjx.evaluation import tracking  # evaluation-only figures

        summary, per_episode = tracking.tracking_summary(self, env.dt, traj, alive, fell)
        return {"tracking": summary}, {"tracking": per_episode}

    @classmethod
    def table_rows(cls, summary: dict) -> list[tuple[str, str]]:
        from hexa_mjx.evaluation import tracking

        return tracking.table_rows(summary)

    def plot(self, env, start_qpos, traj, out):
        from hexa_mjx.evaluation import tracking

        return tracking.plot_tracking(self, env.dt, traj, out / "tracking.png")
