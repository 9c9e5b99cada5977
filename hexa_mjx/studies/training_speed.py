"""Training speed: end-to-end PPO env steps/s, and one update's time by part (physics, contacts,
policy inference, SGD), timed with the training loop's own functions (hexa_mjx.training.ppo).

`python -m hexa_mjx.studies.benchmark --train` and `--profile` print these figures.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jp
import mujoco

from hexa_mjx.studies.benchmark import rollout_fn, timed
from hexa_mjx.training import config


def train_speed(num_envs: int = 256, updates: int = 4, devices: int = 1, **overrides) -> dict:
    """End-to-end PPO env steps/s (train.py's settings, no evaluations) and compile time on `devices`.
    Three training epochs of `updates` updates: the first compiles, the last is timed."""
    from hexa_mjx.training import networks, ppo, loop as training

    cfg = config.TrainConfig(num_envs=num_envs, **overrides)
    env = config.make_env_for(cfg)
    marks = [(0, time.perf_counter())]
    ppo.train(env, training.ppo_settings(cfg, 3 * updates * cfg.steps_per_update, 4, cfg.seed, devices),
              networks.network_factory(cfg), wrap_env_fn=training.wrap_env_fn(env),
              on_interval=lambda step, *_: marks.append((step, time.perf_counter())) if step else None)
    (s1, t1), (s2, t2) = marks[-2:]
    epoch_s = t2 - t1
    return {"train_steps_per_s": (s2 - s1) / epoch_s, "compile_s": (marks[-3][1] - marks[0][1]) - epoch_s,
            "update_s": epoch_s / updates}


def _without_contacts(env):
    """A copy of `env` whose physics skips collision detection and contact forces."""
    import copy

    model = copy.copy(env.mj_model)
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return env.with_physics(model)


def training_profile(num_envs: int = 256, repeats: int = 3, **overrides) -> dict:
    """Seconds per PPO update on one device, by part: physics without contacts, contacts, policy
    inference while acting, and the SGD epochs, each timed alone with train.py's settings
    (`overrides` set other TrainConfig fields)."""
    from brax import envs
    from brax.training.agents.ppo import losses as ppo_losses
    from brax.training.agents.ppo import networks as ppo_networks

    from hexa_mjx.training import loop as training, networks, optimizer_state, ppo, ppo_update

    cfg = config.TrainConfig(num_envs=num_envs, **overrides)
    env = config.make_env_for(cfg)
    steps = cfg.steps_per_update // num_envs  # control steps per env per update
    keys = jax.random.split(jax.random.PRNGKey(0), num_envs)

    out = {}
    for name, e in (("env", env), ("env_without_contacts", _without_contacts(env))):
        wrapped = envs.training.wrap(e, episode_length=cfg.episode_length)  # batched, as PPO steps it
        run = rollout_fn(wrapped.step, env.action_size, steps)
        out[name] = timed(run, (jax.jit(wrapped.reset)(keys), jax.random.PRNGKey(1)), repeats)[1]

    # Acting and the SGD epochs of one update, with the training loop's own functions
    # (hexa_mjx.training.ppo_update), on one device under pmap as training runs them.
    settings = training.ppo_settings(cfg, cfg.steps_per_update, 2, cfg.seed, devices=1)
    wrapped = envs.training.wrap(env, episode_length=cfg.episode_length)
    nets = networks.make_networks(cfg, env)
    normalizer, policy_params, value_params = networks.init_params(cfg, env)
    params = ppo_losses.PPONetworkParams(policy=policy_params, value=value_params)
    rollout = ppo_update.rollout_fn(wrapped, ppo_networks.make_inference_fn(nets), settings)
    optimizer = optimizer_state.make_optimizer(settings)
    sgd = ppo_update.sgd_fn(nets, optimizer, settings)
    one = jax.local_devices()[:1]

    def replicate(tree):
        return ppo.replicate(tree, one)

    act = jax.pmap(lambda state, key, p: rollout((normalizer, p.policy, p.value), state, key)[1],
                   axis_name=ppo_update.AXIS)
    state0 = jax.tree.map(lambda x: x[None], jax.jit(wrapped.reset)(keys))
    _, out["acting"], data = timed(act, (state0, replicate(jax.random.PRNGKey(1)), replicate(params)), repeats)
    learn = jax.pmap(lambda o, p, d, k: sgd(o, p, normalizer, d, k)[1], axis_name=ppo_update.AXIS)
    out["sgd"] = timed(learn, (replicate(optimizer.init(params)), replicate(params), data,
                                replicate(jax.random.PRNGKey(2))), repeats)[1]
    out["sgd_flop"] = sgd_flop(cfg, env)
    out["matmul_flop_per_s"] = matmul_speed(cfg.batch_size * cfg.unroll_length, cfg.hidden[-1], repeats)
    return out


def sgd_flop(cfg, env) -> float:
    """Floating-point operations of one update's SGD, counting the dense layers only: every epoch
    runs each sample forward and backward (about 3x the forward cost) through the policy and
    value networks; a multiply-add is 2 FLOP."""
    def macs(sizes):
        return sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))
    obs = env.observation_size
    per_sample = macs([obs, *cfg.hidden, 2 * env.action_size]) + macs([obs, *cfg.hidden, 1])
    return 2 * 3 * per_sample * cfg.steps_per_update * cfg.update_epochs


def matmul_speed(rows: int, width: int, repeats: int, layers: int = 200) -> float:
    """FLOP/s of a chain of (rows x width) @ (width x width) products with tanh, the shape of one
    minibatch through a hidden layer: what the SGD could reach if it were all matmul."""
    x, w = jp.ones((rows, width)), jp.full((width, width), 1.0 / width)
    chain = jax.jit(lambda x, w: jax.lax.fori_loop(0, layers, lambda _, h: jp.tanh(h @ w), x))
    return 2 * rows * width * width * layers / timed(chain, (x, w), repeats)[1]
