"""A training run's evaluations: brax's deterministic evaluation, run by hexa_mjx.training.loop.

The episodes are the ones brax's `acting.Evaluator` would run (same keys, same wrappers, one
episode per environment, metrics summed until each episode's first end), at a lower cost:
- the environments are split over the CPU devices that divide them, as training splits its own:
  one batch stepped 1,000 times in sequence is bound by one core otherwise;
- the program can be compiled on a background thread (`compile_in_background`) while training
  runs, instead of after the first training interval (XLA's compile takes about 1.5 of 2 cores,
  so started beside the training program's compile it would delay the first update);
- one program serves every evaluation (brax compiles a second one to reset a donated state, and
  compiles its evaluation again when fresh params are weak-typed and trained ones are not).
Per-episode figures agree with brax's up to float rounding (a smaller batch per device may be
vectorized differently).
"""

from __future__ import annotations

import threading
import time

import jax
import jax.numpy as jp
import numpy as np

from hexa_mjx.mdp import randomization
from hexa_mjx.training import program_store


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


def evaluation_devices(num_eval_envs: int) -> int:
    """Devices an evaluation splits its environments over: the most local devices that divide
    `num_eval_envs` (process 0 evaluates alone, on its own devices)."""
    return max(d for d in range(1, jax.local_device_count() + 1) if num_eval_envs % d == 0)


def summarize_episodes(eval_metrics, seconds: float) -> dict:
    """brax's evaluation metrics (`eval/episode_<name>` means, `eval/avg_episode_length`) from
    per-episode sums laid out (devices, environments per device)."""
    flat = jax.tree.map(lambda x: np.asarray(x).reshape(-1), eval_metrics)
    lengths = np.maximum(flat.episode_steps, 1.0).astype(float)
    metrics = {f"eval/episode_{name}": float(np.mean(value / lengths if name.endswith("per_step") else value))
               for name, value in flat.episode_metrics.items()}
    steps = float(np.sum(flat.episode_steps))
    return {**metrics, "eval/avg_episode_length": float(np.mean(flat.episode_steps)),
            "eval/epoch_eval_time": seconds, "eval/sps": steps / seconds if seconds > 0 else float("nan")}


class RunEvaluator:
    """`evaluator(params) -> metrics`: `num_eval_envs` deterministic episodes of the evaluation
    environment, wrapped as training wraps its own (`wrap_env_fn`, or brax's training wrappers
    when None; `randomization_fn` drawn per evaluation environment), the policy made by
    `make_policy` from (normalizer, policy) params shaped like `params_template`."""

    def __init__(self, eval_env, wrap_env_fn, randomization_fn, make_policy, params_template, num_eval_envs: int,
                 episode_length: int, seed: int, done: int = 0, programs=None):
        """`done`: evaluations this run has already run (an exact resume continues their keys).
        `programs` (JSON-able: what the environment and wrappers were made from) keeps the compiled
        evaluation in `program_store` under it."""
        from brax import envs
        from brax.envs.wrappers.training import EvalWrapper
        from brax.training import acting

        base_key = brax_eval_key(seed, jax.process_index())
        self.key, self.calls = base_key, done
        for _ in range(done):  # brax's evaluator splits its key once per evaluation
            self.key = jax.random.split(self.key)[0]
        self.num_eval_envs, self.devices = num_eval_envs, evaluation_devices(num_eval_envs)
        models, model_axes = None, None
        if randomization_fn is not None:  # brax's draw: one model per evaluation environment
            models, model_axes = randomization_fn(eval_env.mjx_model, rng=jax.random.split(base_key, num_eval_envs))
            models = randomization.per_device(models, model_axes, self.devices)
        self.models = models
        wrap = wrap_env_fn or envs.training.wrap

        def episodes(params, reset_keys, key, models):
            randomize = (lambda _: (models, model_axes)) if models is not None else None
            env = EvalWrapper(wrap(eval_env, episode_length=episode_length, action_repeat=1,
                                   randomization_fn=randomize))
            state = acting.generate_unroll(env, env.reset(reset_keys), make_policy(params, deterministic=True), key,
                                           unroll_length=episode_length)[0]
            return state.info["eval_metrics"]

        self.program = jax.pmap(episodes, in_axes=(None, 0, None, model_axes),
                                devices=jax.local_devices()[:self.devices])
        self.template, self.compiled, self.error, self.thread = params_template, None, None, None
        self.programs = None if programs is None else [programs, num_eval_envs, episode_length]

    def compile_in_background(self) -> None:
        """Start compiling the evaluation program on a thread; the next call waits for it."""
        if self.thread is None:
            self.thread = threading.Thread(target=self._compile, args=(fresh_copy(self.template),), daemon=True)
            self.thread.start()

    def _inputs(self, params, key):
        keys = jax.random.split(key, self.num_eval_envs)
        return params, keys.reshape((self.devices, -1) + keys.shape[1:]), key, self.models

    def _compile(self, params) -> None:
        try:
            self.compiled = program_store.compiled(self.program, self._inputs(params, self.key), "evaluation",
                                                   self.programs)
        except Exception as e:  # noqa: BLE001 - raised again by the first call, on the caller's thread
            self.error = e

    def __call__(self, params) -> dict:
        self.compile_in_background()
        self.thread.join()
        if self.error is not None:
            raise self.error
        self.key, unroll_key = jax.random.split(self.key)
        self.calls += 1
        t = time.time()
        eval_metrics = jax.block_until_ready(self.compiled(*self._inputs(fresh_copy(params), unroll_key)))
        return summarize_episodes(eval_metrics, time.time() - t)
