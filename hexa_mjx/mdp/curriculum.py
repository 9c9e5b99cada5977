"""The curriculum: goals near and ahead first, widened per environment as it succeeds; harder ground.

In the style of legged_gym's terrain curriculum, each training environment has a difficulty
level, kept in `state.info["level"]` across its episodes (brax's auto-reset carries `info` over).
With `curriculum_levels` = N, an environment at level l (0 to N-1) draws goals over a fraction
(l + 1) / N of the full ranges: bearings within +-180 deg x that fraction of its heading, and
distances from the range's start up to that fraction of the way to its end. Level N-1 is the
full task. Each goal reached moves the environment up one level; an episode that ends in a fall,
or without reaching any goal, moves it down one. Every environment starts at level 0.

The velocity task has no goals: on a terrain its level grades the ground only; on flat ground it
opens a share (l + 1) / N of each command range about zero (legged_gym's command curriculum). Its
level moves by the commanded path walked, as legged_gym's terrain curriculum: up one for an
episode that lasts its full length and walks at least half of it, down one for a fall or less
than a quarter (`VelocityTask.level_moves`).
Each task says how its levels move (`Task.level_moves`).

Evaluation always uses the full ranges: the curriculum is a setting of the training environment
only. Each evaluation row says how the training environments are spread over the levels
(`level_summary`, read by the host between updates).
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.robot.kinematics import namespace


def range_fraction(level, levels: int):
    """The fraction of the full bearing and distance ranges open at `level` (1 without a curriculum)."""
    if not levels:
        return 1.0
    return (level + 1) / levels


def next_level(level, levels: int, up, down):
    """One environment's level after a step: +1 where `up`, -1 where `down` (the task's
    `level_moves`), kept within [0, levels - 1]."""
    xp = namespace(level)
    change = up.astype(xp.int32) - down.astype(xp.int32)
    return xp.clip(level + change, 0, levels - 1)


def level_summary(levels, n_levels: int) -> dict:
    """{"curriculum/level_mean", "curriculum/top_level_share", "curriculum/level_<l>"}: the shares of
    the training environments at each level, from their `info["level"]` (any shape)."""
    counts = np.bincount(np.asarray(levels).ravel(), minlength=n_levels).astype(float)
    share = counts / counts.sum()
    return {"curriculum/level_mean": float(share @ np.arange(n_levels)),
            "curriculum/top_level_share": float(share[-1]),
            **{f"curriculum/level_{level}": float(x) for level, x in enumerate(share)}}
