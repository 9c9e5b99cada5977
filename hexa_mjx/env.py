"""The hexapod's physics, contacts and shaping terms: the base every task builds on.

A task (`hexa_mjx.tasks`) subclasses `HexapodEnv` and defines only what differs: where goals
go, what the policy observes, and its own reward terms. Everything here is pure JAX, jit- and
vmap-able, behind brax's `Env` interface:

    env = make_env(task="navigate")
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    state = jax.jit(env.step)(state, jp.zeros(env.action_size))

The current goal is the position of the model's `goal` mocap body, so it is part of the physics
state (`pipeline_state.mocap_pos`): auto-resets restore it with the rest of the state, a recorded
trajectory carries it, and the video draws it where it was. Episode bookkeeping that must not leak
across an automatic reset lives in `state.info` and is reset by `step` itself on the last step of
an episode (brax's AutoResetWrapper restores only `pipeline_state` and `obs`).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import functools
import io

import jax
import jax.numpy as jp
import mujoco

# mujoco.mjx (brax imports it too) prints a notice on import when the optional GPU-only warp
# backend is absent.
with contextlib.redirect_stdout(io.StringIO()):
    from brax.envs.base import Env, State
    from mujoco import mjx

from hexa_mjx import curriculum, rewards, terrain as terrains  # noqa: E402
from hexa_mjx.env_config import EnvConfig, check_config, push_steps  # noqa: E402
from hexa_mjx.kinematics import fell as flipped, quat_mul  # noqa: E402
from hexa_mjx.model import RobotModel, action_to_ctrl, failed_ctrl, servo_power  # noqa: E402
from hexa_mjx.observations import noise_scale  # noqa: E402

__all__ = ["EnvConfig", "HexapodEnv", "floor_contacts"]


def floor_contacts(data: mjx.Data, normals: bool = False):
    """(geom1, geom2, dist) of MJX's contact arrays (JAX implementation only), and with `normals`
    the contacts' world-frame normals (n, 3) as well."""
    contact = data._impl.contact
    found = contact.geom1, contact.geom2, contact.dist
    return (*found, contact.frame[..., 0, :]) if normals else found


class HexapodEnv(Env):
    """The robot on a floor with a goal marker; a task subclass adds goals, observation and terms."""

    name = ""  # the task's name in hexa_mjx.tasks.TASKS
    observe_task = property(lambda self: self.name)  # the task whose observation `observe` computes
    rewards: tuple[str, ...] = ()  # the task's reward variants, its default first

    def __init__(self, config: EnvConfig = EnvConfig()):
        config = dataclasses.replace(config, task=self.name, reward=config.reward or self.rewards[0])
        check_config(config)
        if config.reward not in rewards.VARIANTS:
            raise ValueError(f"unknown reward {config.reward!r}; the {self.name} task's are {list(self.rewards)}")
        if config.reward not in self.rewards:
            raise ValueError(f"reward {config.reward!r} is not one of the {self.name} task's: {list(self.rewards)}")
        self.config = config
        self.scales = rewards.make_scales(config.reward, config.ablate, config.reward_scales)
        self.robot = RobotModel(config)  # MuJoCo C: legs, feet, control range, the settled start
        self.mj_model, self.n_substeps = self.robot.mj_model, self.robot.n_substeps
        self.feet, self.geom_leg = self.robot.feet, self.robot.geom_leg
        self.qpos0, self.qvel0 = self.robot.qpos0, self.robot.qvel0
        self._qpos0, self._qvel0, self._ctrl0 = (jp.asarray(x, jp.float32) for x in
                                                 (self.robot.qpos0, self.robot.qvel0, self.robot.ctrl0))
        self._start_xy = jp.asarray(self.robot.start_xy, jp.float32)
        self._put_physics(self.mj_model)
        if self.config.max_contact_points > self.contact_slots:  # a cap above the slots would cap nothing
            raise ValueError(f"max_contact_points {self.config.max_contact_points} is above the model's "
                             f"{self.contact_slots} robot-floor contact slots; use 1 to {self.contact_slots}, or 0 for all")

    def _put_physics(self, mj_model: mujoco.MjModel) -> None:
        # MJX's default device is jax.devices()[0], which only process 0 of a multi-process run can address.
        device = jax.local_devices()[0]
        self.mjx_model = mjx.put_model(mj_model, impl="jax", device=device)
        self._data0 = mjx.make_data(self.mjx_model, impl="jax", device=device)

    def with_physics(self, mj_model: mujoco.MjModel) -> "HexapodEnv":
        """A copy of this env whose physics runs `mj_model` instead (same robot and sizes; for
        example with an option flag changed)."""
        other = copy.copy(self)
        other.mj_model = mj_model
        other._put_physics(mj_model)
        return other

    def data_at(self, qpos: jax.Array) -> mjx.Data:
        """Physics data at joint positions `qpos`, at rest, with kinematics and contacts computed."""
        return mjx.forward(self.mjx_model, self._data0.replace(qpos=qpos))

    # -- brax Env interface -------------------------------------------------

    @functools.cached_property
    def observation_size(self) -> int:
        return int(jax.eval_shape(self.observe, self._data0).shape[0])  # traced once, not per call

    @property
    def action_size(self) -> int:
        return self.mj_model.nu

    @property
    def backend(self) -> str:
        return "mjx"

    @property
    def dt(self) -> float:
        """Control period, s."""
        return self.n_substeps * float(self.mj_model.opt.timestep)

    @property
    def fresh_starts(self) -> bool:
        """Whether episodes start from random states (training must redraw them at every reset)."""
        return bool(self.config.start_joint_noise or self.start_yaw_range)

    @property
    def start_yaw_range(self) -> float:
        """The start heading is turned uniformly in +-this, rad."""
        return self.config.start_yaw_noise

    def reset(self, rng: jax.Array) -> State:
        """Start an episode from the settled standing pose, perturbed by the start noise."""
        data = mjx.forward(self.mjx_model, self.restart(self._data0, rng))
        zero = jp.zeros(())
        metrics = {f"reward/{name}": zero for name in self._active_terms()}
        metrics.update(distance=self.goal_distance(data), success=zero, fell=zero, nonfinite=zero, goal_bonus=zero,
                       goals_reached=zero, final_distance=zero, final_success=zero)
        info = {"rng": rng, "t": jp.zeros((), jp.int32), "success": zero, "goals": jp.zeros((), jp.int32),
                "level": jp.zeros((), jp.int32),  # the curriculum's level (hexa_mjx.curriculum), kept across episodes
                "failed_legs": self.draw_failure(jax.random.fold_in(rng, 3)),
                "air_time": jp.zeros(len(self.robot.legs)),  # s since each foot last touched the floor
                "stance_avg": jp.ones(len(self.robot.legs)),  # running share of time on the floor (all down)
                "latency": self.draw_latency(jax.random.fold_in(rng, 4))}
        return State(data, self.noisy(self.observe(data), jax.random.fold_in(rng, 5)), zero, zero, metrics, info)

    def step(self, state: State, action: jax.Array) -> State:
        """Apply one control step: position targets from `action` in [-1, 1], `n_substeps` physics steps."""
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},) per environment, got {action.shape}; "
                             "batch environments with jax.vmap")
        prev = state.pipeline_state
        target = action_to_ctrl(action, self.robot.ctrl_lo, self.robot.ctrl_hi)
        data = prev.replace(ctrl=target)
        if self.config.push_speed:  # a kick to the torso's planar velocity, every push_interval
            kick = self.push_kick(state.info["t"], jax.random.fold_in(state.info["rng"], 7))
            data = data.replace(qvel=data.qvel.at[:2].add(kick))
        failed = state.info["failed_legs"][self.robot.actuator_leg] > 0
        delay = jp.round(state.info["latency"] * self.n_substeps)  # physics steps of the old command

        def physics_step(d, i):
            ctrl = target
            if self.config.action_latency:
                ctrl = jp.where(i < delay, prev.ctrl, ctrl)
            if self.leg_failures:  # failed servos, re-targeted at every physics step
                ctrl = failed_ctrl(ctrl, d.qpos[self.robot.actuator_qpos], failed, self.config.failure_mode,
                                   self.robot.hold_ctrl)
            return mjx.step(self.mjx_model, d.replace(ctrl=ctrl)), None

        data, _ = jax.lax.scan(physics_step, data, jp.arange(self.n_substeps))
        data = data.replace(ctrl=target)  # the policy's own command, whatever failed or lagged

        # A diverged physics state never reaches the learner: keep the last finite one and end the episode.
        finite = jp.isfinite(data.qpos).all() & jp.isfinite(data.qvel).all()
        data = jax.tree.map(lambda new, old: jp.where(finite, new, old), data, prev)
        data = data.replace(qpos=jp.where(jp.isfinite(data.qpos), data.qpos, self._qpos0),
                            qvel=jp.where(jp.isfinite(data.qvel), data.qvel, 0.0))

        fell = flipped(data.qpos[3:7])
        done = fell | ~finite
        # Every term sees the goal of this step; a goal reached now is replaced only afterwards, so
        # the step that draws a new goal pays no spurious approach reward or penalty.
        dist = self.goal_distance(data)
        reached = dist < self.config.success_radius
        completed = self.goal_completed(reached, state.info["goals"])
        stance = self.foot_stance(data)
        air_time = jp.where(stance, 0.0, state.info["air_time"] + self.dt)
        stance_avg = rewards.running_stance(state.info["stance_avg"], stance, self.dt)
        scaled = {name: self.scales[name] * value for name, value in self.reward_terms(
            prev, data, done, completed, air_time, state.info["failed_legs"], stance_avg).items()}
        reward = sum(scaled.values())

        t = state.info["t"] + 1
        over = done | (t >= self.config.episode_length)
        rng, key = jax.random.split(state.info["rng"])
        goals = state.info["goals"] + completed
        level = state.info["level"]
        if self.config.curriculum_levels:
            level = curriculum.next_level(level, self.config.curriculum_levels, completed, over, done | (goals == 0))
        data = self.set_goal(data, jp.where(completed, self.next_goal(data, goals, key, level), self.goal(data)))
        success = jp.maximum(state.info["success"], reached.astype(jp.float32))
        info = {**state.info, "rng": rng, "t": jp.where(over, 0, t), "success": jp.where(over, 0.0, success),
                "goals": jp.where(over, 0, goals), "level": level,
                "failed_legs": jp.where(over, self.draw_failure(jax.random.fold_in(key, 3),
                                                                state.info.get("leg_failure_rate"),
                                                                state.info.get("leg_failure_p")),
                                        state.info["failed_legs"]),
                "air_time": jp.where(over, 0.0, air_time),
                "stance_avg": jp.where(over, 1.0, stance_avg),
                "latency": jp.where(over, self.draw_latency(jax.random.fold_in(key, 4)), state.info["latency"])}
        # Start from the incoming metrics: wrappers (brax's evaluator) add keys of their own.
        metrics = {**state.metrics, **{f"reward/{name}": value for name, value in scaled.items()}}
        # Per-step values whose sums over an episode are the per-episode figures brax's evaluator reports.
        metrics.update(distance=dist, success=success, fell=fell.astype(jp.float32),
                       nonfinite=(~finite).astype(jp.float32), goals_reached=completed.astype(jp.float32),
                       goal_bonus=rewards.VARIANTS["goal_directed"]["goal_bonus"] * rewards.goal_bonus(
                           dist, self.config.success_radius),
                       final_distance=jp.where(over, dist, 0.0), final_success=jp.where(over, success, 0.0))
        return state.replace(pipeline_state=data, obs=self.noisy(self.observe(data), jax.random.fold_in(key, 5)),
                             reward=reward, done=done.astype(jp.float32), metrics=metrics, info=info)

    def draw_latency(self, rng: jax.Array) -> jax.Array:
        """An episode's action latency, control steps, uniform in [0, action_latency]."""
        return jax.random.uniform(rng, maxval=self.config.action_latency)

    def noisy(self, obs: jax.Array, rng: jax.Array) -> jax.Array:
        """`obs` with the configured observation noise (none at obs_noise=0)."""
        if not self.config.obs_noise:
            return obs
        scale = self.config.obs_noise * noise_scale(self.observe_task, self.action_size)
        return obs + scale * jax.random.uniform(rng, obs.shape, minval=-1.0, maxval=1.0)

    def push_kick(self, t: jax.Array, rng: jax.Array) -> jax.Array:
        """The planar velocity kick (m/s) at episode step `t`: nonzero every `push_interval` s."""
        every = push_steps(self.config, self.dt)
        k_angle, k_speed = jax.random.split(rng)
        angle = jax.random.uniform(k_angle, minval=-jp.pi, maxval=jp.pi)
        speed = jax.random.uniform(k_speed, maxval=self.config.push_speed)
        return jp.where((t > 0) & (t % every == 0), speed, 0.0) * jp.stack([jp.cos(angle), jp.sin(angle)])

    @property
    def leg_failures(self) -> bool:
        """Whether any leg can fail (fixed disabled legs or random failures)."""
        return bool(self.config.disabled_legs) or self.config.leg_failure == "random"

    def draw_failure(self, rng: jax.Array, rate=None, p=None) -> jax.Array:
        """An episode's failed legs, (legs,) of 0/1: the fixed `disabled_legs`, or one leg drawn
        (uniformly, or by `leg_failure_weights`) with probability `leg_failure_rate`. Drawn at reset
        and on an episode's last step (so brax's auto-reset, which keeps `info`, starts the next
        episode with a new draw). A training schedule (`hexa_mjx.failure_schedule`) passes its own
        `rate` and leg probabilities `p`."""
        legs = len(self.robot.legs)
        if self.config.leg_failure != "random":
            return jp.zeros(legs).at[jp.asarray(self.config.disabled_legs, jp.int32) - 1].set(1.0)
        k_which, k_whether = jax.random.split(rng)
        fails = jax.random.uniform(k_whether) < (self.config.leg_failure_rate if rate is None else rate)
        if p is not None:
            leg = jax.random.choice(k_which, legs, p=p)
        elif self.config.leg_failure_weights:
            leg = jax.random.choice(k_which, legs, p=jp.asarray(self.config.leg_failure_weights, jp.float32))
        else:
            leg = jax.random.randint(k_which, (), 0, legs)
        return jax.nn.one_hot(leg, legs) * fails

    def restart(self, data: mjx.Data, rng: jax.Array, level=0) -> mjx.Data:
        """`data` with a fresh start state (qpos, qvel, ctrl, time) and first goal drawn with `rng`
        (at the curriculum's `level`).

        Quantities derived from the state (positions, contacts) are left as they are: the next
        `mjx.step` recomputes them from qpos and qvel, and the observation needs only those.
        """
        qpos = self._qpos0
        if self.config.start_joint_noise or self.start_yaw_range:
            k_joint, k_yaw = jax.random.split(rng)
            noise = self.config.start_joint_noise
            joints = qpos[7:] + jax.random.uniform(k_joint, qpos[7:].shape, minval=-noise, maxval=noise)
            half_yaw = 0.5 * jax.random.uniform(k_yaw, minval=-1.0, maxval=1.0) * self.start_yaw_range
            quat = quat_mul(jp.array([jp.cos(half_yaw), 0.0, 0.0, jp.sin(half_yaw)]), qpos[3:7])
            qpos = jp.concatenate([qpos[:3], quat, jp.clip(joints, self.robot.joint_lo, self.robot.joint_hi)])
        if self.robot.terrain is not None and self.config.curriculum_levels:
            qpos = qpos.at[:2].add(self.level_spawn(level, jax.random.fold_in(rng, 6)))
        data = data.replace(qpos=qpos, qvel=self._qvel0, ctrl=self._ctrl0, time=jp.zeros_like(data.time))
        return self.set_goal(data, self.first_goal(qpos, jax.random.fold_in(rng, 2), level))

    def level_spawn(self, level, rng: jax.Array) -> jax.Array:
        """Offset (m) of a start at the curriculum's `level` on a terrain: the centre of a random
        square in the level's column (hexa_mjx.terrain)."""
        centres = jp.asarray(terrains.spawn_points(), jp.float32)
        return jp.stack([centres[level], centres[jax.random.randint(rng, (), 0, len(centres))]])

    def goal(self, data: mjx.Data) -> jax.Array:
        """The current goal's (x, y), m, world frame."""
        return data.mocap_pos[self.robot.goal_mocap, :2]

    def set_goal(self, data: mjx.Data, goal_xy: jax.Array) -> mjx.Data:
        return data.replace(mocap_pos=data.mocap_pos.at[self.robot.goal_mocap, :2].set(goal_xy))

    def goal_distance(self, data: mjx.Data) -> jax.Array:
        """Planar distance from the torso origin to the current goal, m."""
        return jp.linalg.norm(self.goal(data) - data.qpos[:2])

    @property
    def contact_slots(self) -> int:
        """Contact points MJX solves for at every physics step (all robot-floor slots, or the cap)."""
        return int(floor_contacts(self._data0)[2].shape[0])

    def floor_contact_geoms(self, data: mjx.Data):
        """(active robot-floor contact mask, the robot geom of each contact) over MJX's contact slots."""
        return self.robot.floor_contact_geoms(*floor_contacts(data))

    def foot_stance(self, data: mjx.Data) -> jax.Array:
        """Whether each foot touches the floor, (legs,) bool."""
        return self.robot.foot_stance(*floor_contacts(data))

    def contact_counts(self, data: mjx.Data):
        """Floor contacts of a physics state: (leg contacts while that leg's foot is lifted
        more than `lift_clearance`, contacts of any non-foot geom), from MJX's contact arrays."""
        return self.robot.contact_counts(*floor_contacts(data), data.geom_xpos[self.feet],
                                         self.config.lift_clearance)

    def reward_terms(self, prev: mjx.Data, data: mjx.Data, done, completed, air_time=0.0, failed_legs=0.0,
                     stance_avg=1.0) -> dict:
        """Unscaled values of the active reward terms for the transition prev -> data, with each
        foot's time off the floor (s), the failed legs (0/1) and each foot's running share of time
        on the floor after it."""
        bad, non_foot = self.contact_counts(data)
        power = servo_power(data.actuator_force, data.qvel, self.robot.actuator_dof)
        return rewards.terms(self._active_terms(), self.config, prev.qpos, data.qpos, data.qvel, self.goal(data),
                             bad, non_foot, done, completed, power, ground=self.robot.ground(data.qpos[:2]),
                             air_time=air_time, working=1.0 - failed_legs, stance_avg=stance_avg)

    # -- what a task defines ----------------------------------------------------

    def observe(self, data: mjx.Data) -> jax.Array:
        """The policy's observation of a physics state (reads only qpos, qvel, ctrl and the goal)."""
        raise NotImplementedError

    def first_goal(self, qpos: jax.Array, rng: jax.Array, level=0) -> jax.Array:
        """The goal (x, y) of an episode starting at `qpos`, at the curriculum's `level` if it has one."""
        raise NotImplementedError

    def goal_completed(self, reached: jax.Array, goals: jax.Array) -> jax.Array:
        """Whether this step completes a goal, given that the torso is within the radius (`reached`)
        and `goals` goals were completed earlier in the episode. Default: goals are never replaced."""
        return jp.zeros((), bool)

    def next_goal(self, data: mjx.Data, goals: jax.Array, rng: jax.Array, level=0) -> jax.Array:
        """The goal (x, y) that follows `goals` completed goals, from the state that completed the last."""
        return self.goal(data)

    # -- internals ------------------------------------------------------------

    def _active_terms(self):
        return [name for name, scale in self.scales.items() if scale != 0.0]
