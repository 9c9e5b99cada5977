"""Command-line values shared by train.py, eval.py and play.py: waypoints, leg lists, negative numbers.

Imports neither JAX nor MuJoCo, so play.py stays light.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from hexa_mjx.mdp.config import EnvConfig

# The environment settings eval.py and play.py take, spelt as train.py spells them; unset, each
# keeps the run's (or the exported policy's) own value.
ENV_FLAGS = ("episode_length", "goal_distance", "goal_min_distance", "goal_max_distance", "goal_stay_share",
             "waypoints", "start_joint_noise", "start_yaw_noise", "max_contact_points", "push_speed", "push_interval",
             "action_latency", "obs_noise", "disabled_legs", "leg_failure", "leg_failure_rate",
             "leg_failure_pairs", "failure_mode", "terrain", "terrain_seed",
             "terrain_difficulty", "command_vx", "command_vy", "command_yaw_rate", "command_interval",
             "command_zero_share", "command_heading_share", "tracking_sigma", "yaw_tracking_sigma", "goal_mode_share")
TYPES = {"int": int, "float": float, "str": str, "tuple": str}


def add_env_flags(parser, names=ENV_FLAGS, unset: str = "the run's own") -> None:
    """One flag per EnvConfig setting in `names`, with its help and choices (default None: `unset`)."""
    fields = {f.name: f for f in dataclasses.fields(EnvConfig)}
    group = parser.add_argument_group("task and environment", "change the world the policy runs in; unset, each "
                                      "setting keeps the policy's own")
    for name in names:
        meta = dict(fields[name].metadata)
        kind = meta.pop("type", None) or TYPES[fields[name].type]
        if fields[name].type == "tuple" and "nargs" in meta:  # a range MIN MAX keeps its two values
            meta["metavar"] = ("MIN", "MAX")
        else:
            meta.pop("nargs", None)
        group.add_argument(f"--{name}", type=kind, default=None, **{**meta, "help": f"{meta['help']} (default: {unset})"})


def env_overrides(args, names=ENV_FLAGS) -> dict:
    """The EnvConfig settings given on the command line, parsed; fixed failed legs replace random ones."""
    out = {}
    for name in names:
        value = getattr(args, name)
        if value is None:
            continue
        if name == "waypoints":
            value = tuple(parse_waypoints(value))
        elif isinstance(value, list):
            value = tuple(value)
        elif name == "disabled_legs":
            value = parse_legs(value)
            out["leg_failure"] = "none"
        out[name] = value
    return out


# Options whose value may start with a minus sign: a waypoint at x < 0.
SIGNED_VALUES = ("--waypoints",)


def signed_values(argv: list[str], options=SIGNED_VALUES) -> list[str]:
    """`argv` with `--option -2,0` written `--option=-2,0`, so argparse takes the value for a value
    and not for an unknown option."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in options and i + 1 < len(argv) and argv[i + 1].startswith("-") and not argv[i + 1].startswith("--"):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def parse_waypoints(text: str) -> list[tuple[float, float]]:
    """Waypoints from "x,y x,y ..." (metres), or from a file holding that text (one or more lines)."""
    source = text
    if text and Path(text).is_file():
        source = Path(text).read_text()
    tokens = source.replace(";", " ").split()
    if not tokens:
        raise ValueError(f"no waypoints in {text!r}; give them as \"x,y x,y ...\" in metres, e.g. \"1,0 1,1 0,1 0,0\"")
    points = []
    for token in tokens:
        parts = token.split(",")
        try:
            x, y = (float(p) for p in parts)
        except ValueError:
            raise ValueError(f"waypoint {token!r} is not x,y in metres; give them as \"x,y x,y ...\", "
                             "e.g. \"1,0 1,1 0,1 0,0\"") from None
        if not (np.isfinite(x) and np.isfinite(y)):
            raise ValueError(f"waypoint {token!r} is not finite")
        points.append((x, y))
    return points


def parse_legs(text: str) -> tuple[int, ...]:
    """Leg numbers from "3" or "1 4" or "1,4"."""
    try:
        return tuple(int(x) for x in text.replace(",", " ").split())
    except ValueError:
        raise ValueError(f'--disabled_legs takes leg numbers from 1, like "3" or "1 4", got {text!r}') from None
