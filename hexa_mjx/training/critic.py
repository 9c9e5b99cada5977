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
    pad = lambda x, fill: np.concatenate([x, np.full(extra, fill, x.dtype)])  # noqa: E731
    count = normalizer.count  # brax's UInt64 (hi, lo): observations seen
    seen = float(count.hi) * 2.0 ** 32 + float(count.lo) if hasattr(count, "hi") else float(count)
    stats = like.replace(
        count=count, mean={POLICY_KEY: normalizer.mean, CRITIC_KEY: pad(normalizer.mean, 0.0)},
        summed_variance={POLICY_KEY: normalizer.summed_variance, CRITIC_KEY: pad(normalizer.summed_variance, seen)},
        std={POLICY_KEY: normalizer.std, CRITIC_KEY: pad(normalizer.std, 1.0)})

    def widen(source, wanted):  # the first layer's kernel gains rows; every other array fits as it is
        if source.shape == wanted.shape:
            return source
        return np.concatenate([source, np.zeros((wanted.shape[0] - source.shape[0],) + source.shape[1:], source.dtype)])

    return stats, policy, jax.tree.map(widen, value, template[2])
