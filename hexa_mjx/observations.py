"""What each task's policy observes: pure functions of the physics state's arrays (NumPy or JAX).

The MJX environment and the native-MuJoCo player and Gymnasium environments call the same
functions, so a policy sees the same numbers in either engine. `layout` names every slice with
its units; the ONNX export stores it for deployers.
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.kinematics import namespace, rotate, to_heading_frame, yaw

GRAVITY_WORLD = np.array([0.0, 0.0, -1.0], np.float32)  # unit vector
TASKS = ("goal", "navigate")  # the tasks with an observation here


def goal_observation(qpos, qvel, goal_xy):
    """The report's 52 values, world frame (layout("goal", ...))."""
    xp = namespace(qpos)
    goal_vec = goal_xy - qpos[:2]
    angvel_world = rotate(qvel[3:6], qpos[3:7])  # free-joint angular velocity is body-frame
    return xp.concatenate([qpos[:3], qpos[3:7], qvel[:3], angvel_world, qpos[7:], qvel[6:], goal_vec,
                           xp.linalg.norm(goal_vec)[None]])


def navigate_observation(qpos, qvel, ctrl, goal_xy, ctrl_lo, ctrl_hi, distance_cap):
    """67 values in the heading frame (x forward, y left, z up, turned by the torso's yaw only)
    (layout("navigate", ...)). The distance reads at most `distance_cap` m: a farther goal looks like
    the farthest goal trained on, and the policy walks toward it until it is in range."""
    xp = namespace(qpos)
    quat = qpos[3:7]
    heading = yaw(quat)
    goal_vec = to_heading_frame(goal_xy - qpos[:2], heading)
    dist = xp.linalg.norm(goal_vec)
    conj = quat * xp.asarray([1.0, -1.0, -1.0, -1.0], dtype=quat.dtype)
    last_action = 2.0 * (ctrl - ctrl_lo) / (ctrl_hi - ctrl_lo) - 1.0
    return xp.concatenate([
        goal_vec / xp.maximum(dist, 1e-6), xp.minimum(dist, distance_cap)[None],
        qpos[2:3],
        to_heading_frame(qvel[:2], heading), qvel[2:3],
        qvel[3:6],
        rotate(xp.asarray(GRAVITY_WORLD, dtype=quat.dtype), conj),
        qpos[7:], qvel[6:],
        last_action,
    ])


# Half-widths of uniform observation noise at obs_noise=1, by what a slice holds (the levels of
# MuJoCo Playground's locomotion tasks); other slices (goal, orientation, last action) stay exact.
NOISE_SCALES = {"joint angles": 0.03, "joint velocities": 1.5, "linear velocity": 0.1, "angular velocity": 0.2}


def noise_scale(task: str, joints: int) -> np.ndarray:
    """Per-value half-width of observation noise at obs_noise=1 for `task`'s observation."""
    out = np.zeros(layout(task, joints)[-1][1], np.float32)
    for start, end, what, _ in layout(task, joints):
        for key, scale in NOISE_SCALES.items():
            if key in what:
                out[start:end] = scale
    return out


def _layout(parts):
    """(start, end, what, units) of each (what, units, size) in order."""
    out, start = [], 0
    for what, units, size in parts:
        out.append((start, start + size, what, units))
        start += size
    return out


def layout(task: str, joints: int) -> list[tuple[int, int, str, str]]:
    """(start, end, what, units) of every slice of `task`'s observation on a robot with `joints` joints."""
    joint_parts = [("joint angles, hinge order of the model", "rad", joints), ("joint velocities", "rad/s", joints)]
    if task == "goal":
        return _layout([
            ("torso position, world", "m", 3), ("torso quaternion (w, x, y, z), world", "", 4),
            ("torso linear velocity, world", "m/s", 3), ("torso angular velocity, world", "rad/s", 3),
            *joint_parts, ("goal minus torso (x, y), world", "m", 2), ("goal distance", "m", 1)])
    if task == "navigate":
        return _layout([
            ("goal direction (x, y), heading frame, unit vector", "", 2),
            ("goal distance, capped at the trained range's end", "m", 1), ("torso height", "m", 1),
            ("torso linear velocity (x, y) heading frame, z world", "m/s", 3),
            ("torso angular velocity, body frame", "rad/s", 3), ("gravity direction, body frame", "", 3),
            *joint_parts, ("previous action (control targets mapped back to [-1, 1])", "", joints)])
    raise ValueError(f"unknown task {task!r}; choose one of {list(TASKS)}")
