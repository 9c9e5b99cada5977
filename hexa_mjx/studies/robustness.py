"""Robustness sweeps on native MuJoCo: one perturbation, or a grid of several, over their sizes.

    python -m hexa_mjx.studies.robustness policies/goal.onnx --sweep push --values 0 0.5 1 1.5 2 --out push.png
    python -m hexa_mjx.studies.robustness policies/goal.onnx --grid friction=0.4,1.25 mass=0.8,1.2 payload=0,1.5

Each value (or grid point) runs the same seeded episodes (`hexa_mjx.deploy.player`) with those quantities
changed and everything else nominal (no pushes, latency or noise, whatever the policy was trained
with): `push` (m/s, a kick every 3 s), `latency` (control steps), `noise` (observation noise
level), `friction` (coefficient), `mass` (every link's mass scale), `payload` (kg on the torso),
or a generated terrain (`hexa_mjx.mdp.terrain`, at `--terrain_seed`) of a size: `bumps` (m, bump height),
`slopes` (degrees) or `steps` (m, step height). It prints success and falls per value and plots
a single sweep; `--workers` runs episodes in that many processes.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import itertools
import json
import multiprocessing
import sys
from pathlib import Path

import numpy as np

from hexa_mjx.deploy import commands, player
from hexa_mjx.mdp import randomization, terrain
from hexa_mjx.tasks import TASKS

NOMINAL = randomization.Ranges(friction=(1.0, 1.0), mass_scale=(1.0, 1.0), payload=(0.0, 0.0), kp_scale=(1.0, 1.0),
                               force_scale=(1.0, 1.0), damping_scale=(1.0, 1.0), armature_scale=(1.0, 1.0))
CLEAN = {"push_speed": 0.0, "action_latency": 0.0, "obs_noise": 0.0, "leg_failure": "none"}  # no perturbation


@dataclasses.dataclass(frozen=True)
class Sweep:
    """A swept quantity: its units and what a value sets, an `EnvConfig` field or a fixed
    `randomization.Ranges` field; a terrain's value is a size up to `full` (its difficulty 1)."""

    units: str
    setting: str = ""
    range_field: str = ""
    terrain: str = ""
    full: float = 0.0


SWEEPS = {
    "push": Sweep("m/s", setting="push_speed"),
    "latency": Sweep("control steps", setting="action_latency"),
    "noise": Sweep("x Playground's levels", setting="obs_noise"),
    "friction": Sweep("", range_field="friction"),
    "mass": Sweep("x", range_field="mass_scale"),
    "payload": Sweep("kg", range_field="payload"),
    "bumps": Sweep("m", terrain="bumps", full=terrain.BUMP_HEIGHT),
    "slopes": Sweep("degrees", terrain="slopes", full=terrain.SLOPE_DEG),
    "steps": Sweep("m", terrain="steps", full=terrain.STEP_HEIGHT),
}


def settings(point: dict[str, float]) -> tuple[dict, randomization.Ranges | None]:
    """(EnvConfig overrides, fixed physics ranges or None) of a point {sweep name: value}."""
    overrides, ranges = {}, None
    for name, value in point.items():
        if name not in SWEEPS:
            raise ValueError(f"unknown sweep {name!r}; choose one of {sorted(SWEEPS)}")
        sweep = SWEEPS[name]
        if sweep.setting:
            overrides[sweep.setting] = value
        elif sweep.range_field:
            ranges = dataclasses.replace(ranges or NOMINAL, **{sweep.range_field: (value, value)})
            ranges.check()
        else:
            if "terrain" in overrides:
                raise ValueError(f"a point can have one terrain, got {sorted(point)}")
            if not 0 <= value <= sweep.full:
                raise ValueError(f"{name} sweeps sizes from 0 to {sweep.full:g} {sweep.units} "
                                 f"(hexa_mjx.mdp.terrain's full size), got {value:g}")
            overrides.update(terrain=sweep.terrain, terrain_difficulty=value / sweep.full)
    return overrides, ranges


def path_env(policy: player.OnnxPolicy, path, **overrides):
    """The native environment that walks `path` ((x, y) waypoints, m, from the start): a velocity
    policy through the path follower, a navigation policy given the waypoints, a drive policy
    through the follower or, with `goal_mode_share=1` among the overrides, given the waypoints in
    its goal mode; without a path, the policy's own environment."""
    task = TASKS.get(policy.metadata["env_config"].get("task"))  # None: env_for says what is wrong
    by_goals = task is not None and task.follows_waypoints and (
        not task.uses_command or overrides.get("goal_mode_share") == 1.0)
    if path is not None and task is not None and not (task.uses_command or by_goals):
        raise ValueError(f"{policy.path} is a {policy.metadata['task']} policy: a path is walked by a velocity "
                         "policy (through the path follower) or a navigation policy (its waypoints)")
    if path is not None and by_goals:
        overrides = {**overrides, "waypoints": path}
    elif path is not None and task is not None and task.follows_waypoints:  # drive: commands from the first step
        overrides = {**overrides, "goal_mode_share": 0.0}
    return player.env_for(policy, **overrides)


def _episodes(policy_path: str, overrides: dict, ranges, seeds: list[int], path=None) -> list[dict]:
    policy = player.OnnxPolicy(policy_path)
    env = path_env(policy, path, **overrides)
    if ranges is not None:
        env.ranges = ranges

    def follower():  # a fresh one per episode: the path from the start, ended at its last waypoint
        if path is None or env.config.waypoints:
            return None
        return commands.PathFollower(env.robot.start_xy + np.asarray(path), env.task.command_ranges,
                                     success_radius=env.config.success_radius, ends_episode=True)
    return [player.run_episode(policy, env, s, source=follower(), end_at_path=True) for s in seeds]


def run_conditions(policy_path: str, conditions: list[tuple[dict, object]], episodes: int, seed: int = 0,
                   workers: int = 1, path=None) -> list[dict]:
    """A summary (hexa_mjx.deploy.player.summarize) per condition (EnvConfig overrides, fixed physics
    ranges or None), each over the same seeded episodes, run in `workers` processes. With a `path`
    ((x, y) waypoints, m, from the start), a velocity policy walks it through the path follower and
    a navigation policy given its waypoints (path_env), each episode ended at the last waypoint."""
    policy = player.OnnxPolicy(policy_path)
    for overrides, _ in conditions:
        path_env(policy, path, **overrides)  # bad input fails here, before any episode runs
    chunk = max(1, -(-episodes // max(workers, 1)))
    jobs = [(i, overrides, ranges, list(range(seed + start, seed + min(episodes, start + chunk))))
            for i, (overrides, ranges) in enumerate(conditions) for start in range(0, episodes, chunk)]
    if workers > 1:
        # spawn, not fork: the caller may hold JAX's or onnxruntime's threads, which a fork copies mid-flight
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            results = list(pool.map(_episodes, *zip(*[(policy_path, o, r, s, path) for _, o, r, s in jobs])))
    else:
        results = [_episodes(policy_path, o, r, s, path) for _, o, r, s in jobs]
    return [player.summarize([e for (j, *_), result in zip(jobs, results) if j == i for e in result])
            for i in range(len(conditions))]


def evaluate_points(policy_path: str, points: list[dict], episodes: int, seed: int = 0, workers: int = 1,
                    **overrides) -> list[dict]:
    """A summary per point {sweep name: value}, with the point's values (run_conditions)."""
    conditions = []
    for point in points:
        setting, ranges = settings(point)
        conditions.append(({**CLEAN, **overrides, **setting}, ranges))
    summaries = run_conditions(policy_path, conditions, episodes, seed, workers)
    return [{**point, **summary} for point, summary in zip(points, summaries)]


def sweep(policy_path: str, name: str, values: list[float], episodes: int, seed: int = 0, workers: int = 1,
          **overrides) -> list[dict]:
    """A summary per value of sweep `name` (rows carry it as "value"); `settings` rejects an unknown name."""
    rows = evaluate_points(policy_path, [{name: v} for v in values], episodes, seed, workers, **overrides)
    return [{"value": row.pop(name), **row} for row in rows]


def parse_grid(items: list[str]) -> dict[str, list[float]]:
    """{"friction": [0.4, 1.25], ...} from ["friction=0.4,1.25", ...]."""
    grid = {}
    for item in items:
        name, _, values = item.partition("=")
        if name not in SWEEPS or not values:
            raise ValueError(f"--grid takes NAME=V1,V2,... with NAME one of {sorted(SWEEPS)}, got {item!r}")
        try:
            grid[name] = [float(v) for v in values.split(",")]
        except ValueError:
            raise ValueError(f"--grid {name}: values are numbers separated by commas, got {values!r}") from None
    return grid


def plot(rows: list[dict], name: str, out: Path, title: str = "") -> Path:
    """Success and falls against the swept value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hexa_mjx.evaluation.plots import save_figure

    fig, ax = plt.subplots(figsize=(5, 3.2), constrained_layout=True)
    values = [r["value"] for r in rows]
    ax.plot(values, [r["success_rate"] for r in rows], "o-", label="success")
    ax.plot(values, [1 - r["fall_rate"] for r in rows], "s--", label="no fall")
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel(f"{name} ({SWEEPS[name].units})" if SWEEPS[name].units else name)
    ax.grid(alpha=0.3)
    ax.legend()
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, out)


def table(rows: list[dict], names: list[str], headers: list[str] | None = None) -> str:
    """Markdown: the point's values (keys `names`, titled `headers`), success, falls, speed to the goal."""
    tracking = any(r.get("velocity_rms_mean") is not None for r in rows)  # a velocity policy
    last = "velocity RMS error" if tracking else "speed to the goal"
    lines = [f"| {' | '.join(headers or names)} | success | falls | {last} |", "|" + "---|" * (len(names) + 3)]
    for r in rows:
        figure = r["velocity_rms_mean"] if tracking else r["speed_to_first_goal"]
        lines.append(f"| {' | '.join(f'{r[n]:g}' for n in names)} | {r['success_rate']:.0%} | {r['fall_rate']:.0%} | "
                     f"{'-' if figure is None else f'{figure:.3f} m/s'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.robustness", description=__doc__.split("\n\n")[0])
    p.add_argument("policy", help="exported .onnx policy")
    p.add_argument("--sweep", choices=sorted(SWEEPS), help="one quantity, over --values")
    p.add_argument("--values", type=float, nargs="+")
    p.add_argument("--grid", nargs="+", default=None,
                   help="every combination of several, e.g. friction=0.4,1.25 mass=0.8,1.2 payload=0,1.5")
    p.add_argument("--episodes", type=int, default=64, help="per value or grid point")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=1, help="processes running episodes (one per core)")
    p.add_argument("--start_joint_noise", type=float, default=None, help="rad (default: the policy's training)")
    p.add_argument("--terrain", default=None, choices=terrain.KINDS,
                   help="ground of the sweeps that are not terrains (default: the policy's training ground)")
    p.add_argument("--terrain_seed", type=int, default=None,
                   help="seed of the terrains swept (default: the policy's training terrain's, 0)")
    p.add_argument("--out", default="", help="PNG plot to write (a sweep) and .json beside it")
    args = p.parse_args(argv)
    if args.episodes < 1 or args.workers < 1:
        p.error("--episodes and --workers must be at least 1")
    if (args.sweep is None) == (args.grid is None) or (args.sweep is not None) != (args.values is not None):
        p.error("give either --sweep NAME --values ... or --grid NAME=V1,V2 ...")
    where = dict(start_joint_noise=args.start_joint_noise, terrain=args.terrain, terrain_seed=args.terrain_seed)
    try:
        if args.grid is not None:
            grid = parse_grid(args.grid)
            names = list(grid)
            points = [dict(zip(names, combo)) for combo in itertools.product(*grid.values())]
            rows = evaluate_points(args.policy, points, args.episodes, args.seed, args.workers, **where)
        else:
            names = ["value"]
            rows = sweep(args.policy, args.sweep, args.values, args.episodes, args.seed, args.workers, **where)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(table(rows, names, None if args.grid is not None else [args.sweep]))
    if args.grid is not None:
        worst = min(rows, key=lambda r: r["success_rate"])
        print(f"worst point: {', '.join(f'{n}={worst[n]:g}' for n in names)}: {worst['success_rate']:.0%} success")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        if args.sweep:
            plot(rows, args.sweep, out, f"{Path(args.policy).name}, {args.episodes} episodes per value")
        out.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
