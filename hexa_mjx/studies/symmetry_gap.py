"""How differently a policy acts when its legs are relabelled by a turn of the torso: the mirror
loss of `hexa_mjx.training.symmetry` at weight 1, on the observations of the policy's own
deterministic episodes in its run's environment (0 for a policy that acts alike under every turn).

    python -m hexa_mjx.studies.symmetry_gap policies/generalist_start --episodes 32
"""

from __future__ import annotations

import argparse
import dataclasses
import types
from pathlib import Path

import jax
import jax.numpy as jp


def symmetry_gap(ckpt: str | Path, episodes: int = 32, steps: int = 150, every: int = 5, turns: int = 6,
                 seed: int = 0) -> float:
    """The mirror loss of the checkpoint at `ckpt` (a run directory or one checkpoint folder) on
    every `every`-th observation of `episodes` episodes of `steps` control steps."""
    from hexa_mjx.training import symmetry
    from hexa_mjx.training.checkpoints import load_checkpoint, resolve_checkpoint
    from hexa_mjx.training.config import load_config, make_env_for
    from hexa_mjx.training.critic import actor_params
    from hexa_mjx.training.networks import init_params, make_inference, make_networks

    run_dir, checkpoint = resolve_checkpoint(Path(ckpt))
    cfg = load_config(run_dir)
    env = make_env_for(cfg)
    _, params = load_checkpoint(checkpoint, init_params(cfg, env))
    act, step = jax.jit(make_inference(cfg, env, params)), jax.jit(jax.vmap(env.step))
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(seed), episodes))
    seen = []
    for t in range(steps):
        state = step(state, act(state.obs, jax.random.PRNGKey(t)))
        if t % every == 0:
            seen.append(state.obs)
    normalizer, policy, _ = actor_params(params)
    network = make_networks(dataclasses.replace(cfg, privileged_critic=False), env)
    loss = symmetry.mirror_loss(network, 1.0, *symmetry.maps_for(env, turns))
    return float(loss(types.SimpleNamespace(policy=policy), normalizer, jp.stack(seen)))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("ckpt", help="a run directory (its latest checkpoint) or one checkpoint folder")
    parser.add_argument("--episodes", type=int, default=32, help="episodes rolled out, deterministic policy")
    parser.add_argument("--steps", type=int, default=150, help="control steps per episode")
    parser.add_argument("--turns", type=int, default=6, help="equal turns the legs are relabelled by (6: every leg)")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.steps < 1:
        parser.error("--episodes and --steps must be at least 1")
    gap = symmetry_gap(args.ckpt, args.episodes, args.steps, turns=args.turns)
    print(f"mirror loss (mean squared gap of the mean action, {args.turns - 1} turns): {gap:.3f}")


if __name__ == "__main__":
    main()
