"""The policy's action noise: the std of its Gaussian, read from a run's checkpoints.

    python -m hexa_mjx.evaluation.action_noise runs/goal_directed-s0 [more run directories]

The actor's std is one learned parameter per joint, independent of the state (CleanRL's actor,
hexa_mjx.training.networks.network_factory); it starts at --init_noise_std and PPO moves it. Evaluation
uses the mean action, but training rolls out with this noise (docs/RESULTS.md, "The fast preset's finish").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax
import numpy as np


def action_noise_std(params) -> np.ndarray:
    """Per-action std of the actor in (normalizer, policy, value) `params` ("normal" policies)."""
    policy = params[1]["params"]
    if "std_logparam" not in policy:
        raise ValueError("this policy's std depends on the state (brax's tanh_normal); only --policy_dist normal "
                         "has one std per action")
    return np.exp(np.asarray(jax.tree.leaves(policy["std_logparam"])[0], np.float64))


def run_noise(run_dir: Path) -> list[tuple[int, float]]:
    """(step, mean std over actions) of every complete checkpoint of `run_dir`, oldest first."""
    from hexa_mjx.training import checkpoints, config, networks

    cfg = config.load_config(run_dir)
    template = networks.init_params(cfg, config.make_env_for(cfg))
    return [(step, float(action_noise_std(checkpoints.load_checkpoint(path, template)[1]).mean()))
            for step, path in checkpoints.list_checkpoints(run_dir)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.evaluation.action_noise", description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories")
    args = parser.parse_args(argv)
    for run_dir in args.runs:
        if not (run_dir / "config.json").is_file():
            print(f"error: {run_dir} is not a run directory (no config.json)", file=sys.stderr)
            return 2
    for run_dir in args.runs:
        rows = run_noise(run_dir)
        print(f"{run_dir}: " + ("no checkpoints" if not rows else
                                "  ".join(f"{step / 1e6:.2f}M {std:.3f}" for step, std in rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
