"""A training run's evaluations, run by hexa_mjx.training.loop rather than inside brax's `ppo.train`.

brax evaluates the untrained params before the first update and compiles its evaluation program
twice: its fresh params carry weak-typed scalars that trained ones do not (and, with randomized
physics, are not committed to a device while trained ones are). On a 2-core CPU one
evaluation of 32 episodes x 1000 steps runs about 30 s and each compile 40 s. Run here, a run can
skip the evaluation at step 0 (`--no_eval_at_start`), a resumed run skips the one of a checkpoint
whose row is already logged, and one program serves every evaluation. The episodes are the ones
brax's own evaluator would run: same key, same wrappers.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jp
import numpy as np


def brax_eval_key(seed: int, process_index: int = 0) -> jax.Array:
    """The key brax's `ppo.train(seed=seed)` hands its evaluator."""
    _, local = jax.random.split(jax.random.PRNGKey(seed))
    return jax.random.split(jax.random.fold_in(local, process_index), 3)[2]


def fresh_copy(tree):
    """`tree` as new device arrays, strongly typed and not committed to a device: the same input
    types at every evaluation. (brax's fresh params have weak-typed leaves and trained ones do not;
    params taken from a pmap are committed to device 0 and others are not; either difference
    compiles the evaluation program again.)"""
    return jax.tree.map(lambda x: jp.asarray(np.asarray(x)), tree)


class RunEvaluator:
    """`evaluator(make_policy, params) -> metrics`: brax's Evaluator over `num_eval_envs` episodes of
    the evaluation environment, wrapped as `ppo.train` wraps its own (`wrap_env_fn`, or brax's
    training wrappers when None; `randomization_fn` drawn per evaluation environment)."""

    def __init__(self, eval_env, wrap_env_fn, randomization_fn, num_eval_envs: int, episode_length: int, seed: int,
                 done: int = 0):
        """`done`: evaluations this run has already run (an exact resume continues their keys)."""
        from brax import envs

        self.key = brax_eval_key(seed, jax.process_index())
        self.calls = done
        v_randomization = (functools.partial(randomization_fn, rng=jax.random.split(self.key, num_eval_envs))
                           if randomization_fn is not None else None)
        wrap = wrap_env_fn or envs.training.wrap
        self.env = wrap(eval_env, episode_length=episode_length, action_repeat=1, randomization_fn=v_randomization)
        self.num_eval_envs, self.episode_length = num_eval_envs, episode_length
        self.evaluator = None  # built at the first call: it needs brax's make_policy

    def __call__(self, make_policy, params) -> dict:
        from brax.training import acting

        if self.evaluator is None:
            key = self.key
            for _ in range(self.calls):  # brax's evaluator splits its key once per evaluation
                key = jax.random.split(key)[0]
            self.evaluator = acting.Evaluator(self.env, functools.partial(make_policy, deterministic=True),
                                              num_eval_envs=self.num_eval_envs, episode_length=self.episode_length,
                                              action_repeat=1, key=key)
        self.calls += 1
        return self.evaluator.run_evaluation(fresh_copy(params), training_metrics={})
