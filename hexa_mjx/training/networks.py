"""The policy and value networks of a run: brax's PPO networks at the config's sizes, fresh params
and their templates, and the policy function that evaluations and exports act with.

With `privileged_critic` the value network reads its own observation (`hexa_mjx.training.critic`);
the policy functions here read the policy's observation alone.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jp
import numpy as np
from flax import linen

from hexa_mjx.engines.wrappers import CRITIC_KEY
from hexa_mjx.training.config import TrainConfig
from hexa_mjx.training.critic import actor_params, observation_shapes
from hexa_mjx.training.optimizer_state import adam_template


def network_factory(cfg: TrainConfig):
    """brax's PPO network factory with the config's layer sizes and tanh activations; with
    `privileged_critic`, the value network reads the critic's own observation (`CriticObservation`)."""
    from brax.training.agents.ppo import networks as ppo_networks

    keys = dict(value_obs_key=CRITIC_KEY) if cfg.privileged_critic else {}
    # CleanRL's actor: state-independent log std (starting at std 1 by default), a small output layer for the mean.
    return functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=tuple(cfg.hidden),
                             value_hidden_layer_sizes=tuple(cfg.hidden), activation=linen.tanh,
                             distribution_type=cfg.policy_dist, noise_std_type="log", init_noise_std=cfg.init_noise_std,
                             mean_kernel_init_fn=jax.nn.initializers.variance_scaling,
                             mean_kernel_init_kwargs={"scale": cfg.mean_init_scale ** 2, "mode": "fan_in",
                                                      "distribution": "uniform"}, **keys)


def make_networks(cfg: TrainConfig, env):
    """Networks as PPO trained them: observations normalized by the saved running statistics."""
    from brax.training.acme import running_statistics

    return network_factory(cfg)(observation_shapes(cfg, env), env.action_size,
                                preprocess_observations_fn=running_statistics.normalize)


def init_params(cfg: TrainConfig, env):
    """Fresh (normalizer, policy, value) params: the structure checkpoints restore into (with
    `privileged_critic`, the normalizer holds statistics for each of `observation_shapes`)."""
    from brax.training.acme import running_statistics, specs

    nets = make_networks(cfg, env)
    key_policy, key_value = jax.random.split(jax.random.PRNGKey(cfg.seed))
    shapes = observation_shapes(cfg, env)
    as_spec = lambda shape: specs.Array(shape, jp.dtype("float32"))  # noqa: E731
    spec = {key: as_spec(shape) for key, shape in shapes.items()} if isinstance(shapes, dict) else as_spec((shapes,))
    normalizer = running_statistics.init_state(spec)
    return normalizer, nets.policy_network.init(key_policy), nets.value_network.init(key_value)


def templates(cfg: TrainConfig, env):
    """(params, Adam state) shaped as a run of `cfg` holds them, as NumPy zeros: what checkpoints
    restore into and programs are compiled for. Made from shapes alone: run, their few dozen
    operations would each compile on its own (about 1.5 s on a 2-core CPU)."""

    def made():
        params = init_params(cfg, env)
        return params, adam_template(params)

    return jax.tree.map(lambda x: np.zeros(x.shape, x.dtype), jax.eval_shape(made))


def policy_maker(cfg: TrainConfig, env):
    """brax's `make_policy(params, deterministic)` for the config's networks, on the policy's own
    observation whatever the critic saw."""
    from brax.training.agents.ppo import networks as ppo_networks

    make = ppo_networks.make_inference_fn(make_networks(dataclasses.replace(cfg, privileged_critic=False), env))
    return lambda params, deterministic=False: make(actor_params(params), deterministic)


def make_inference(cfg: TrainConfig, env, params, deterministic=True):
    """A policy function obs -> action from saved params."""
    policy = policy_maker(cfg, env)(params, deterministic=deterministic)
    return lambda obs, key: policy(obs, key)[0]
