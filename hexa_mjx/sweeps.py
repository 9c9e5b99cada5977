"""Robustness sweeps on native MuJoCo: one perturbation at a time, over a grid of sizes.

    python -m hexa_mjx.sweeps policies/goal.onnx --sweep push --values 0 0.5 1 1.5 2 --out push.png

Each value runs the same seeded episodes (`hexa_mjx.player`) with one quantity changed and
everything else nominal (no pushes, latency or noise, whatever the policy was trained with): `push` (m/s, a kick every 3 s), `latency` (control steps), `noise`
(observation noise level), `friction` (coefficient), `mass` (every link's mass scale) or
`payload` (kg on the torso). It prints success and falls per value and plots them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from hexa_mjx import player, randomization

NOMINAL = randomization.Ranges(friction=(1.0, 1.0), mass_scale=(1.0, 1.0), payload=(0.0, 0.0), kp_scale=(1.0, 1.0),
                               force_scale=(1.0, 1.0), damping_scale=(1.0, 1.0), armature_scale=(1.0, 1.0))
CLEAN = {"push_speed": 0.0, "action_latency": 0.0, "obs_noise": 0.0, "leg_failure": "none"}  # no perturbation
SWEEPS = {  # name: (units, how a value sets the environment)
    "push": ("m/s", lambda v: {"push_speed": v}),
    "latency": ("control steps", lambda v: {"action_latency": v}),
    "noise": ("x Playground's levels", lambda v: {"obs_noise": v}),
    "friction": ("", lambda v: {"ranges": dataclasses.replace(NOMINAL, friction=(v, v))}),
    "mass": ("x", lambda v: {"ranges": dataclasses.replace(NOMINAL, mass_scale=(v, v))}),
    "payload": ("kg", lambda v: {"ranges": dataclasses.replace(NOMINAL, payload=(v, v))}),
}


def sweep(policy_path: str, name: str, values: list[float], episodes: int, seed: int = 0, **overrides) -> list[dict]:
    """A summary (hexa_mjx.player.summarize) per value of sweep `name`."""
    if name not in SWEEPS:
        raise ValueError(f"unknown sweep {name!r}; choose one of {sorted(SWEEPS)}")
    policy = player.OnnxPolicy(policy_path)
    rows = []
    for value in values:
        setting = SWEEPS[name][1](value)
        ranges = setting.pop("ranges", None)
        env = player.env_for(policy, **{**CLEAN, **overrides, **setting})
        if ranges is not None:
            ranges.check()
            env.ranges = ranges
        rows.append({"value": value, **player.summarize([player.run_episode(policy, env, seed + i)
                                                          for i in range(episodes)])})
    return rows


def plot(rows: list[dict], name: str, out: Path, title: str = "") -> Path:
    """Success and falls against the swept value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hexa_mjx.plots import save_figure

    fig, ax = plt.subplots(figsize=(5, 3.2), constrained_layout=True)
    values = [r["value"] for r in rows]
    ax.plot(values, [r["success_rate"] for r in rows], "o-", label="success")
    ax.plot(values, [1 - r["fall_rate"] for r in rows], "s--", label="no fall")
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel(f"{name} ({SWEEPS[name][0]})" if SWEEPS[name][0] else name)
    ax.grid(alpha=0.3)
    ax.legend()
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hexa_mjx.sweeps", description=__doc__.split("\n\n")[0])
    p.add_argument("policy", help="exported .onnx policy")
    p.add_argument("--sweep", required=True, choices=sorted(SWEEPS))
    p.add_argument("--values", type=float, nargs="+", required=True)
    p.add_argument("--episodes", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--start_joint_noise", type=float, default=None, help="rad (default: the policy's training)")
    p.add_argument("--out", default="", help="PNG plot to write (and .json beside it)")
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error("--episodes must be at least 1")
    try:
        rows = sweep(args.policy, args.sweep, args.values, args.episodes, args.seed,
                     start_joint_noise=args.start_joint_noise)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"| {args.sweep} | success | falls | speed to the goal |\n|---|---|---|---|")
    for r in rows:
        speed = r["speed_to_first_goal"]
        print(f"| {r['value']:g} | {r['success_rate']:.0%} | {r['fall_rate']:.0%} | "
              f"{'-' if speed is None else f'{speed:.3f} m/s'} |")
    if args.out:
        out = Path(args.out)
        plot(rows, args.sweep, out, f"{Path(args.policy).name}, {args.episodes} episodes per value")
        out.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
