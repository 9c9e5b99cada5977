"""Walk a path two ways on native MuJoCo, side by side: a velocity policy through the path
follower (hexa_mjx.deploy.commands.PathFollower) and a navigation policy given the waypoints.

    python -m hexa_mjx.studies.path_following policies/velocity.onnx policies/navigate.onnx --episodes 32

Each path runs the same seeded starts (random heading and joint noise, each policy's own) for
both. A waypoint counts when the torso comes within the navigation task's success radius (0.5 m)
of it, in order; the path is completed when the last one counts. Figures per path and policy:
paths completed, time to complete, the largest distance of the torso from the straight segments
(hexa_mjx.evaluation.nav_metrics.waypoint_summary), and falls.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from hexa_mjx.deploy import commands, player
from hexa_mjx.evaluation import nav_metrics
from hexa_mjx.studies.robustness import path_env

PATHS = {"square": [(2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)],
         "zigzag": [(1.0, 0.5), (2.0, -0.5), (3.0, 0.5), (4.0, -0.5)]}


def compare(velocity_path: str, navigate_path: str, paths: dict, episodes: int, seed: int = 0,
            speed: float = 0.5, episode_length: int = 3000) -> dict:
    """Per path: the follower's and the navigation policy's waypoint figures."""
    out = {}
    for name, points in paths.items():
        out[name] = {}
        for label, path in (("velocity + follower", velocity_path), ("navigation", navigate_path)):
            policy = player.OnnxPolicy(path)
            env = path_env(policy, points, episode_length=episode_length)
            follow = env.task.uses_command
            runs = []
            for i in range(episodes):
                source = None
                if follow:
                    source = commands.PathFollower(env.robot.start_xy + np.asarray(points), env.task.command_ranges,
                                                   speed=speed, success_radius=env.config.success_radius)
                episode = player.run_episode(policy, env, seed + i, record=True, source=source)
                runs.append((episode["trajectory"]["qpos"], episode["trajectory"]["reached"], episode["fell"]))
            steps = max(len(q) for q, _, _ in runs) - 1
            qpos = np.zeros((steps, episodes, env.mj_model.nq))
            completed, alive = np.zeros((steps, episodes)), np.zeros((steps, episodes))
            for i, (q, reached, _) in enumerate(runs):
                n = len(q) - 1
                qpos[:n, i], alive[:n, i] = q[1:], 1.0
                completed[:n, i] = np.diff(reached) > 0
            start = np.array([q[0] for q, _, _ in runs])
            summary = nav_metrics.waypoint_summary(start, qpos, completed, alive, [f for _, _, f in runs],
                                                   points, env.dt)
            done = [a[-1] for a, ok in zip(summary["per_episode"]["arrival_s"], summary["per_episode"]["completed"])
                    if ok]
            out[name][label] = {"completed_rate": summary["completed_rate"], "fall_rate": summary["fall_rate"],
                                "time_s_median": float(np.median(done)) if done else None,
                                "max_deviation_median": summary["max_deviation_median"],
                                "max_deviation_mean": summary["max_deviation_mean"]}
    return out


def table(result: dict) -> str:
    """Markdown: one row per path and policy."""
    lines = ["| path | policy | completed | time, median | largest deviation, median (mean) | falls |",
             "|---|---|---|---|---|---|"]
    for name, rows in result.items():
        for label, r in rows.items():
            time = "-" if r["time_s_median"] is None else f"{r['time_s_median']:.1f} s"
            lines.append(f"| {name} | {label} | {r['completed_rate']:.0%} | {time} | "
                         f"{r['max_deviation_median']:.2f} m ({r['max_deviation_mean']:.2f} m) | {r['fall_rate']:.0%} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.path_following", description=__doc__.split("\n\n")[0])
    p.add_argument("velocity", help="exported velocity-task policy (.onnx)")
    p.add_argument("navigate", help="exported navigation-task policy (.onnx)")
    p.add_argument("--episodes", type=int, default=32, help="per path and policy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--speed", type=float, default=0.5, help="m/s, the follower's cruising speed")
    p.add_argument("--episode_length", type=int, default=3000, help="control steps (50 s at 60 Hz)")
    p.add_argument("--paths", nargs="+", default=list(PATHS), choices=list(PATHS))
    p.add_argument("--json", default="", help="write the figures here")
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error("--episodes must be at least 1")
    try:
        result = compare(args.velocity, args.navigate, {k: PATHS[k] for k in args.paths}, args.episodes, args.seed,
                         args.speed, args.episode_length)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(table(result))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
