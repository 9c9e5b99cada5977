"""How a policy copes with a failed leg, on native MuJoCo: intact, each leg failed, opposite pairs.

    python -m hexa_mjx.studies.leg_failure_sweep policies/goal.onnx --episodes 64 --start_joint_noise 0.1 --out sweep.json

Each condition runs the same seeded episodes (`hexa_mjx.deploy.player`); the table gives success, falls,
speed to the first goal and that speed as a share of the intact robot's. Opposite legs are the
pairs whose hips sit diametrically across the torso.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import mujoco
import numpy as np

from hexa_mjx.deploy import player


def opposite_pairs(env) -> list[tuple[int, int]]:
    """Leg pairs (numbers from 1) whose hip axes point in opposite directions from the torso centre."""
    m, robot = env.mj_model, env.robot
    data = mujoco.MjData(m)
    data.qpos[:] = robot.qpos0
    mujoco.mj_forward(m, data)
    offsets = data.xanchor[robot.hips, :2] - data.qpos[:2]
    unit = offsets / np.linalg.norm(offsets, axis=1, keepdims=True)
    legs = len(robot.hips)
    return [(i + 1, j + 1) for i in range(legs) for j in range(i + 1, legs) if unit[i] @ unit[j] < -0.99]


def sweep(policy_path: str, episodes: int, seed: int = 0, workers: int = 1, **overrides) -> list[dict]:
    """Summaries (hexa_mjx.deploy.player.summarize) of each condition, with its failed legs and speed ratio."""
    from hexa_mjx.studies.robustness import CLEAN, run_conditions

    overrides = {**CLEAN, **overrides}  # only the failed legs change, whatever the policy was trained with
    env = player.env_for(player.OnnxPolicy(policy_path), **overrides)
    conditions = [()] + [(leg,) for leg in range(1, len(env.robot.legs) + 1)] + opposite_pairs(env)
    summaries = run_conditions(policy_path, [({**overrides, "disabled_legs": legs}, None) for legs in conditions],
                               episodes, seed, workers)
    rows = [{"failed_legs": list(legs), **summary} for legs, summary in zip(conditions, summaries)]
    intact = rows[0]["speed_to_first_goal"]
    for row in rows:
        speed = row["speed_to_first_goal"]
        row["speed_share_of_intact"] = speed / intact if speed and intact else None
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| failed legs | success | falls | speed to the goal | share of intact speed |", "|---|---|---|---|---|"]
    for r in rows:
        speed, share = r["speed_to_first_goal"], r["speed_share_of_intact"]
        lines.append(f"| {' + '.join(map(str, r['failed_legs'])) or 'none'} | {r['success_rate']:.0%} | "
                     f"{r['fall_rate']:.0%} | {'-' if speed is None else f'{speed:.3f} m/s'} | "
                     f"{'-' if share is None else f'{share:.0%}'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.leg_failure_sweep", description=__doc__.split("\n\n")[0])
    p.add_argument("policy", help="exported .onnx policy")
    p.add_argument("--episodes", type=int, default=64, help="episodes per condition")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--start_joint_noise", type=float, default=None, help="rad (default: the policy's training)")
    p.add_argument("--failure_mode", default="limp", choices=["limp", "locked"])
    p.add_argument("--workers", type=int, default=1, help="processes that share the episodes")
    p.add_argument("--out", default="", help="write the rows as JSON here")
    args = p.parse_args(argv)
    if args.episodes < 1 or args.workers < 1:
        p.error("--episodes and --workers must be at least 1")
    try:
        rows = sweep(args.policy, args.episodes, args.seed, args.workers, start_joint_noise=args.start_joint_noise,
                     failure_mode=args.failure_mode)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(table(rows))
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
