"""Adam's state in checkpoints: its template, so a checkpoint's copy can be checked and restored.

`hexa_mjx.training.ppo` optimizes with brax's PPO optimizer, `optax.adam` chained after gradient clipping,
and hands each checkpoint Adam's part of that state (`ppo.adam_of`); a resume puts it back
(`ppo.with_adam`), so Adam's moments and step count go on where they stopped. The keys and the
environments' state that make a resume exact are `hexa_mjx.training.resume`'s.
"""

from __future__ import annotations

import optax


def adam_template(params_template, lr: float = 1e-3):
    """Adam's state for (normalizer, policy, value) params, as PPO optimizes them."""
    from brax.training.agents.ppo import losses

    _, policy, value = params_template
    return optax.adam(lr).init(losses.PPONetworkParams(policy=policy, value=value))
