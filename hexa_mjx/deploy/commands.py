"""Velocity commands for a velocity-task policy outside the trainer: a schedule from a file, the
viewer's keyboard, and a path follower that turns waypoints into commands (NumPy only).

A command is (vx, vy, yaw rate): m/s forward and left in the robot's heading frame, rad/s
counter-clockwise. Each source is a callable `source(t, env) -> command` that play.py calls
before every control step; the command is clipped to the ranges the policy was trained on.

Schedule files (docs/DEPLOYMENT.md): rows of (time s, vx, vy, yaw rate), times increasing from 0
or later; each command holds from its time until the next row's (zero before the first row).
- CSV: one row per line, comma-separated; an optional header `t,vx,vy,yaw_rate`; `#` comments.
- JSON: a list of [t, vx, vy, yaw_rate] rows or of {"t": ..., "vx": ..., "vy": ..., "yaw_rate": ...}.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hexa_mjx.evaluation.nav_metrics import segment_distance
from hexa_mjx.robot.kinematics import to_heading_frame, yaw

FIELDS = ("t", "vx", "vy", "yaw_rate")


def load_schedule(path: str | Path) -> np.ndarray:
    """A command schedule file as an array of (t, vx, vy, yaw rate) rows; ValueError that says
    what is wrong and how the file should look."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"command schedule {path} not found; give a CSV or JSON file of (t, vx, vy, yaw_rate) rows")
    text = path.read_text()
    how = ("write one row per command: t,vx,vy,yaw_rate (s, m/s, m/s, rad/s), e.g. \"0,0.5,0,0\", or a JSON list "
           "of such rows")
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(text)
            if not isinstance(doc, list):
                raise ValueError("the JSON is not a list of rows")
            rows = [[row[k] for k in FIELDS] if isinstance(row, dict) else list(row) for row in doc]
        else:
            lines = [line.split("#")[0].strip() for line in text.splitlines()]
            lines = [line for line in lines if line]
            if lines and lines[0].replace(" ", "").lower() == ",".join(FIELDS):
                lines = lines[1:]
            rows = [[float(x) for x in line.split(",")] for line in lines]
        table = np.array(rows, float)
    except (ValueError, KeyError, TypeError, json.JSONDecodeError) as e:
        raise ValueError(f"command schedule {path} cannot be read ({e}); {how}") from None
    if table.ndim != 2 or table.shape[1] != 4 or len(table) == 0:
        raise ValueError(f"command schedule {path} needs rows of 4 values (t, vx, vy, yaw_rate); {how}")
    if not np.all(np.isfinite(table)):
        raise ValueError(f"command schedule {path} holds a value that is not a finite number")
    if table[0, 0] < 0 or np.any(np.diff(table[:, 0]) <= 0):
        raise ValueError(f"command schedule {path}: the times must start at 0 s or later and increase row by row")
    return table


def clip_command(command, ranges) -> np.ndarray:
    """`command` (vx, vy, yaw rate) within `ranges` ((min, max) of each)."""
    return np.array([np.clip(c, lo, hi) for c, (lo, hi) in zip(command, ranges)])


class Schedule:
    """Commands from a schedule table (load_schedule): each row's command from its time on."""

    def __init__(self, table: np.ndarray):
        self.table = np.asarray(table, float)

    @property
    def duration(self) -> float:
        """s, the last row's time."""
        return float(self.table[-1, 0])

    def __call__(self, t: float, env=None) -> np.ndarray:
        row = np.searchsorted(self.table[:, 0], t + 1e-9, side="right") - 1
        return np.zeros(3) if row < 0 else self.table[row, 1:].copy()


# Viewer keys (GLFW key codes) -> change of (vx m/s, vy m/s, yaw rate rad/s); space stops.
KEY_STEPS = {265: (0.1, 0, 0), 87: (0.1, 0, 0), 264: (-0.1, 0, 0), 83: (-0.1, 0, 0),  # up/W, down/S
             263: (0, 0.1, 0), 65: (0, 0.1, 0), 262: (0, -0.1, 0), 68: (0, -0.1, 0),  # left/A, right/D
             81: (0, 0, 0.25), 69: (0, 0, -0.25)}  # Q turns left, E right
STOP_KEY = 32  # space


class Keyboard:
    """A command held and changed by key presses (KEY_STEPS, STOP_KEY), within `ranges`."""

    def __init__(self, ranges):
        self.ranges, self.command = ranges, np.zeros(3)

    def press(self, key: int) -> bool:
        """Apply a key; whether it was one of the driving keys."""
        if key == STOP_KEY:
            self.command = np.zeros(3)
        elif key in KEY_STEPS:
            self.command = np.round(clip_command(self.command + np.array(KEY_STEPS[key]), self.ranges), 6)
        else:
            return False
        return True

    def __call__(self, t: float, env=None) -> np.ndarray:
        return self.command.copy()


class PathFollower:
    """Pure pursuit on commands: walk toward the point `lookahead` m along the path from the torso's
    nearest point on it, at `speed` m/s slowing over the last `slow_within` m, turned by
    `turn_gain` toward the direction of travel; stand still within `stop_within` m of the end.
    Waypoints are world (x, y), m; the path starts at the torso's position at `reset`. With
    `ends_episode`, `finished` turns true once the last waypoint counts (player.run_episode stops
    there); otherwise the robot stands at the end until the episode's time runs out."""

    def __init__(self, waypoints, ranges, speed: float = 0.5, lookahead: float = 0.4, turn_gain: float = 1.5,
                 slow_within: float = 0.5, stop_within: float = 0.1, success_radius: float = 0.5,
                 ends_episode: bool = False):
        self.ends_episode = ends_episode
        self.waypoints = np.asarray(waypoints, float).reshape(-1, 2)
        self.ranges, self.speed, self.lookahead, self.turn_gain = ranges, speed, lookahead, turn_gain
        self.slow_within, self.stop_within, self.success_radius = slow_within, stop_within, success_radius
        self.corners, self.segment, self.reached = None, 0, 0

    def reset(self, start_xy) -> None:
        self.corners = np.vstack([np.asarray(start_xy, float)[None], self.waypoints])
        self.segment, self.reached = 0, 0

    @property
    def completed(self) -> bool:
        """Whether every waypoint has counted."""
        return self.reached == len(self.waypoints)

    @property
    def finished(self) -> bool:
        """Whether the episode should end here: the path completed, with `ends_episode`."""
        return self.ends_episode and self.completed

    @property
    def goal(self) -> np.ndarray:
        """The waypoint walked to now (the last once all are reached)."""
        return self.waypoints[min(self.reached, len(self.waypoints) - 1)]

    def __call__(self, t: float, env) -> np.ndarray:
        qpos = env.data.qpos
        xy, heading = qpos[:2].copy(), float(yaw(qpos[3:7]))
        if self.corners is None:
            self.reset(xy)
        # Waypoints count as reached in order, within success_radius (as the navigation task's).
        while self.reached < len(self.waypoints) and np.linalg.norm(self.waypoints[self.reached] - xy) < self.success_radius:
            self.reached += 1
        # Segments are walked in order: the next one takes over once it is the nearer. A path that
        # closes where it starts puts the robot as near its last segment as its first; choosing the
        # nearest of all the later ones jumped to the end on a drift at the start and stood there.
        a, b = self.corners[:-1], self.corners[1:]
        following = min(self.segment + 1, len(a) - 1)
        dist = segment_distance(np.repeat(xy[None], 2, 0), a[[self.segment, following]], b[[self.segment, following]])
        if dist[1] < dist[0]:
            self.segment = following
        target = self._along(xy, self.lookahead)
        remaining = self._remaining(xy)
        if remaining < self.stop_within:
            return np.zeros(3)
        direction = target - xy
        speed = self.speed * min(1.0, remaining / self.slow_within)
        velocity = speed * direction / max(np.linalg.norm(direction), 1e-9)
        error = np.arctan2(direction[1], direction[0]) - heading
        turn = self.turn_gain * np.arctan2(np.sin(error), np.cos(error))
        return clip_command([*to_heading_frame(velocity, heading), turn], self.ranges)

    def _projection(self, xy):
        a, b = self.corners[self.segment], self.corners[self.segment + 1]
        ab = b - a
        return float(np.clip((xy - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)) * np.linalg.norm(ab)

    def _along(self, xy, ahead: float) -> np.ndarray:
        """The point `ahead` m along the path from the torso's projection on its segment."""
        k, s = self.segment, self._projection(xy) + ahead
        while k < len(self.corners) - 1:
            length = np.linalg.norm(self.corners[k + 1] - self.corners[k])
            if s <= length:
                return self.corners[k] + (self.corners[k + 1] - self.corners[k]) * s / max(length, 1e-12)
            s, k = s - length, k + 1
        return self.corners[-1]

    def _remaining(self, xy) -> float:
        """m of path left from the torso's projection to the end (plus the offset at the end)."""
        k = self.segment
        rest = sum(np.linalg.norm(self.corners[j + 1] - self.corners[j]) for j in range(k + 1, len(self.corners) - 1))
        length = np.linalg.norm(self.corners[k + 1] - self.corners[k])
        if k == len(self.corners) - 2:
            return float(np.linalg.norm(self.corners[-1] - xy))
        return float(length - self._projection(xy) + rest)
