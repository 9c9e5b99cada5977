"""How wide each drive mode's rewards and PPO advantages spread, on a checkpoint's own rollout.

PPO normalizes the advantages over a whole batch, goal-mode and command-mode steps together; a
mode whose advantages spread narrower gets a smaller share of every gradient step. This rolls the
checkpoint's stochastic policy out in its own training environment (its failures, terrain and
physics settings), computes brax's GAE advantages with its value network, and prints each mode's
spread, with the `--command_mode_gain` that would make the two spreads equal.

    python -m hexa_mjx.studies.mode_advantages runs/drive-s0/best --envs 128 --steps 400
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def spreads(ckpt: str | Path, envs: int = 128, steps: int = 400, seed: int = 1) -> dict:
    """Per mode ("goal", "command"): its share of the steps, the mean and std of its scaled
    per-step reward and of its GAE advantages; "gain": command_mode_gain times the two advantage
    stds' ratio (goal over command)."""
    import jax
    from brax.envs import training as brax_training
    from brax.training import acting
    from brax.training.agents.ppo import losses as ppo_losses

    from hexa_mjx.tasks import drive
    from hexa_mjx.training import checkpoints, config, networks

    run_dir, ckpt_dir = checkpoints.resolve_checkpoint(Path(ckpt))
    cfg = config.load_config(run_dir)
    if cfg.task != "drive":
        raise SystemExit(f"{ckpt} is a {cfg.task} policy; this study splits a drive policy's steps by mode")
    if cfg.privileged_critic:
        raise SystemExit(f"{ckpt} has a privileged critic, whose value network reads its own observation; this "
                         "study computes advantages with a critic that reads the policy's")
    env = config.make_env_for(cfg)
    _, params = checkpoints.load_checkpoint(ckpt_dir, networks.init_params(cfg, env))
    policy = networks.policy_maker(cfg, env)(params, deterministic=False)
    value = networks.make_networks(cfg, env).value_network
    wrapped = brax_training.wrap(env, episode_length=cfg.episode_length, action_repeat=1)
    state = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(seed), envs))
    _, data = jax.jit(lambda s, k: acting.generate_unroll(wrapped, s, policy, k, steps, extra_fields=("truncation",)))(
        state, jax.random.PRNGKey(seed + 1))
    truncation = data.extras["state_extras"]["truncation"]
    _, advantages = ppo_losses.compute_gae(
        truncation=truncation, termination=(1 - data.discount) * (1 - truncation),
        rewards=data.reward * cfg.reward_scaling, values=value.apply(params[0], params[2], data.observation),
        bootstrap_value=value.apply(params[0], params[2], data.next_observation[-1]),
        lambda_=cfg.gae_lambda, discount=cfg.discount)
    mode_at = drive.DriveTask.layout(env.action_size)[-1][0]
    goal_mode = np.asarray(data.observation[..., mode_at]) > 0.5
    reward, advantages = np.asarray(data.reward * cfg.reward_scaling), np.asarray(advantages)
    out = {}
    for name, mask in (("goal", goal_mode), ("command", ~goal_mode)):
        out[name] = {"share": float(mask.mean()), "reward_mean": float(reward[mask].mean()),
                     "reward_std": float(reward[mask].std()), "advantage_mean": float(advantages[mask].mean()),
                     "advantage_std": float(advantages[mask].std())}
    out["gain"] = cfg.command_mode_gain * out["goal"]["advantage_std"] / out["command"]["advantage_std"]
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("ckpt", help="a drive run's checkpoint: RUN/best, RUN or RUN/checkpoints/STEP")
    parser.add_argument("--envs", type=int, default=128, help="environments rolled out at once")
    parser.add_argument("--steps", type=int, default=400, help="control steps each")
    parser.add_argument("--seed", type=int, default=1, help="the rollout's seed")
    args = parser.parse_args(argv)
    if args.envs < 2 or args.steps < 2:
        parser.error("--envs and --steps must be at least 2")
    result = spreads(args.ckpt, args.envs, args.steps, args.seed)
    print(f"{'mode':8} {'share':>6} {'reward mean':>12} {'reward std':>11} {'advantage std':>14}")
    for name in ("goal", "command"):
        r = result[name]
        print(f"{name:8} {r['share']:6.2f} {r['reward_mean']:12.4f} {r['reward_std']:11.4f} {r['advantage_std']:14.3f}")
    print(f"command_mode_gain that equals the advantage spreads: {result['gain']:.2f}")


if __name__ == "__main__":
    main()
