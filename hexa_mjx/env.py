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

import dataclasses
import functools
import math
from pathlib import Path

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from brax.envs.base import Env, State

from mujoco import mjx

from hexa_mjx import rewards, robot


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Environment settings; `make_env(**overrides)` sets any of them by name."""

    task: str = "goal"  # a key of hexa_mjx.tasks.TASKS
    reward: str = ""  # a key of rewards.VARIANTS valid for the task; "": the task's own
    ablate: tuple[str, ...] = ()  # keys of rewards.ABLATIONS whose terms are zeroed
    reward_scales: dict = dataclasses.field(default_factory=dict)  # per-term scale overrides
    model_path: str = str(robot.MODEL_XML)
    ctrl_hz: float = 60.0  # Hz, policy rate; 240 Hz physics / ctrl_hz must be whole
    episode_length: int = 1000  # control steps
    success_radius: float = 0.5  # m
    # The goal bonus is paid only while nothing but the feet touches the floor. The report pays it
    # for being within the radius; with that, policies reached the goal, then rested on their shins
    # there for the rest of the episode (100 per step dwarfs -1 per contact). False: the report's bonus.
    bonus_on_feet_only: bool = True
    target_height: float = 0.12  # m, torso-origin height the height term aims for
    lift_clearance: float = 0.02  # m, foot height above which a leg's floor contact is "bad"
    settle_steps: int = 100  # physics steps the start pose settles before the first observation
    # Start-state noise, drawn per reset (the report starts every episode from the same pose).
    start_joint_noise: float = 0.0  # rad, each joint's start angle is offset uniformly in +-this
    start_yaw_noise: float = 0.0  # rad, the start heading is turned uniformly in +-this (navigate: always pi)
    solver_iterations: int | None = None  # None: the model's own setting
    ls_iterations: int | None = None
    # MJX gives every robot-floor geom pair fixed contact slots (40 on the report's hexapod: box 4,
    # capsules 2, spheres 1) and solves for all of them each step. N > 0 keeps only the N deepest
    # (MJX's `max_contact_points`); 0 keeps every slot. See docs/RESULTS.md, "Speed".
    max_contact_points: int = 0
    # Report task ("goal"): one goal this far ahead (+x) of the start.
    goal_distance: float = 1.5  # m
    # Navigation task ("navigate"): goals at a bearing uniform over 360 degrees from the torso and a
    # distance uniform in [goal_min_distance, goal_max_distance]; a new one each time one is reached.
    goal_min_distance: float = 0.5  # m
    goal_max_distance: float = 3.0  # m
    # Navigation: the observed distance is capped here (0: goal_max_distance). A policy keeps the
    # cap it was trained with when evaluated on another range.
    goal_distance_cap: float = 0.0  # m
    # Navigation: a fixed path instead of random goals, ((x, y), ...) in metres, world frame,
    # relative to the start position. The last waypoint stays the goal once reached.
    waypoints: tuple = ()


def floor_contacts(data: mjx.Data):
    """(geom1, geom2, dist) of MJX's contact arrays (JAX implementation only)."""
    contact = data._impl.contact
    return contact.geom1, contact.geom2, contact.dist


def _load_model(path: Path, max_contact_points: int) -> mujoco.MjModel:
    """The MJCF at `path` with MJX's contact cap set (0: none, whatever the file says)."""
    spec = mujoco.MjSpec.from_file(str(path))
    for numeric in spec.numerics:
        if numeric.name == "max_contact_points":
            spec.delete(numeric)
    if max_contact_points:
        spec.add_numeric(name="max_contact_points", data=[max_contact_points])
    return spec.compile()


def roll_pitch(quat):
    """Roll and pitch (ZYX Euler angles, rad) of a (w, x, y, z) quaternion."""
    w, x, y, z = quat
    roll = jp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = jp.arcsin(jp.clip(2 * (w * y - z * x), -1.0, 1.0))
    return roll, pitch


def yaw(quat):
    """Heading (ZYX Euler yaw, rad) of a (w, x, y, z) quaternion."""
    w, x, y, z = quat
    return jp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def quat_mul(a, b):
    """Hamilton product of two (w, x, y, z) quaternions."""
    return jp.concatenate([a[:1] * b[:1] - a[1:] @ b[1:],
                           a[0] * b[1:] + b[0] * a[1:] + jp.cross(a[1:], b[1:])])


def rotate(vec, quat):
    """Rotate `vec` by the (w, x, y, z) quaternion `quat`."""
    w, u = quat[0], quat[1:]
    return vec + 2 * jp.cross(u, jp.cross(u, vec) + w * vec)


def check_config(config: EnvConfig) -> None:
    """Raise ValueError for settings out of range (before any model is built or compiled)."""
    for name in ("ctrl_hz", "success_radius", "goal_distance", "goal_max_distance", "target_height"):
        value = getattr(config, name)
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number above 0, got {value}")
    if not (math.isfinite(config.goal_distance_cap) and config.goal_distance_cap >= 0):
        raise ValueError(f"goal_distance_cap must be 0 (the range's end) or a distance in m, got {config.goal_distance_cap}")
    for name in ("start_joint_noise", "start_yaw_noise"):
        if not 0 <= getattr(config, name) <= np.pi:
            raise ValueError(f"{name} is a range in radians from 0 to pi, got {getattr(config, name)}")
    if not (math.isfinite(config.goal_min_distance) and 0 <= config.goal_min_distance <= config.goal_max_distance):
        raise ValueError(f"the goal distance range needs 0 <= min <= max, got min {config.goal_min_distance} "
                         f"and max {config.goal_max_distance} m")
    if config.episode_length < 1:
        raise ValueError(f"episode_length must be at least 1, got {config.episode_length}")
    if config.max_contact_points < 0:
        raise ValueError(f"max_contact_points must be 0 (every contact slot) or positive, "
                         f"got {config.max_contact_points}")
    for point in config.waypoints:
        if len(point) != 2 or not all(math.isfinite(float(c)) for c in point):
            raise ValueError(f"a waypoint is a pair of finite coordinates x,y in metres, got {point}")


class HexapodEnv(Env):
    """The robot on a floor with a goal marker; a task subclass adds goals, observation and terms."""

    name = ""  # the task's name in hexa_mjx.tasks.TASKS
    rewards: tuple[str, ...] = ()  # the task's reward variants, its default first

    def __init__(self, config: EnvConfig = EnvConfig()):
        check_config(config)
        config = dataclasses.replace(config, task=self.name, reward=config.reward or self.rewards[0])
        if config.reward not in rewards.VARIANTS:
            raise ValueError(f"unknown reward {config.reward!r}; the {self.name} task's are {list(self.rewards)}")
        if config.reward not in self.rewards:
            raise ValueError(f"reward {config.reward!r} is not one of the {self.name} task's: {list(self.rewards)}")
        self.config = config
        self.scales = rewards.make_scales(config.reward, config.ablate, config.reward_scales)
        path = Path(config.model_path)
        if not path.is_file():
            raise FileNotFoundError(f"model {path} not found; run `python -m hexa_mjx.convert URDF -o {path}`")
        model = _load_model(path, config.max_contact_points)
        if config.solver_iterations is not None:
            model.opt.iterations = config.solver_iterations
        if config.ls_iterations is not None:
            model.opt.ls_iterations = config.ls_iterations
        self.mj_model = model

        substeps = 1.0 / (config.ctrl_hz * model.opt.timestep)
        if abs(substeps - round(substeps)) > 1e-3 or round(substeps) < 1:
            rate = round(1.0 / model.opt.timestep, 3)  # the MJCF stores the timestep to 6 digits
            choices = [round(rate / n, 3) for n in range(1, 13) if abs(rate / n - round(rate / n)) < 1e-3]
            raise ValueError(f"ctrl_hz={config.ctrl_hz} is not the {rate:g} Hz physics rate divided by a whole "
                             f"number; choose e.g. one of {choices}")
        self.n_substeps = int(round(substeps))

        self._floor = model.geom(robot.FLOOR_GEOM).id
        self._torso = model.body(robot.TORSO_BODY).id
        self._goal_mocap = model.body_mocapid[model.body(robot.GOAL_BODY).id]
        legs = sorted({model.joint(j).name.split("_")[0] for j in range(model.njnt)
                       if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE}, key=lambda s: int(s[3:]))
        self.feet = np.array([model.geom(robot.foot_geom(leg)).id for leg in legs])  # foot geom ids
        # Leg index of every geom (-1 for the torso and the world), and whether it is a foot.
        body_leg = np.full(model.nbody, -1)
        for i, leg in enumerate(legs):
            for j in range(model.njnt):
                if model.joint(j).name.startswith(leg + "_"):
                    body_leg[model.jnt_bodyid[j]] = i
        for b in range(1, model.nbody):  # bodies without joints inherit their parent's leg
            if body_leg[b] < 0 and model.body_parentid[b] > 0:
                body_leg[b] = body_leg[model.body_parentid[b]]
        self.geom_leg = body_leg[model.geom_bodyid]
        self._geom_leg = jp.asarray(self.geom_leg)
        self._geom_is_foot = jp.asarray(np.isin(np.arange(model.ngeom), self.feet))
        self._ctrl_lo, self._ctrl_hi = (jp.asarray(x, dtype=jp.float32) for x in model.actuator_ctrlrange.T)

        # Settle the start pose once with MuJoCo C; every reset starts from that state.
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        for _ in range(config.settle_steps):
            mujoco.mj_step(model, data)
        self.qpos0, self.qvel0 = np.array(data.qpos), np.array(data.qvel)
        self._qpos0, self._qvel0, self._ctrl0 = (jp.asarray(x, dtype=jp.float32) for x in (data.qpos, data.qvel, data.ctrl))
        self._start_xy = jp.asarray(data.qpos[:2], dtype=jp.float32)
        hinge_range = model.jnt_range[model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE]
        self._joint_lo, self._joint_hi = (jp.asarray(x, dtype=jp.float32) for x in hinge_range.T)
        self.mjx_model = mjx.put_model(model, impl="jax")
        self._data0 = mjx.make_data(self.mjx_model, impl="jax")

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
        info = {"rng": rng, "t": jp.zeros((), jp.int32), "success": zero, "goals": jp.zeros((), jp.int32)}
        return State(data, self.observe(data), zero, zero, metrics, info)

    def step(self, state: State, action: jax.Array) -> State:
        """Apply one control step: position targets from `action` in [-1, 1], `n_substeps` physics steps."""
        if action.shape != (self.action_size,):
            raise ValueError(f"action must have shape ({self.action_size},) per environment, got {action.shape}; "
                             "batch environments with jax.vmap")
        prev = state.pipeline_state
        target = self._ctrl_lo + (jp.clip(action, -1.0, 1.0) + 1.0) * 0.5 * (self._ctrl_hi - self._ctrl_lo)
        data = prev.replace(ctrl=target)
        data, _ = jax.lax.scan(lambda d, _: (mjx.step(self.mjx_model, d), None), data, None, length=self.n_substeps)

        # A diverged physics state never reaches the learner: keep the last finite one and end the episode.
        finite = jp.isfinite(data.qpos).all() & jp.isfinite(data.qvel).all()
        data = jax.tree.map(lambda new, old: jp.where(finite, new, old), data, prev)
        data = data.replace(qpos=jp.where(jp.isfinite(data.qpos), data.qpos, self._qpos0),
                            qvel=jp.where(jp.isfinite(data.qvel), data.qvel, 0.0))

        roll, pitch = roll_pitch(data.qpos[3:7])
        fell = (jp.abs(roll) > jp.pi / 2) | (jp.abs(pitch) > jp.pi / 2)
        done = fell | ~finite
        # Every term sees the goal of this step; a goal reached now is replaced only afterwards, so
        # the step that draws a new goal pays no spurious approach reward or penalty.
        dist = self.goal_distance(data)
        reached = dist < self.config.success_radius
        completed = self.goal_completed(reached, state.info["goals"])
        scaled = {name: self.scales[name] * value
                  for name, value in self.reward_terms(prev, data, done, completed).items()}
        reward = sum(scaled.values())

        t = state.info["t"] + 1
        over = done | (t >= self.config.episode_length)
        rng, key = jax.random.split(state.info["rng"])
        goals = state.info["goals"] + completed
        data = self.set_goal(data, jp.where(completed, self.next_goal(data, goals, key), self.goal(data)))
        success = jp.maximum(state.info["success"], reached.astype(jp.float32))
        info = {**state.info, "rng": rng, "t": jp.where(over, 0, t), "success": jp.where(over, 0.0, success),
                "goals": jp.where(over, 0, goals)}
        # Start from the incoming metrics: wrappers (brax's evaluator) add keys of their own.
        metrics = {**state.metrics, **{f"reward/{name}": value for name, value in scaled.items()}}
        # Per-step values whose sums over an episode are the per-episode figures brax's evaluator reports.
        metrics.update(distance=dist, success=success, fell=fell.astype(jp.float32),
                       nonfinite=(~finite).astype(jp.float32), goals_reached=completed.astype(jp.float32),
                       goal_bonus=rewards.VARIANTS["goal_directed"]["goal_bonus"] * rewards.goal_bonus(
                           dist, self.config.success_radius),
                       final_distance=jp.where(over, dist, 0.0), final_success=jp.where(over, success, 0.0))
        return state.replace(pipeline_state=data, obs=self.observe(data), reward=reward,
                             done=done.astype(jp.float32), metrics=metrics, info=info)

    def restart(self, data: mjx.Data, rng: jax.Array) -> mjx.Data:
        """`data` with a fresh start state (qpos, qvel, ctrl, time) and first goal drawn with `rng`.

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
            qpos = jp.concatenate([qpos[:3], quat, jp.clip(joints, self._joint_lo, self._joint_hi)])
        data = data.replace(qpos=qpos, qvel=self._qvel0, ctrl=self._ctrl0, time=jp.zeros_like(data.time))
        return self.set_goal(data, self.first_goal(qpos, jax.random.fold_in(rng, 2)))

    def goal(self, data: mjx.Data) -> jax.Array:
        """The current goal's (x, y), m, world frame."""
        return data.mocap_pos[self._goal_mocap, :2]

    def set_goal(self, data: mjx.Data, goal_xy: jax.Array) -> mjx.Data:
        return data.replace(mocap_pos=data.mocap_pos.at[self._goal_mocap, :2].set(goal_xy))

    def goal_distance(self, data: mjx.Data) -> jax.Array:
        """Planar distance from the torso origin to the current goal, m."""
        return jp.linalg.norm(self.goal(data) - data.qpos[:2])

    @property
    def contact_slots(self) -> int:
        """Contact points MJX solves for at every physics step (all robot-floor slots, or the cap)."""
        return int(floor_contacts(self._data0)[2].shape[0])

    def floor_contact_geoms(self, data: mjx.Data):
        """(active robot-floor contact mask, the robot geom of each contact) over MJX's contact slots."""
        geom1, geom2, dist = floor_contacts(data)
        on_floor = (dist < 0) & ((geom1 == self._floor) | (geom2 == self._floor))
        return on_floor, jp.where(geom1 == self._floor, geom2, geom1)

    def contact_counts(self, data: mjx.Data):
        """Floor contacts of a physics state: (leg contacts while that leg's foot is lifted
        more than `lift_clearance`, contacts of any non-foot geom), from MJX's contact arrays."""
        on_floor, other = self.floor_contact_geoms(data)
        leg = self._geom_leg[other]
        foot_clearance = data.geom_xpos[self.feet, 2] - self.mj_model.geom_size[self.feet, 0]
        lifted = foot_clearance[jp.maximum(leg, 0)] > self.config.lift_clearance
        bad = on_floor & (leg >= 0) & lifted
        return bad.sum(), (on_floor & ~self._geom_is_foot[other]).sum()

    def reward_terms(self, prev: mjx.Data, data: mjx.Data, done, completed) -> dict:
        """Unscaled values of the active reward terms for the transition prev -> data."""
        roll, pitch = roll_pitch(data.qpos[3:7])
        inputs = self._term_inputs(prev, data, done, roll, pitch, completed)
        return {name: rewards.TERMS[name](*inputs[name]) for name in self._active_terms()}

    # -- what a task defines ----------------------------------------------------

    def observe(self, data: mjx.Data) -> jax.Array:
        """The policy's observation of a physics state (reads only qpos, qvel, ctrl and the goal)."""
        raise NotImplementedError

    def first_goal(self, qpos: jax.Array, rng: jax.Array) -> jax.Array:
        """The goal (x, y) of an episode starting at `qpos`."""
        raise NotImplementedError

    def goal_completed(self, reached: jax.Array, goals: jax.Array) -> jax.Array:
        """Whether this step completes a goal, given that the torso is within the radius (`reached`)
        and `goals` goals were completed earlier in the episode. Default: goals are never replaced."""
        return jp.zeros((), bool)

    def next_goal(self, data: mjx.Data, goals: jax.Array, rng: jax.Array) -> jax.Array:
        """The goal (x, y) that follows `goals` completed goals, from the state that completed the last."""
        return self.goal(data)

    # -- internals ------------------------------------------------------------

    def _active_terms(self):
        return [name for name, scale in self.scales.items() if scale != 0.0]

    def _term_inputs(self, prev, data, done, roll, pitch, completed):
        """Arguments of every reward term, by name; XLA drops what no active term uses."""
        xy, prev_xy, vel_xy = data.qpos[:2], prev.qpos[:2], data.qvel[:2]
        goal_dir = self.goal(data) - xy
        goal_dir = goal_dir / jp.maximum(jp.linalg.norm(goal_dir), 1e-6)
        bad, non_foot = self.contact_counts(data)
        # The previous position's distance to this step's goal (the goal only moves after the terms).
        dist_prev = jp.linalg.norm(self.goal(data) - prev_xy)
        return {
            "goal_approach": (dist_prev, self.goal_distance(data)),
            "goal_reached": (completed,),
            "velocity_alignment": (vel_xy, goal_dir),
            "goal_bonus": (self.goal_distance(data), self.config.success_radius,
                           non_foot if self.config.bonus_on_feet_only else 0),
            "stability": (roll, pitch),
            "height": (data.qpos[2], self.config.target_height),
            "energy": (data.qvel[6:],),
            "contact_quality": (bad,),
            "body_contact": (non_foot,),
            "termination": (done,),
            "forward_progress": (prev_xy, xy),
            "forward_velocity": (vel_xy,),
        }
