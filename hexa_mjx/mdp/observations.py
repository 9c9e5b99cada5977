"""Observation terms: pure functions of the physics state's arrays (NumPy or JAX), and the helpers
a task's observation layout is written with.

Both engines call the same functions, so a policy sees the same numbers in either. A task's
`layout` names every slice with its units; the ONNX export stores it for deployers.
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.robot.kinematics import namespace, rotate, to_heading_frame, yaw

GRAVITY_WORLD = np.array([0.0, 0.0, -1.0], np.float32)  # unit vector


def goal_observation(qpos, qvel, goal_xy):
    """The report's 52 values, world frame (GoalTask.layout)."""
    xp = namespace(qpos)
    goal_vec = goal_xy - qpos[:2]
    angvel_world = rotate(qvel[3:6], qpos[3:7])  # free-joint angular velocity is body-frame
    return xp.concatenate([qpos[:3], qpos[3:7], qvel[:3], angvel_world, qpos[7:], qvel[6:], goal_vec,
                           xp.linalg.norm(goal_vec)[None]])


def proprioception(qpos, qvel, ctrl, ctrl_lo, ctrl_hi):
    """The torso's velocities (linear in the heading frame), gravity in the body frame, the joints
    and the previous action mapped back to [-1, 1] (proprioception_slices)."""
    xp = namespace(qpos)
    quat = qpos[3:7]
    heading = yaw(quat)
    conj = quat * xp.asarray([1.0, -1.0, -1.0, -1.0], dtype=quat.dtype)
    last_action = 2.0 * (ctrl - ctrl_lo) / (ctrl_hi - ctrl_lo) - 1.0
    return xp.concatenate([to_heading_frame(qvel[:2], heading), qvel[2:3], qvel[3:6],
                           rotate(xp.asarray(GRAVITY_WORLD, dtype=quat.dtype), conj), qpos[7:], qvel[6:], last_action])


def navigate_observation(qpos, qvel, ctrl, goal_xy, ctrl_lo, ctrl_hi, distance_cap):
    """67 values in the heading frame (x forward, y left, z up, turned by the torso's yaw only)
    (NavigateTask.layout). The distance reads at most `distance_cap` m: a farther goal looks like
    the farthest goal trained on, and the policy walks toward it until it is in range."""
    xp = namespace(qpos)
    goal_vec = to_heading_frame(goal_xy - qpos[:2], yaw(qpos[3:7]))
    dist = xp.linalg.norm(goal_vec)
    return xp.concatenate([goal_vec / xp.maximum(dist, 1e-6), xp.minimum(dist, distance_cap)[None], qpos[2:3],
                           proprioception(qpos, qvel, ctrl, ctrl_lo, ctrl_hi)])


# Half-widths of uniform observation noise at obs_noise=1, by what a slice holds (the levels of
# MuJoCo Playground's locomotion tasks); other slices (goal, orientation, last action) stay exact.
NOISE_SCALES = {"joint angles": 0.03, "joint velocities": 1.5, "linear velocity": 0.1, "angular velocity": 0.2}


def noise_scale(layout) -> np.ndarray:
    """Per-value half-width of observation noise at obs_noise=1 for an observation `layout`."""
    out = np.zeros(layout[-1][1], np.float32)
    for start, end, what, _ in layout:
        for key, scale in NOISE_SCALES.items():
            if key in what:
                out[start:end] = scale
    return out


def slices(parts) -> list[tuple[int, int, str, str]]:
    """(start, end, what, units) of each (what, units, size) in order: an observation's layout."""
    out, start = [], 0
    for what, units, size in parts:
        out.append((start, start + size, what, units))
        start += size
    return out


def joint_slices(joints: int) -> list[tuple[str, str, int]]:
    """The joint angles and velocities of a robot with `joints` joints, as (what, units, size)."""
    return [("joint angles, hinge order of the model", "rad", joints), ("joint velocities", "rad/s", joints)]


def proprioception_slices(joints: int) -> list[tuple[str, str, int]]:
    """The layout of `proprioception`, as (what, units, size)."""
    return [("torso linear velocity (x, y) heading frame, z world", "m/s", 3),
            ("torso angular velocity, body frame", "rad/s", 3), ("gravity direction, body frame", "", 3),
            *joint_slices(joints), ("previous action (control targets mapped back to [-1, 1])", "", joints)]


def failure_observation(failed_legs, locked):
    """What failed this episode, for a critic that may know it: per leg, limp (0/1), then per leg,
    locked (0/1). `locked` is 1.0 where the failed legs are locked, 0.0 where limp."""
    xp = namespace(failed_legs)
    return xp.concatenate([failed_legs * (1.0 - locked), failed_legs * locked], axis=-1)
