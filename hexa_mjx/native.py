"""The hexapod's tasks on native MuJoCo (C), with NumPy: no JAX anywhere on this path.

`NativeEnv` runs a task as the MJX environment does: the same settled start and start noise,
action-to-target mapping, control rate, observation (`hexa_mjx.observations`), reward terms and
scales (`hexa_mjx.rewards`), contact rules (`hexa_mjx.model`), termination and goal chaining.
Only the engine differs, and the random draws (NumPy's generator instead of JAX's keys).
play.py and the Gymnasium environments are built on it.

    env = NativeEnv(EnvConfig(task="navigate"))
    obs = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(action)
"""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np

from hexa_mjx import randomization, rewards
from hexa_mjx.env_config import EnvConfig, check_config, push_steps
from hexa_mjx.kinematics import fell, quat_mul
from hexa_mjx.model import RobotModel, action_to_ctrl, failed_ctrl, servo_power
from hexa_mjx.observations import TASKS, goal_observation, layout, navigate_observation, noise_scale


class NativeEnv:
    """One environment of a task on MuJoCo C; `observe_as` names another task's observation."""

    def __init__(self, config: EnvConfig = EnvConfig(), observe_as: str = "", ranges=None):
        """`ranges` (hexa_mjx.randomization.Ranges): draw a randomized physics model every episode."""
        if config.task not in TASKS:
            raise ValueError(f"unknown task {config.task!r}; choose one of {list(TASKS)}")
        if observe_as and observe_as not in TASKS:
            raise ValueError(f"unknown task {observe_as!r} to observe as; choose one of {list(TASKS)}")
        check_config(config)
        config = dataclasses.replace(config, reward=config.reward or rewards.TASK_REWARDS[config.task][0])
        if config.reward not in rewards.TASK_REWARDS[config.task]:
            raise ValueError(f"reward {config.reward!r} is not one of the {config.task} task's: "
                             f"{list(rewards.TASK_REWARDS[config.task])}")
        self.config, self.observe_as = config, observe_as or config.task
        self.scales = rewards.make_scales(config.reward, config.ablate, config.reward_scales)
        self.active = [name for name, scale in self.scales.items() if scale != 0.0]
        self.robot = RobotModel(config)
        self.mj_model, self.n_substeps = self.robot.mj_model, self.robot.n_substeps
        self.qpos0 = self.robot.qpos0
        self.ranges, self.nominal = ranges, copy.copy(self.mj_model)
        self.data = mujoco.MjData(self.mj_model)
        self.rng = np.random.default_rng()
        self.t = self.goals = 0
        self.success = False
        self.failed_legs = np.zeros(len(self.robot.legs))
        self.air_time = np.zeros(len(self.robot.legs))  # s since each foot last touched the floor
        self.stance_avg = np.ones(len(self.robot.legs))  # running share of time on the floor
        self.noise = config.obs_noise * noise_scale(self.observe_as, self.mj_model.nu)  # per observed value

    @property
    def dt(self) -> float:
        """Control period, s."""
        return self.n_substeps * float(self.mj_model.opt.timestep)

    @property
    def observation_size(self) -> int:
        return layout(self.observe_as, self.mj_model.nu)[-1][1]

    @property
    def action_size(self) -> int:
        return self.mj_model.nu

    @property
    def start_yaw_range(self) -> float:
        """rad; the navigation task turns every start uniformly over 360 degrees."""
        return np.pi if self.config.task == "navigate" else self.config.start_yaw_noise

    @property
    def goal(self) -> np.ndarray:
        """The current goal's (x, y), m, world frame: the `goal` mocap body, which the viewer can drag."""
        return self.data.mocap_pos[self.robot.goal_mocap, :2].copy()

    def set_goal(self, goal_xy) -> None:
        self.data.mocap_pos[self.robot.goal_mocap, :2] = goal_xy

    def goal_distance(self) -> float:
        return float(np.linalg.norm(self.goal - self.data.qpos[:2]))

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start an episode from the settled pose with this task's start noise; returns the observation."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        data, robot = self.data, self.robot
        if self.ranges is not None:  # this episode's physics, drawn as training draws each environment's
            variant = randomization.draw(self.nominal, int(self.rng.integers(2 ** 31 - 1)), self.ranges, robot.torso)
            for name, value in variant.items():
                getattr(self.mj_model, name)[:] = value
        mujoco.mj_resetData(self.mj_model, data)
        qpos = robot.qpos0.copy()
        noise = self.config.start_joint_noise
        if noise:
            qpos[7:] = np.clip(qpos[7:] + self.rng.uniform(-noise, noise, qpos[7:].shape), robot.joint_lo, robot.joint_hi)
        if self.start_yaw_range:
            half_yaw = 0.5 * self.rng.uniform(-1.0, 1.0) * self.start_yaw_range
            qpos[3:7] = quat_mul(np.array([np.cos(half_yaw), 0.0, 0.0, np.sin(half_yaw)]), qpos[3:7])
        data.qpos[:], data.qvel[:], data.ctrl[:] = qpos, robot.qvel0, robot.ctrl0
        self.t = self.goals = 0
        self.success = False
        self.failed_legs = self._draw_failure()
        self.air_time, self.stance_avg = np.zeros(len(self.robot.legs)), np.ones(len(self.robot.legs))
        self.latency = self.rng.uniform(0, self.config.action_latency)  # control steps
        self.set_goal(self._first_goal())
        mujoco.mj_forward(self.mj_model, data)
        return self.observe()

    def observe(self) -> np.ndarray:
        """The policy's observation, with the configured noise."""
        d = self.data
        if self.observe_as == "goal":
            obs = goal_observation(d.qpos, d.qvel, self.goal)
        else:
            cap = self.config.goal_distance_cap or self.config.goal_max_distance
            obs = navigate_observation(d.qpos, d.qvel, d.ctrl, self.goal, self.robot.ctrl_lo, self.robot.ctrl_hi, cap)
        if self.config.obs_noise:
            obs = obs + self.noise * self.rng.uniform(-1.0, 1.0, obs.shape)
        return obs.astype(np.float32)

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict]:
        """One control step: targets from `action` in [-1, 1], `n_substeps` physics steps.
        Returns (observation, reward, terminated (fell or diverged), truncated (time limit), info);
        info holds the unscaled terms ("terms"), the distance, success, goals reached and falls."""
        action = np.asarray(action, np.float64)
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},), got {action.shape}")
        model, data = self.mj_model, self.data
        prev_qpos, prev_qvel = data.qpos.copy(), data.qvel.copy()
        target = action_to_ctrl(np.nan_to_num(action), self.robot.ctrl_lo, self.robot.ctrl_hi)
        every = push_steps(self.config, self.dt)
        if self.config.push_speed and self.t > 0 and self.t % every == 0:  # as HexapodEnv.push_kick
            angle, speed = self.rng.uniform(-np.pi, np.pi), self.rng.uniform(0, self.config.push_speed)
            data.qvel[:2] += speed * np.array([np.cos(angle), np.sin(angle)])
        failed = self.failed_legs[self.robot.actuator_leg] > 0
        delay, previous = round(self.latency * self.n_substeps), data.ctrl.copy()
        for i in range(self.n_substeps):
            data.ctrl[:] = previous if i < delay else target  # as HexapodEnv.step: latency, then failures
            if failed.any():  # failed servos, re-targeted at every physics step
                data.ctrl[:] = failed_ctrl(data.ctrl.copy(), data.qpos[self.robot.actuator_qpos], failed,
                                           self.config.failure_mode, self.robot.hold_ctrl)
            mujoco.mj_step(model, data)
        data.ctrl[:] = target  # the policy's own command, whatever failed
        finite = bool(np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all())
        if not finite:  # as in MJX: keep the last finite state and end the episode
            data.qpos[:], data.qvel[:] = prev_qpos, prev_qvel
            mujoco.mj_forward(model, data)
        fallen = bool(fell(data.qpos[3:7]))
        done = fallen or not finite
        goal = self.goal
        dist = float(np.linalg.norm(goal - data.qpos[:2]))
        reached = dist < self.config.success_radius
        completed = self._goal_completed(reached)
        bad, non_foot = self.contact_counts()
        c = data.contact
        stance = self.robot.foot_stance(c.geom1, c.geom2, c.dist)
        self.air_time = np.where(stance, 0.0, self.air_time + self.dt)
        self.stance_avg = rewards.running_stance(self.stance_avg, stance, self.dt)
        power = servo_power(data.actuator_force, data.qvel, self.robot.actuator_dof)
        terms = rewards.terms(self.active, self.config, prev_qpos, data.qpos, data.qvel, goal, bad, non_foot,
                              np.bool_(done), np.bool_(completed), power, ground=self.robot.ground(data.qpos[:2]),
                              air_time=self.air_time, working=1.0 - self.failed_legs, stance_avg=self.stance_avg)
        reward = float(sum(self.scales[name] * value for name, value in terms.items()))
        self.t += 1
        if completed:
            self.goals += 1
            self.set_goal(self._next_goal())
        self.success |= reached
        info = {"terms": {name: float(v) for name, v in terms.items()}, "distance": dist, "success": self.success,
                "goals_reached": self.goals, "fell": fallen, "nonfinite": not finite, "feet_only": int(non_foot) == 0}
        return self.observe(), reward, done, self.t >= self.config.episode_length, info

    def new_goal(self) -> np.ndarray:
        """A goal as the task draws them: the report's fixed goal, the next waypoint, or a random one."""
        if self.config.task == "goal":
            return self._first_goal()
        return self._next_goal()

    def contact_counts(self) -> tuple[int, int]:
        """(leg contacts while that foot is lifted, non-foot contacts) with the floor, now."""
        c, feet = self.data.contact, self.robot.feet
        return self.robot.contact_counts(c.geom1, c.geom2, c.dist, self.data.geom_xpos[feet],
                                         self.config.lift_clearance)

    def _draw_failure(self) -> np.ndarray:
        """This episode's failed legs (0/1 per leg), as HexapodEnv.draw_failure draws them."""
        mask = np.zeros(len(self.robot.legs))
        if self.config.leg_failure == "random":
            weights = np.asarray(self.config.leg_failure_weights, float)
            if weights.size:
                leg = self.rng.choice(len(mask), p=weights / weights.sum())
            else:
                leg = self.rng.integers(len(mask))
            mask[leg] = float(self.rng.uniform() < self.config.leg_failure_rate)
        else:
            mask[np.asarray(self.config.disabled_legs, int) - 1] = 1.0
        return mask

    # -- goals, as the task modules in hexa_mjx.tasks draw them ------------------

    def _first_goal(self) -> np.ndarray:
        if self.config.task == "goal":
            return self.robot.start_xy + np.array([self.config.goal_distance, 0.0])
        if self.config.waypoints:
            return self.robot.start_xy + np.asarray(self.config.waypoints[0], float)
        return self._draw_goal()

    def _goal_completed(self, reached: bool) -> bool:
        if self.config.task == "goal":
            return False
        return reached and (not self.config.waypoints or self.goals < len(self.config.waypoints))

    def _next_goal(self) -> np.ndarray:
        if self.config.waypoints:
            last = min(self.goals, len(self.config.waypoints) - 1)
            return self.robot.start_xy + np.asarray(self.config.waypoints[last], float)
        return self._draw_goal()

    def _draw_goal(self) -> np.ndarray:
        bearing = self.rng.uniform(-np.pi, np.pi)
        dist = self.rng.uniform(self.config.goal_min_distance, self.config.goal_max_distance)
        return self.data.qpos[:2] + dist * np.array([np.cos(bearing), np.sin(bearing)])
