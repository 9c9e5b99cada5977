"""Adam's state through brax's PPO: handed to the host for each checkpoint, and restored on resume.

brax's public `ppo.train` restores only the (normalizer, policy, value) params (brax #655) and
builds its optimizer itself: `optax.adam`, chained after gradient clipping. `AdamRecorder` is a
thin layer over that Adam, put in place for one `ppo.train` call by `recording`:

- its `init` returns the checkpoint's Adam state (moments and step count) when a run resumes;
- its `update` sends the state to the host once per PPO update, after the last minibatch of the
  last epoch, so the checkpoint written after an update holds the state that update left.

What a resume still cannot restore through brax's API, and why it is not bit-exact: brax draws its
keys from `seed` at every `ppo.train` call, and starts every environment on a new episode (the
documented gap, measured in docs/RESULTS.md "Reliability").
"""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jp
import numpy as np
import optax


class AdamRecorder:
    """Wraps brax's Adam: restores `restored` (host arrays, `adam_template`'s structure) at init and
    keeps the state after the most recent PPO update for `latest`."""

    def __init__(self, updates_per_batch: int, restored=None, record: bool = True):
        self.updates_per_batch = updates_per_batch  # optimizer steps in one PPO update
        self.restored = restored
        # The record is a host callback, and JAX's compile cache keeps no program that has one.
        self.record = record
        self._latest = None
        self.used = False

    def _record(self, state):
        # Only a reference: reading a device array back inside the callback would wait on the
        # devices that are running this very computation (a deadlock with several CPU devices).
        self._latest = state

    @property
    def latest(self):
        """The Adam state after the last PPO update so far, as NumPy arrays (None before the first,
        or when not recording)."""
        jax.effects_barrier()
        return None if self._latest is None else jax.tree.map(np.array, self._latest)

    def wrap(self, adam: optax.GradientTransformation) -> optax.GradientTransformation:
        def init(params):
            self.used = True
            state = adam.init(params)
            if self.restored is not None:
                state = restore_into(state, self.restored)
            return state, jp.zeros((), jp.int32)

        def update(updates, state, params=None):
            inner, calls = state
            updates, inner = adam.update(updates, inner, params)
            calls = calls + 1
            if not self.record:
                return updates, (inner, calls)
            # Every device of every process calls back with the same (all-reduced) state.
            jax.lax.cond(calls % self.updates_per_batch == 0, lambda s: jax.debug.callback(self._record, s),
                         lambda s: None, inner)
            return updates, (inner, calls)

        return optax.GradientTransformation(init, update)


def restore_into(template, restored):
    """`restored` (host arrays in `template`'s structure, as checkpoints.load_optimizer checked it)
    as device arrays of `template`'s dtypes."""
    return jax.tree.map(lambda saved, fresh: jp.asarray(saved, dtype=fresh.dtype), restored, template)


def adam_template(params_template, lr: float = 1e-3):
    """Adam's state for (normalizer, policy, value) params, as brax's PPO optimizes them."""
    from brax.training.agents.ppo import losses

    _, policy, value = params_template
    return optax.adam(lr).init(losses.PPONetworkParams(policy=policy, value=value))


class _OptaxWithRecordedAdam:
    """The optax module as brax's PPO sees it during `recording`: the same, but for `adam`."""

    def __init__(self, recorder: AdamRecorder):
        self._recorder = recorder

    def adam(self, *args, **kwargs):
        return self._recorder.wrap(optax.adam(*args, **kwargs))

    def __getattr__(self, name):
        return getattr(optax, name)


@contextlib.contextmanager
def recording(recorder: AdamRecorder):
    """brax's `ppo.train` builds its Adam through `recorder` inside this block."""
    from brax.training.agents.ppo import train as ppo_train

    real = ppo_train.optax
    ppo_train.optax = _OptaxWithRecordedAdam(recorder)
    try:
        yield recorder
    finally:
        ppo_train.optax = real
    if not recorder.used:  # brax no longer builds Adam as this layer expects (a newer brax)
        raise RuntimeError("brax's PPO did not build its optimizer through optax.adam; the optimizer state "
                           "was not recorded (check hexa_mjx/optimizer_state.py against this brax version)")
