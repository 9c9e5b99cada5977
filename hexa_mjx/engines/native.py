"""A task on native MuJoCo (C), with NumPy: no JAX anywhere on this path.

`NativeEnv` runs the same episode code as the MJX environment (`hexa_mjx.mdp.episode`: the task,
start noise, pushes, latency, failed servos, reward terms, termination and goal chaining). This
engine supplies only MuJoCo C's physics step, its contact arrays and NumPy's random draws. play.py
and the Gymnasium environments are built on it.

    env = NativeEnv(EnvConfig(task="navigate"))
    obs = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(action)
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from hexa_mjx.engines import terrain_contacts as terrain_contacts_
from hexa_mjx.mdp import events, randomization
from hexa_mjx.mdp.config import EnvConfig
from hexa_mjx.mdp.episode import Contacts, make_episode
from hexa_mjx.robot.kinematics import yaw
from hexa_mjx.robot.model import action_to_ctrl, servo_power


class NumpyDraws:
    """Random draws from a NumPy generator (the engine-neutral interface of `hexa_mjx.mdp.events`);
    keys are ignored: the generator's state is the key."""

    xp = np

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def split(self, key):
        return key, key

    def fold_in(self, key, data):
        return key

    def uniform(self, key, shape, minval, maxval):
        return self.rng.uniform(minval, maxval, shape)

    def randint(self, key, low, high):
        return int(self.rng.integers(low, high))

    def choice(self, key, n, p):
        p = np.asarray(p, float)
        return int(self.rng.choice(n, p=p / p.sum()))

    @staticmethod
    def select(cond, if_true, if_false):
        """`if_true()` if `cond`, else `if_false()`: only the one taken is computed (and draws)."""
        return if_true() if cond else if_false()


class NativeEnv:
    """One environment of a task on MuJoCo C; `observe_as` names another task's observation."""

    def __init__(self, config: EnvConfig = EnvConfig(), observe_as: str = "", ranges=None,
                 terrain_contacts: str = "all"):
        """`ranges` (hexa_mjx.mdp.randomization.Ranges): draw a randomized physics model every episode.
        `terrain_contacts`: "all" of MuJoCo C's heightfield contacts, or "mjx", made as MJX makes them
        (hexa_mjx.engines.terrain_contacts)."""
        if terrain_contacts not in terrain_contacts_.MODES:
            raise ValueError(f"terrain_contacts is one of {terrain_contacts_.MODES}, got {terrain_contacts!r}")
        self.terrain_contacts = terrain_contacts
        self.episode = make_episode(config, observe_as)
        self.config, self.robot, self.task = self.episode.config, self.episode.robot, self.episode.task
        self.observe_as = self.episode.observer.name
        self.scales, self.active = self.episode.scales, self.episode.active
        self.mj_model, self.n_substeps = self.robot.mj_model, self.robot.n_substeps
        self.qpos0 = self.robot.qpos0
        self.ranges, self.nominal = ranges, copy.copy(self.mj_model)
        self.data = mujoco.MjData(self.mj_model)
        self.rng = np.random.default_rng()
        self.info = self.episode.start_info(self.draws, None)

    @property
    def dt(self) -> float:
        """Control period, s."""
        return self.episode.dt

    @property
    def observation_size(self) -> int:
        return self.episode.observer.layout(self.mj_model.nu)[-1][1]

    @property
    def action_size(self) -> int:
        return self.mj_model.nu

    @property
    def start_yaw_range(self) -> float:
        """The start heading is turned uniformly in +-this, rad."""
        return self.task.start_yaw_range

    @property
    def goal(self) -> np.ndarray:
        """The current goal's (x, y), m, world frame: the `goal` mocap body, which the viewer can drag."""
        return self.data.mocap_pos[self.robot.goal_mocap, :2].copy()

    def set_goal(self, goal_xy) -> None:
        self.data.mocap_pos[self.robot.goal_mocap, :2] = goal_xy

    @property
    def heading(self) -> float:
        """The goal marker's heading, rad."""
        return float(yaw(self.data.mocap_quat[self.robot.goal_mocap]))

    def set_heading(self, heading: float) -> None:
        self.data.mocap_quat[self.robot.goal_mocap] = [np.cos(heading / 2), 0.0, 0.0, np.sin(heading / 2)]

    @property
    def command(self) -> np.ndarray:
        """The task's command (the model's userdata; hexa_mjx.tasks.velocity)."""
        return self.data.userdata.copy()

    def set_command(self, command, heading=None) -> None:
        """Set the task's command (and the heading it turns to in heading mode): play.py's
        keyboard and command schedules drive the velocity task with it."""
        self.data.userdata[:] = command
        if heading is not None:
            self.set_heading(float(heading))

    def goal_distance(self) -> float:
        return float(np.linalg.norm(self.goal - self.data.qpos[:2]))

    @property
    def draws(self) -> NumpyDraws:
        return NumpyDraws(self.rng)

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start an episode from the settled pose with this task's start noise; returns the observation."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        data, robot, draws = self.data, self.robot, self.draws
        if self.ranges is not None:  # this episode's physics, drawn as training draws each environment's
            variant = randomization.draw(self.nominal, int(self.rng.integers(2 ** 31 - 1)), self.ranges, robot.torso)
            for name, value in variant.items():
                getattr(self.mj_model, name)[:] = value
        mujoco.mj_resetData(self.mj_model, data)
        qpos = self.episode.start_qpos(robot.qpos0.copy(), draws, None)
        data.qpos[:], data.qvel[:], data.ctrl[:] = qpos, robot.qvel0, robot.ctrl0
        self.info = self.episode.start_info(draws, None)
        self.set_goal(self.task.first_goal(qpos, draws, None))
        if self.task.uses_heading:
            self.set_heading(self.task.goal_heading(qpos, draws, None))
        if self.task.uses_command:
            self.set_command(*self.task.first_command(qpos, draws, None))
        mujoco.mj_forward(self.mj_model, data)
        return self.observe()

    def observe(self) -> np.ndarray:
        """The policy's observation, with the configured noise."""
        d = self.data
        obs = self.episode.observe(d.qpos, d.qvel, d.ctrl, self.goal, self.heading, self.command, self.draws, None)
        return np.asarray(obs, np.float32)

    def contact_counts(self) -> tuple[int, int]:
        """(leg contacts while that foot is lifted, non-foot contacts) with the floor, now."""
        c = self.contacts()
        return self.robot.contact_counts(c.geom1, c.geom2, c.dist, c.foot_pos, self.config.lift_clearance)

    def foot_stance(self) -> np.ndarray:
        """Whether each foot touches the floor now, (legs,) bool."""
        c = self.data.contact
        return np.asarray(self.robot.foot_stance(c.geom1, c.geom2, c.dist))

    def servo_power(self) -> float:
        """The servos' mechanical power now, sum over joints of |torque x joint velocity|, W."""
        return float(servo_power(self.data.actuator_force, self.data.qvel, self.robot.actuator_dof))

    def contacts(self) -> Contacts:
        c = self.data.contact
        return Contacts(c.geom1, c.geom2, c.dist, self.data.geom_xpos[self.robot.feet])

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict]:
        """One control step: targets from `action` in [-1, 1], `n_substeps` physics steps.
        Returns (observation, reward, terminated (fell or diverged), truncated (time limit), info);
        info holds the unscaled terms ("terms"), the distance, success, goals reached and falls."""
        action = np.asarray(action, np.float64)
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},), got {action.shape}")
        model, data, episode, draws = self.mj_model, self.data, self.episode, self.draws
        prev_qpos, prev_qvel, previous = data.qpos.copy(), data.qvel.copy(), data.ctrl.copy()
        target = action_to_ctrl(np.nan_to_num(action), self.robot.ctrl_lo, self.robot.ctrl_hi)
        if self.config.push_speed:
            data.qvel[:2] += events.push_kick(self.info["t"], episode.push_every, self.config.push_speed, draws, None)
        failed, delay = episode.failed_servos(self.info), episode.delay(self.info)
        for i in range(self.n_substeps):
            data.ctrl[:] = episode.servo_ctrl(i, delay, target, previous, data.qpos, failed)
            if self.terrain_contacts == "mjx":
                terrain_contacts_.step(model, data, self.robot.floor)
            else:
                mujoco.mj_step(model, data)
        data.ctrl[:] = target  # the policy's own command, whatever failed or lagged
        finite = events.finite(data.qpos, data.qvel)
        if not finite:  # keep the last finite state and end the episode
            data.qpos[:], data.qvel[:] = prev_qpos, prev_qvel
            mujoco.mj_forward(model, data)
        self.info, terms, fig, target = episode.transition(self.info, prev_qpos, data.qpos, data.qvel, self.goal,
                                                            self.heading, self.command, self.contacts(),
                                                            data.actuator_force, np.bool_(finite), draws, None)
        self.set_goal(target["goal"])
        if self.task.uses_command:
            self.set_command(target["command"], target["heading"])
        reward = float(sum(episode.scaled(terms).values()))
        info = {"terms": {name: float(value) for name, value in terms.items()}, "distance": float(fig["distance"]), "success": bool(fig["success"]),
                "goals_reached": int(fig["goals"]), "fell": bool(fig["fell"]), "nonfinite": not finite,
                "feet_only": int(fig["non_foot"]) == 0}
        truncated = int(self.info["t"]) >= self.config.episode_length
        return self.observe(), reward, bool(fig["done"]), truncated, info

    def new_goal(self) -> np.ndarray:
        """A goal as the task draws the next one (the viewer's key for a new goal)."""
        return self.task.next_goal(self.data.qpos, self.goal, self.info["goals"], self.draws, None)
