"""Torso orientation and frames: pure functions of NumPy or JAX arrays.

Each works on whichever array library its input comes from (the array API's
`__array_namespace__`), so the MJX environment and the native-MuJoCo player
compute the same observation and termination from the same code.
"""

from __future__ import annotations

import numpy as np


def namespace(x):
    """The array library of `x`: jax.numpy for JAX arrays and tracers, NumPy otherwise."""
    return x.__array_namespace__() if hasattr(x, "__array_namespace__") else np


def roll_pitch(quat):
    """Roll and pitch (ZYX Euler angles, rad) of a (w, x, y, z) quaternion."""
    xp = namespace(quat)
    w, x, y, z = quat
    roll = xp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = xp.arcsin(xp.clip(2 * (w * y - z * x), -1.0, 1.0))
    return roll, pitch


def yaw(quat):
    """Heading (ZYX Euler yaw, rad) of a (w, x, y, z) quaternion."""
    xp = namespace(quat)
    w, x, y, z = quat
    return xp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def fell(quat):
    """Whether the torso has rolled or pitched past 90 degrees (the report's flip)."""
    roll, pitch = roll_pitch(quat)
    return (abs(roll) > np.pi / 2) | (abs(pitch) > np.pi / 2)


def quat_mul(a, b):
    """Hamilton product of two (w, x, y, z) quaternions."""
    xp = namespace(a)
    return xp.concatenate([a[:1] * b[:1] - a[1:] @ b[1:],
                           a[0] * b[1:] + b[0] * a[1:] + xp.cross(a[1:], b[1:])])


def rotate(vec, quat):
    """Rotate `vec` by the (w, x, y, z) quaternion `quat`."""
    xp = namespace(quat)
    w, u = quat[0], quat[1:]
    return vec + 2 * xp.cross(u, xp.cross(u, vec) + w * vec)


def to_heading_frame(vec_xy, heading):
    """A world-frame planar vector in the frame turned by `heading` (rad) about z."""
    xp = namespace(vec_xy)
    c, s = xp.cos(heading), xp.sin(heading)
    return xp.stack([c * vec_xy[0] + s * vec_xy[1], -s * vec_xy[0] + c * vec_xy[1]])
