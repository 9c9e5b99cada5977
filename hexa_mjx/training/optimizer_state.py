"""PPO's optimizer, and Adam's part of its state as checkpoints keep it.

`hexa_mjx.training.ppo` optimizes with brax's PPO optimizer (`make_optimizer`: `optax.adam` chained
after gradient clipping) and hands each checkpoint Adam's part of that state (`adam_of`); a resume
puts it back (`with_adam`), so Adam's moments and step count go on where they stopped. The keys and
the environments' state that make a resume exact are `hexa_mjx.training.resume`'s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jp
import optax

if TYPE_CHECKING:
    from hexa_mjx.training.ppo import PPOSettings


def make_optimizer(settings: PPOSettings):
    """brax's PPO optimizer: gradients clipped by global norm, then Adam."""
    return optax.chain(optax.clip_by_global_norm(settings.max_grad_norm), optax.adam(settings.learning_rate))


def adam_of(optimizer_state):
    """Adam's part of the optimizer state (gradient clipping's part holds nothing)."""
    return optimizer_state[1]


def with_adam(optimizer_state, adam_state):
    """The optimizer state with Adam's part replaced by `adam_state` (host arrays, as saved)."""
    restored = jax.tree.map(lambda saved, fresh: jp.asarray(saved, dtype=fresh.dtype), adam_state,
                            adam_of(optimizer_state))
    return (optimizer_state[0], restored)


def adam_template(params_template, lr: float = 1e-3):
    """Adam's state for (normalizer, policy, value) params, as PPO optimizes them."""
    from brax.training.agents.ppo import losses

    _, policy, value = params_template
    return optax.adam(lr).init(losses.PPONetworkParams(policy=policy, value=value))
