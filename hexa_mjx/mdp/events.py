"""Episode events, written once for both engines: the start state, pushes, latency, failed servos,
the leg-failure draw, the goal that stays put, the non-finite check and observation noise.

Pure functions of NumPy or JAX arrays. Random numbers come from the engine's `draws` (JAX keys in
MJX, a NumPy generator in native MuJoCo; see `hexa_mjx.engines`), so one line of code draws them in
either engine.
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.mdp.config import STAY_AFTER_MAX
from hexa_mjx.robot.kinematics import namespace, quat_mul
from hexa_mjx.robot.model import failed_ctrl


def start_qpos(qpos0, joint_noise: float, yaw_range: float, joint_lo, joint_hi, draws, key):
    """The settled pose `qpos0` with each joint offset uniformly in +-`joint_noise` rad (clipped to
    its range) and the heading turned uniformly in +-`yaw_range` rad; `qpos0` itself without noise."""
    if not (joint_noise or yaw_range):
        return qpos0
    xp = namespace(qpos0)
    k_joint, k_yaw = draws.split(key)
    joints = qpos0[7:] + draws.uniform(k_joint, qpos0[7:].shape, -joint_noise, joint_noise)
    half_yaw = 0.5 * draws.uniform(k_yaw, (), -1.0, 1.0) * yaw_range
    quat = quat_mul(xp.array([xp.cos(half_yaw), 0.0, 0.0, xp.sin(half_yaw)]), qpos0[3:7])
    return xp.concatenate([qpos0[:3], quat, xp.clip(joints, joint_lo, joint_hi)])


def level_spawn(level, centres, draws, key):
    """Offset (m) of a start at the curriculum's `level` on a terrain: the centre of a random square
    in the level's column (`centres`: the terrain's square centres along one axis)."""
    xp = namespace(centres)
    return xp.stack([centres[level], centres[draws.randint(key, 0, len(centres))]])


def push_steps(push_interval: float, dt: float) -> int:
    """Control steps between pushes (`push_interval` s at a control period of `dt` s)."""
    return max(int(round(push_interval / dt)), 1)


def push_kick(t, every: int, push_speed: float, draws, key):
    """The planar velocity kick (m/s) at episode step `t`: a random direction and a speed uniform in
    [0, push_speed] every `every` control steps, zero otherwise."""
    k_angle, k_speed = draws.split(key)
    angle = draws.uniform(k_angle, (), -np.pi, np.pi)
    speed = draws.uniform(k_speed, (), 0.0, push_speed)
    xp = namespace(angle)
    return xp.where((t > 0) & (t % every == 0), speed, 0.0) * xp.stack([xp.cos(angle), xp.sin(angle)])


NEVER = 2**30  # a goal count no episode reaches: every goal is replaced once reached


def draw_stay_after(share: float, draws, key):
    """How many goals an episode completes before its goal stays put once reached: with
    probability `share`, uniform in 0..STAY_AFTER_MAX; otherwise NEVER."""
    k_whether, k_after = draws.split(key)
    xp = draws.xp
    stays = draws.uniform(k_whether, (), 0.0, 1.0) < share
    return xp.where(stays, draws.randint(k_after, 0, STAY_AFTER_MAX + 1), NEVER).astype(xp.int32)


def draw_latency(max_latency: float, draws, key):
    """An episode's action latency, control steps, uniform in [0, max_latency]."""
    return draws.uniform(key, (), 0.0, max_latency)


def servo_ctrl(step, delay, target, previous, joint_angles, failed, config, hold):
    """The servo targets at physics step `step` of a control step: the previous command until
    `delay` physics steps have passed (action latency), then `target`; a failed servo's target
    follows its joint (limp: no torque) or holds `hold` (locked)."""
    xp = namespace(target)
    ctrl = target
    if config.action_latency:
        ctrl = xp.where(step < delay, previous, ctrl)
    if config.disabled_legs or config.leg_failure == "random":
        ctrl = failed_ctrl(ctrl, joint_angles, failed, config.failure_mode, hold)
    return ctrl


def draw_failure(config, legs: int, draws, key, rate=None, p=None, pairs=()):
    """An episode's failed legs, (legs,) of 0/1: the fixed `disabled_legs`, or with probability
    `leg_failure_rate` one leg drawn (uniformly, or by `leg_failure_weights`), or, in a share
    `leg_failure_pairs` of those, two non-adjacent legs drawn uniformly from `pairs` ((n, 2) leg
    indices). A training schedule (`hexa_mjx.mdp.failure_schedule`) passes its own `rate` and leg
    probabilities `p`."""
    xp = draws.xp
    if config.leg_failure != "random":
        disabled = xp.asarray(config.disabled_legs or (0,), xp.int32) - 1
        return (xp.arange(legs)[:, None] == disabled[None, :]).any(1).astype(xp.float32)
    k_which, k_whether = draws.split(key)
    fails = draws.uniform(k_whether, (), 0.0, 1.0) < (config.leg_failure_rate if rate is None else rate)
    if p is not None:
        leg = draws.choice(k_which, legs, p)
    elif config.leg_failure_weights:
        leg = draws.choice(k_which, legs, xp.asarray(config.leg_failure_weights, xp.float32))
    else:
        leg = draws.randint(k_which, 0, legs)
    failed = xp.arange(legs) == leg
    if config.leg_failure_pairs:
        k_pair, k_two = draws.split(draws.fold_in(key, 2))
        pair = xp.asarray(pairs)[draws.randint(k_pair, 0, len(pairs))]
        two = (xp.arange(legs) == pair[0]) | (xp.arange(legs) == pair[1])
        failed = xp.where(draws.uniform(k_two, (), 0.0, 1.0) < config.leg_failure_pairs, two, failed)
    return failed.astype(xp.float32) * fails


def draw_locked(config, draws, key):
    """Whether an episode's failed legs are locked (1.0) or limp (0.0) under `failure_mode` "mixed":
    even odds."""
    return (draws.uniform(key, (), 0.0, 1.0) < 0.5).astype(draws.xp.float32)


def finite(qpos, qvel):
    """Whether a physics state is finite (a diverged one ends the episode and never reaches the learner)."""
    xp = namespace(qpos)
    return xp.isfinite(qpos).all() & xp.isfinite(qvel).all()


def noisy(obs, scale, draws, key):
    """`obs` plus uniform noise of half-width `scale` per value (the observation noise)."""
    return obs + scale * draws.uniform(key, obs.shape, -1.0, 1.0)
