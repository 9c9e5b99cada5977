"""Networks that read more values than the params they start from: zero weights on the added inputs.

A run may start (`--init_from`) from a policy whose task observes a prefix of what this run's task
observes: the drive task's observation is the navigate task's (or the velocity task's, but for the
meaning of its first values) with the mode appended. The
source's first layers gain zero rows for the added values and its observation statistics gain
mean 0, std 1 for them, so the widened networks compute exactly what the source's did until
training moves those weights. The privileged critic widens its value network the same way
(hexa_mjx.training.critic).
"""

from __future__ import annotations

import jax
import numpy as np


def seen_count(normalizer) -> float:
    """Observations brax's running statistics have counted (its UInt64 (hi, lo), or a number)."""
    count = normalizer.count
    return float(count.hi) * 2.0 ** 32 + float(count.lo) if hasattr(count, "hi") else float(count)


def padded_statistics(normalizer, extra: int) -> tuple:
    """(mean, summed variance, std) of `normalizer` with `extra` values appended at mean 0, std 1."""
    pad = lambda x, fill: np.concatenate([np.asarray(x), np.full(extra, fill, np.asarray(x).dtype)])  # noqa: E731
    return pad(normalizer.mean, 0.0), pad(normalizer.summed_variance, seen_count(normalizer)), pad(normalizer.std, 1.0)


def widen(source, wanted):
    """`source`, with zero rows appended where `wanted` (an array of the target's shape) has more:
    the first layer's kernel gains inputs; every other array fits as it is."""
    source = np.asarray(source)
    if source.shape == tuple(wanted.shape):
        return source
    rows = np.zeros((wanted.shape[0] - source.shape[0],) + source.shape[1:], source.dtype)
    return np.concatenate([source, rows])


def widened(params, template):
    """(normalizer, policy, value) params trained on a shorter observation, in the structure of
    `template`, a run whose observation appends values to the source's."""
    normalizer, policy, value = jax.tree.map(np.asarray, params)
    extra = template[0].mean.shape[0] - normalizer.mean.shape[0]
    mean, summed_variance, std = padded_statistics(normalizer, extra)
    stats = template[0].replace(count=normalizer.count, mean=mean, summed_variance=summed_variance, std=std)
    return stats, jax.tree.map(widen, policy, template[1]), jax.tree.map(widen, value, template[2])


def extends(source_layout, layout) -> bool:
    """Whether an observation `layout` holds `source_layout`'s values in the same places and adds
    values after them. A lead of task inputs (a goal, a command) may differ in meaning, as between
    tasks of the same length; from the first slice that matches in place and units on, every slice
    must match."""
    end = source_layout[-1][1]
    if layout[-1][1] <= end or end not in {t[1] for t in layout}:
        return False
    place = {(t[0], t[1], t[3]) for t in layout}
    matches = [(s[0], s[1], s[3]) in place for s in source_layout]
    return any(matches) and all(matches[matches.index(True):])
