"""A task on MuJoCo MJX: pure JAX, jit- and vmap-able, behind brax's `Env` interface.

    env = make_env(task="navigate")
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    state = jax.jit(env.step)(state, jp.zeros(env.action_size))

This engine supplies MJX's physics step, its contact arrays (`hexa_mjx.engines.contacts`) and JAX's
random draws; the task and every episode event come from `hexa_mjx.mdp.episode`, which native
MuJoCo runs too. The current goal is the model's `goal` mocap body, so it is part of the physics
state (`pipeline_state.mocap_pos`): auto-resets restore it with the rest of the state, a recorded
trajectory carries it, and the video draws it where it was. Episode bookkeeping lives in
`state.info` and is reset by `step` itself on the last step of an episode (brax's
AutoResetWrapper restores only `pipeline_state` and `obs`).
"""

from __future__ import annotations

import contextlib
import copy
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

from hexa_mjx.engines import contacts  # noqa: E402
from hexa_mjx.mdp import events, rewards, terrain as terrains  # noqa: E402
from hexa_mjx.mdp.config import EnvConfig  # noqa: E402
from hexa_mjx.mdp.episode import Contacts, make_episode  # noqa: E402
from hexa_mjx.robot.kinematics import yaw  # noqa: E402
from hexa_mjx.robot.model import action_to_ctrl  # noqa: E402


class JaxDraws:
    """Random draws from JAX keys (the engine-neutral interface of `hexa_mjx.mdp.events`)."""

    xp = jp
    split = staticmethod(jax.random.split)
    fold_in = staticmethod(jax.random.fold_in)

    @staticmethod
    def uniform(key, shape, minval, maxval):
        return jax.random.uniform(key, shape, minval=minval, maxval=maxval)

    @staticmethod
    def randint(key, low, high):
        return jax.random.randint(key, (), low, high)

    @staticmethod
    def choice(key, n, p):
        return jax.random.choice(key, n, p=p)

    @staticmethod
    def select(cond, if_true, if_false):
        """`if_true()` where `cond`, else `if_false()` (trees of arrays): under tracing both are computed."""
        return jax.tree.map(lambda a, b: jp.where(cond, a, b), if_true(), if_false())


DRAWS = JaxDraws()


class HexapodEnv(Env):
    """A task of `hexa_mjx.tasks` on MJX; `observe_as` names another task whose observation the
    policy sees (the report's policy on navigation goals)."""

    def __init__(self, config: EnvConfig = EnvConfig(), observe_as: str = ""):
        self.episode = make_episode(config, observe_as)
        self.config, self.robot, self.task = self.episode.config, self.episode.robot, self.episode.task
        self.scales = self.episode.scales
        self.mj_model, self.n_substeps = self.robot.mj_model, self.robot.n_substeps
        self.qpos0, self.qvel0 = self.robot.qpos0, self.robot.qvel0
        self.feet, self.geom_leg = self.robot.feet, self.robot.geom_leg
        self._qpos0, self._qvel0, self._ctrl0 = (jp.asarray(x, jp.float32) for x in
                                                 (self.robot.qpos0, self.robot.qvel0, self.robot.ctrl0))
        self._put_physics(self.mj_model)
        if self.config.max_contact_points > self.contact_slots:  # a cap above the slots would cap nothing
            raise ValueError(f"max_contact_points {self.config.max_contact_points} is above the model's "
                             f"{self.contact_slots} robot-floor contact slots; use 1 to {self.contact_slots}, or 0 for all")

    name = property(lambda self: self.task.name)
    observe_task = property(lambda self: self.episode.observer.name)  # the task whose observation the policy sees

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
        return self.episode.dt

    @property
    def fresh_starts(self) -> bool:
        """Whether episodes start from random states (training must redraw them at every reset)."""
        return bool(self.config.start_joint_noise or self.start_yaw_range or self.task.uses_heading
                    or self.task.uses_command)

    @property
    def start_yaw_range(self) -> float:
        """The start heading is turned uniformly in +-this, rad."""
        return self.task.start_yaw_range

    def reset(self, rng: jax.Array) -> State:
        """Start an episode from the settled standing pose, perturbed by the start noise."""
        data = mjx.forward(self.mjx_model, self.restart(self._data0, rng))
        zero = jp.zeros(())
        metrics = {f"reward/{name}": zero for name in self.episode.active}
        metrics.update(distance=self.goal_distance(data), success=zero, fell=zero, nonfinite=zero, goal_bonus=zero,
                       goals_reached=zero, final_distance=zero, final_success=zero)
        info = {"rng": rng, **self.episode.start_info(DRAWS, rng)}
        return State(data, self.noisy(self.observe(data), jax.random.fold_in(rng, 5)), zero, zero, metrics, info)

    def step(self, state: State, action: jax.Array) -> State:
        """Apply one control step: position targets from `action` in [-1, 1], `n_substeps` physics steps."""
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},) per environment, got {action.shape}; "
                             "batch environments with jax.vmap")
        episode, info = self.episode, state.info
        prev = state.pipeline_state
        target = action_to_ctrl(action, self.robot.ctrl_lo, self.robot.ctrl_hi)
        data = prev.replace(ctrl=target)
        if self.config.push_speed:  # a kick to the torso's planar velocity, every push_interval
            kick = events.push_kick(info["t"], episode.push_every, self.config.push_speed, DRAWS,
                                    jax.random.fold_in(info["rng"], 7))
            data = data.replace(qvel=data.qvel.at[:2].add(kick))
        failed, delay = episode.failed_servos(info), episode.delay(info)

        def physics_step(d, i):
            ctrl = episode.servo_ctrl(i, delay, target, prev.ctrl, d.qpos, failed)
            return mjx.step(self.mjx_model, d.replace(ctrl=ctrl)), None

        data, _ = jax.lax.scan(physics_step, data, jp.arange(self.n_substeps))
        data = data.replace(ctrl=target)  # the policy's own command, whatever failed or lagged

        # A diverged physics state never reaches the learner: keep the last finite one and end the episode.
        finite = events.finite(data.qpos, data.qvel)
        data = jax.tree.map(lambda new, old: jp.where(finite, new, old), data, prev)
        data = data.replace(qpos=jp.where(jp.isfinite(data.qpos), data.qpos, self._qpos0),
                            qvel=jp.where(jp.isfinite(data.qvel), data.qvel, 0.0))

        rng, key = jax.random.split(info["rng"])
        info, terms, fig, target = episode.transition(info, prev.qpos, data.qpos, data.qvel, self.goal(data),
                                                       self.heading(data), self.command(data), self.contacts(data),
                                                       data.actuator_force, finite, DRAWS, key)
        data = self.set_target(data, **target)
        info = episode.restart_info({**info, "rng": rng}, fig["over"], DRAWS, key, info.get("leg_failure_rate"),
                                    info.get("leg_failure_p"))
        over, dist, success, scaled = fig["over"], fig["distance"], fig["success"], episode.scaled(terms)
        # Start from the incoming metrics: wrappers (brax's evaluator) add keys of their own.
        metrics = {**state.metrics, **{f"reward/{name}": value for name, value in scaled.items()}}
        # Per-step values whose sums over an episode are the per-episode figures brax's evaluator reports.
        metrics.update(distance=dist, success=success, fell=fig["fell"].astype(jp.float32),
                       nonfinite=(~finite).astype(jp.float32), goals_reached=fig["completed"].astype(jp.float32),
                       goal_bonus=rewards.GOAL_BONUS * rewards.goal_bonus(dist, self.config.success_radius),
                       final_distance=jp.where(over, dist, 0.0), final_success=jp.where(over, success, 0.0))
        return state.replace(pipeline_state=data, obs=self.noisy(self.observe(data), jax.random.fold_in(key, 5)),
                             reward=sum(scaled.values()), done=fig["done"].astype(jp.float32), metrics=metrics,
                             info=info)

    def noisy(self, obs: jax.Array, rng: jax.Array) -> jax.Array:
        """`obs` with the configured observation noise (none at obs_noise=0)."""
        if not self.config.obs_noise:
            return obs
        return events.noisy(obs, self.episode.noise_scale, DRAWS, rng)

    def draw_failure(self, rng: jax.Array, rate=None, p=None) -> jax.Array:
        """An episode's failed legs, (legs,) of 0/1 (`hexa_mjx.mdp.events.draw_failure`)."""
        return events.draw_failure(self.config, len(self.robot.legs), DRAWS, rng, rate, p,
                                   self.robot.non_adjacent_pairs)

    def restart(self, data: mjx.Data, rng: jax.Array, level=0) -> mjx.Data:
        """`data` with a fresh start state (qpos, qvel, ctrl, time) and first goal drawn with `rng`
        (at the curriculum's `level`).

        Quantities derived from the state (positions, contacts) are left as they are: the next
        `mjx.step` recomputes them from qpos and qvel, and the observation needs only those.
        """
        spawn = jp.asarray(terrains.spawn_points(), jp.float32) if self.robot.terrain is not None else None
        qpos = self.episode.start_qpos(self._qpos0, DRAWS, rng, level, spawn)
        data = data.replace(qpos=qpos, qvel=self._qvel0, ctrl=self._ctrl0, time=jp.zeros_like(data.time))
        key = jax.random.fold_in(rng, 2)
        heading = self.task.goal_heading(qpos, DRAWS, jax.random.fold_in(key, 1))
        command, commanded_heading = self.task.first_command(qpos, DRAWS, jax.random.fold_in(key, 3))
        return self.set_target(data, self.task.first_goal(qpos, DRAWS, key, level),
                               heading if commanded_heading is None else commanded_heading, command)

    def observe(self, data: mjx.Data) -> jax.Array:
        """The policy's observation of a physics state (reads only qpos, qvel, ctrl and the goal)."""
        return self.episode.observer.observe(data.qpos, data.qvel, data.ctrl, self.goal(data), self.heading(data),
                                             self.command(data))

    # -- the goal marker and contacts ------------------------------------------

    def goal(self, data: mjx.Data) -> jax.Array:
        """The current goal's (x, y), m, world frame."""
        return data.mocap_pos[self.robot.goal_mocap, :2]

    def set_goal(self, data: mjx.Data, goal_xy: jax.Array) -> mjx.Data:
        return data.replace(mocap_pos=data.mocap_pos.at[self.robot.goal_mocap, :2].set(goal_xy))

    def heading(self, data: mjx.Data) -> jax.Array:
        """The goal marker's heading, rad."""
        return yaw(data.mocap_quat[self.robot.goal_mocap])

    def set_heading(self, data: mjx.Data, heading: jax.Array) -> mjx.Data:
        quat = jp.stack([jp.cos(heading / 2), 0.0 * heading, 0.0 * heading, jp.sin(heading / 2)])
        return data.replace(mocap_quat=data.mocap_quat.at[self.robot.goal_mocap].set(quat))

    def command(self, data: mjx.Data) -> jax.Array:
        """The task's command (the model's userdata; hexa_mjx.tasks.velocity)."""
        return data.userdata

    def set_target(self, data: mjx.Data, goal, heading=None, command=None) -> mjx.Data:
        """`data` with the task's goal and, where given, heading and command."""
        data = self.set_goal(data, goal)
        if heading is not None and (self.task.uses_heading or self.task.uses_command):
            data = self.set_heading(data, heading)
        return data if command is None else data.replace(userdata=command)

    def goal_distance(self, data: mjx.Data) -> jax.Array:
        """Planar distance from the torso origin to the current goal, m."""
        return jp.linalg.norm(self.goal(data) - data.qpos[:2])

    @property
    def contact_slots(self) -> int:
        """Contact points MJX solves for at every physics step (all robot-floor slots, or the cap)."""
        return int(contacts.of(self._data0)[2].shape[0])

    def contacts(self, data: mjx.Data) -> Contacts:
        """The robot-floor contact arrays the episode reads."""
        return Contacts(*contacts.of(data), data.geom_xpos[self.robot.feet])

    def floor_contact_geoms(self, data: mjx.Data):
        """(active robot-floor contact mask, the robot geom of each contact) over MJX's contact slots."""
        return self.robot.floor_contact_geoms(*contacts.of(data))

    def foot_stance(self, data: mjx.Data) -> jax.Array:
        """Whether each foot touches the floor, (legs,) bool."""
        return self.robot.foot_stance(*contacts.of(data))

    def contact_counts(self, data: mjx.Data):
        """(leg contacts while that leg's foot is lifted more than `lift_clearance`, contacts of any
        non-foot geom) with the floor."""
        return self.robot.contact_counts(*contacts.of(data), data.geom_xpos[self.robot.feet], self.config.lift_clearance)
