"""One PPO update's two halves, as brax's PPO runs them: the rollout (`rollout_fn`) and the
minibatch SGD on its batch (`sgd_fn`). `hexa_mjx.training.ppo` composes them into one compiled
update; `hexa_mjx.studies.training_speed` times each on its own.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import jax
import jax.numpy as jp
import optax
from brax.training import acting, gradients
from brax.training.agents.ppo import losses as ppo_losses

if TYPE_CHECKING:
    from hexa_mjx.training.ppo import PPOSettings

AXIS = "i"  # the pmap axis the gradients and the normalizer are averaged over
UNROLL_FIELDS = ("truncation", "episode_metrics", "episode_done")


def rollout_fn(env, make_policy, settings: PPOSettings):
    """One update's acting, as brax's PPO runs it: `rollout(params, env_state, key) -> (env_state,
    data)`, every environment stepping `batch_size x num_minibatches / num_envs` segments of
    `unroll_length` steps with the policy of `params` (normalizer, policy, value); `data` holds one
    segment per row."""

    def rollout(params, env_state, key):
        policy = make_policy(params)

        def unroll(carry, _):
            env_state, key = carry
            key, next_key = jax.random.split(key)
            env_state, data = acting.generate_unroll(env, env_state, policy, key, settings.unroll_length,
                                                     extra_fields=UNROLL_FIELDS)
            return (env_state, next_key), data

        segments = settings.batch_size * settings.num_minibatches // settings.num_envs
        (env_state, _), data = jax.lax.scan(unroll, (env_state, key), (), length=segments)
        # (unrolls x steps x environments) -> (unrolls * environments, steps)
        data = jax.tree.map(lambda x: jp.swapaxes(x, 1, 2), data)
        return env_state, jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), data)

    return rollout


def sgd_fn(network, optimizer, settings: PPOSettings, scaled_lr: bool = False, extra_loss=None):
    """One update's learning, as brax's PPO runs it: `sgd(opt_state, params, normalizer, data, key,
    lr_scale) -> (opt_state, params)`, `num_updates_per_batch` epochs of minibatch steps on brax's
    PPO loss, gradients averaged over the pmap axis AXIS. With `scaled_lr`, each Adam step is
    multiplied by `lr_scale` (Adam's step is proportional to its learning rate). `extra_loss(network)`
    makes a `loss(params, normalizer, observation)` added to PPO's (`hexa_mjx.training.symmetry`)."""
    ppo_loss = functools.partial(ppo_losses.compute_ppo_loss, ppo_network=network, entropy_cost=settings.entropy_cost,
                                 discounting=settings.discounting, reward_scaling=settings.reward_scaling,
                                 gae_lambda=settings.gae_lambda, clipping_epsilon=settings.clipping_epsilon,
                                 normalize_advantage=True, vf_coefficient=settings.vf_loss_coefficient)
    if extra_loss is not None:
        added = extra_loss(network)

        def with_added(params, normalizer, data, key):
            total, metrics = ppo_loss(params, normalizer, data, key)
            return total + added(params, normalizer, data.observation), metrics

    loss_and_grad = gradients.loss_and_pgrad(ppo_loss if extra_loss is None else with_added,
                                             pmap_axis_name=AXIS, has_aux=True)

    def minibatch_step(carry, data, normalizer, lr_scale):
        opt_state, params, key = carry
        key, key_loss = jax.random.split(key)
        _, grads = loss_and_grad(params, normalizer, data, key_loss)
        step, opt_state = optimizer.update(grads, opt_state)
        if scaled_lr:
            step = jax.tree.map(lambda x: x * lr_scale, step)
        return (opt_state, optax.apply_updates(params, step), key), None

    def sgd_epoch(carry, _, data, normalizer, lr_scale):
        opt_state, params, key = carry
        key, key_perm, key_grad = jax.random.split(key, 3)
        shuffled = jax.tree.map(lambda x: jax.random.permutation(key_perm, x).reshape(
            (settings.num_minibatches, -1) + x.shape[1:]), data)
        (opt_state, params, _), _ = jax.lax.scan(
            functools.partial(minibatch_step, normalizer=normalizer, lr_scale=lr_scale),
            (opt_state, params, key_grad), shuffled, length=settings.num_minibatches)
        return (opt_state, params, key), None

    def sgd(opt_state, params, normalizer, data, key, lr_scale=1.0):
        (opt_state, params, _), _ = jax.lax.scan(
            functools.partial(sgd_epoch, data=data, normalizer=normalizer, lr_scale=lr_scale),
            (opt_state, params, key), (), length=settings.num_updates_per_batch)
        return opt_state, params

    return sgd
