"""The privileged critic (`--privileged_critic`): a value network that reads more than the policy.

PPO's critic is thrown away after training, so it may read what no deployed robot could: here the
observation without its noise and which legs failed this episode and how
(`hexa_mjx.engines.wrappers.CriticObservation`), as Playground's locomotion tasks give their critics
privileged state. With a leg failed in most episodes and nothing telling the critic which, its
value estimates average over conditions that the advantages must tell apart.

The run's params then hold two sets of observation statistics and a wider first critic layer;
the policy, its ONNX file and every evaluation read the policy's observation alone (`actor_params`).
"""

from __future__ import annotations

import jax
import numpy as np

from hexa_mjx.engines.wrappers import CRITIC_KEY, POLICY_KEY, CriticObservation
from hexa_mjx.training.warm_start import padded_statistics, widen


def observation_shapes(cfg, env):
    """What the networks read, as brax's PPO networks take it: the policy observation's length, or
    with `privileged_critic` {key: shape} for the policy's observation and the critic's."""
    if not cfg.privileged_critic:
        return env.observation_size
    return {POLICY_KEY: (env.observation_size,), CRITIC_KEY: (CriticObservation.critic_size(env),)}


def actor_params(params):
    """(normalizer, policy, value) params as the policy acts on them: with a privileged critic, the
    normalizer of the policy's own observation alone (the value params are the critic's, unused)."""
    from brax.training import networks

    normalizer, policy, value = params
    if isinstance(normalizer.mean, dict):
        normalizer = networks.normalizer_select(normalizer, POLICY_KEY)
    return normalizer, policy, value


def with_critic(params, template):
    """Params trained without a privileged critic, in the structure of `template` (a run with one):
    the policy as it was; the critic's statistics of the values both observations share copied and
    the rest at mean 0, std 1; its first layer's weights on the added values 0, so that it starts
    with the source's value of every state."""
    normalizer, policy, value = jax.tree.map(np.asarray, params)
    like = template[0]
    extra = like.mean[CRITIC_KEY].shape[0] - normalizer.mean.shape[0]
    mean, summed_variance, std = padded_statistics(normalizer, extra)
    stats = like.replace(count=normalizer.count, mean={POLICY_KEY: normalizer.mean, CRITIC_KEY: mean},
                         summed_variance={POLICY_KEY: normalizer.summed_variance, CRITIC_KEY: summed_variance},
                         std={POLICY_KEY: normalizer.std, CRITIC_KEY: std})
    return stats, policy, jax.tree.map(widen, value, template[2])
