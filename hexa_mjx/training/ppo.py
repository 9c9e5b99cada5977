"""PPO's training loop over brax's PPO parts: one compiled program per update, no host callbacks.

brax's `ppo.train` compiles one program per evaluation interval and, between evaluations, gives
the host nothing but host callbacks; JAX's compile cache keeps no program that has one, so every
run compiled its training program again (docs/RESULTS.md, "Warm start"). `train` runs the same
computation with the same keys as `ppo.train` does for the settings hexa_mjx uses (brax's losses,
gradients, rollouts and observation normalizer; tests/test_ppo.py checks the params against
`ppo.train`), but returns to the host after every update. The progress line, Adam's state for a
checkpoint and the evaluations then need no callback, and a second run loads the program from
the cache.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable

import jax
import jax.numpy as jp
import numpy as np
from brax import envs
from brax.training import pmap, types
from brax.training.acme import running_statistics, specs
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks
from brax.training.agents.ppo.train import TrainingState

from hexa_mjx.training import program_store
from hexa_mjx.training.optimizer_state import adam_of, make_optimizer, with_adam
from hexa_mjx.training.ppo_update import AXIS, rollout_fn, sgd_fn


def unpmap(tree):
    """The first local device's copy of a replicated tree."""
    return jax.tree.map(lambda x: x.addressable_shards[0].data.squeeze(0), tree)


def replicate(tree, devices):
    """`tree` with one copy on each of `devices`, stacked on a new leading axis: pmap's input layout.
    (jax 0.9's `device_put_replicated`; jax >= 0.10 dropped it, and a GPU image may hold one.)"""
    if hasattr(jax, "device_put_replicated"):
        return jax.device_put_replicated(tree, devices)
    sharding = jax.sharding.NamedSharding(jax.sharding.Mesh(np.array(devices), (AXIS,)), jax.sharding.PartitionSpec(AXIS))
    return jax.tree.map(lambda x: jax.device_put(jp.stack([jp.asarray(x)] * len(devices)), sharding), tree)


def strong_types(tree):
    """`tree` with weak types removed: one compile for the first update and the later ones."""
    return jax.tree.map(lambda x: jp.asarray(x).astype(jp.asarray(x).dtype), tree)


@dataclasses.dataclass(frozen=True)
class PPOSettings:
    """PPO's hyperparameters and run shape, named as brax's `ppo.train` names its arguments (so
    `dataclasses.asdict(settings)` is also the keywords of a brax call; tests/test_ppo.py)."""

    num_timesteps: int  # env steps in all
    num_evals: int  # brax's count: intervals + 1 (the evaluation before training is one)
    seed: int
    num_envs: int
    episode_length: int  # control steps
    unroll_length: int  # steps per trajectory segment
    batch_size: int  # trajectory segments per minibatch
    num_minibatches: int
    num_updates_per_batch: int  # epochs over each rollout
    learning_rate: float
    entropy_cost: float
    discounting: float
    reward_scaling: float
    clipping_epsilon: float
    gae_lambda: float
    max_grad_norm: float
    vf_loss_coefficient: float
    normalize_observations: bool = True
    max_devices_per_host: int | None = None


# One function, as brax's ppo.train is: the update's closures share the run's networks, optimizer
# and keys, and it reads top to bottom as the run goes.
@dataclasses.dataclass(frozen=True)
class Position:
    """Where a run is, with everything its next update depends on besides the training state: the
    keys and the training environments' state. A run restarted from it continues bit for bit."""

    step: int  # env steps done
    interval: int  # evaluation intervals done
    update: int  # updates done within the current interval
    local_key: object  # the key the next interval's keys are split from
    key: object  # the current interval's per-device update keys (None between intervals)
    env_state: object  # the training environments, laid out (devices, environments per device, ...)


def train(environment, settings: PPOSettings, network_factory, *, wrap_env_fn=None, randomization_fn=None,
          restore_params=None, restore_adam=None, anneal_lr: tuple[int, int] | None = None,
          on_interval: Callable | None = None, on_update: Callable | None = None, resume: dict | None = None,
          environments: list | None = None, stop: Callable | None = None, on_stop: Callable | None = None,
          programs: object = None, extra_loss: Callable | None = None):
    """PPO as brax's `ppo.train` runs it (the same `settings` and `network_factory`), for
    `settings.num_timesteps` env steps in `settings.num_evals - 1` intervals. On every process,
    `on_interval(step, make_policy, params, adam_state, env_state)` is called before training and
    after each interval (params and Adam's state as host copies; the training environments' state
    laid out (devices, environments per device, ...));
    `on_update(step, env_state)` after every update, once it has run. `restore_params` and
    `restore_adam` (host arrays, `optimizer_state.adam_template`'s structure) continue a run.
    `anneal_lr=(done, total)`: CleanRL's schedule, the learning rate falling linearly from
    `settings.learning_rate` at env step 0 to 0 at `total`, for a run that has `done` steps behind it.
    `on_interval`'s sixth argument is the run's `Position`. `resume` (a `Position`'s step,
    interval, update, keys and the environment state's leaves, as host arrays) continues the same
    run exactly where that position was; steps are then counted from the run's start. Without it,
    `environments` (the environment state's saved leaves) continues the training environments as
    they were under a new schedule, where they fit this run's (else they start afresh). `stop()` is
    asked after every update; when it says so, `on_stop(step, params, adam_state, position)` is
    called and training returns early. `programs` (JSON-able: what the environment, wrappers and
    networks were made from) keeps the compiled reset and update in `program_store` under it, so
    that a second run loads them without tracing. `extra_loss(network)` makes a loss added to PPO's
    (`ppo_update.sgd_fn`). Returns the final (normalizer, policy, value)
    params."""
    if not settings.normalize_observations:
        raise ValueError("hexa_mjx's PPO always normalizes observations")
    process_id, process_count = jax.process_index(), jax.process_count()
    devices = jax.local_devices()[:settings.max_devices_per_host or None]
    device_count = len(devices) * process_count
    if settings.num_envs % device_count or (settings.batch_size * settings.num_minibatches) % settings.num_envs:
        raise ValueError(f"num_envs {settings.num_envs} must divide over {device_count} devices and divide "
                         f"batch_size x num_minibatches ({settings.batch_size * settings.num_minibatches})")
    steps_per_update = settings.batch_size * settings.unroll_length * settings.num_minibatches
    intervals = max(settings.num_evals - 1, 1)
    updates_per_interval = int(np.ceil(settings.num_timesteps / (intervals * steps_per_update)))

    # brax's keys, drawn in brax's order, so that a run agrees with ppo.train from the same seed.
    global_key, local_key = jax.random.split(jax.random.PRNGKey(settings.seed))
    local_key = jax.random.fold_in(local_key, process_id)
    local_key, key_env, _ = jax.random.split(local_key, 3)
    key_policy, key_value = jax.random.split(global_key)

    randomize = None
    if randomization_fn is not None:  # one model per environment, the same draw on every device
        randomize = functools.partial(randomization_fn,
                                      rng=jax.random.split(key_env, settings.num_envs // device_count))
    env = (wrap_env_fn or envs.training.wrap)(environment, episode_length=settings.episode_length, action_repeat=1,
                                             randomization_fn=randomize)
    key_envs = jax.random.split(key_env, settings.num_envs // process_count)
    reset_keys = key_envs.reshape((len(devices), -1) + key_envs.shape[1:])
    reset = jax.pmap(env.reset, axis_name=AXIS)
    if programs is not None:  # PPO's settings shape the programs too
        programs = [programs, dataclasses.asdict(settings), anneal_lr]
    # The update is traced from the shapes the reset will return (strongly typed, as training
    # holds them), while XLA compiles the reset on a worker thread (tracing is Python: one core).
    reset = program_store.prepare(reset, (reset_keys,), "reset", programs)
    env_shapes = reset.out_info
    obs_shape = jax.tree.map(lambda x: x.shape[2:], env_shapes.obs)  # {key: shape} where the critic has its own
    network = network_factory(obs_shape, env.action_size, preprocess_observations_fn=running_statistics.normalize)
    make_policy = ppo_networks.make_inference_fn(network)
    optimizer = make_optimizer(settings)
    rollout = rollout_fn(env, make_policy, settings)
    sgd = sgd_fn(network, optimizer, settings, scaled_lr=anneal_lr is not None, extra_loss=extra_loss)

    def update(state: TrainingState, env_state, key):
        """One PPO update: every environment rolls out, then epochs of minibatch SGD on the batch."""
        key_sgd, key_unroll, next_key = jax.random.split(key, 3)
        env_state, data = rollout((state.normalizer_params, state.params.policy, state.params.value), env_state,
                                  key_unroll)
        normalizer = running_statistics.update(state.normalizer_params, data.observation, pmap_axis_name=AXIS)
        lr_scale = 1.0
        if anneal_lr is not None:  # the share of the run still ahead, as CleanRL's `frac`
            done, total = anneal_lr
            steps = state.env_steps.hi.astype(jp.float32) * 2.0 ** 32 + state.env_steps.lo.astype(jp.float32)
            lr_scale = jp.clip(1.0 - (done + steps) / total, 0.0, 1.0)
        opt_state, params = sgd(state.optimizer_state, state.params, normalizer, data, key_sgd, lr_scale)
        return TrainingState(optimizer_state=opt_state, params=params, normalizer_params=normalizer,
                             env_steps=state.env_steps + steps_per_update), env_state, next_key

    update = jax.pmap(update, axis_name=AXIS, donate_argnums=(0, 1))

    def initial_state():
        params = ppo_losses.PPONetworkParams(policy=network.policy_network.init(key_policy),
                                             value=network.value_network.init(key_value))
        return TrainingState(optimizer_state=optimizer.init(params), params=params,
                             normalizer_params=running_statistics.init_state(jax.tree.map(
                                 lambda x: specs.Array(x.shape[2:], jp.dtype("float32")), env_shapes.obs)),
                             env_steps=types.UInt64(hi=0, lo=0))

    # One compiled program, the same bits as brax's eager init (tests/test_ppo.py): run eagerly,
    # each of its few dozen operations compiles on its own (about 1.5 s on a 2-core CPU).
    state = jax.jit(initial_state)()
    if restore_params is not None:
        normalizer, policy, value = restore_params
        state = state.replace(normalizer_params=normalizer, params=ppo_losses.PPONetworkParams(policy, value))
    if restore_adam is not None:
        state = state.replace(optimizer_state=with_adam(state.optimizer_state, restore_adam))
    step, first_interval, first_update = 0, 0, 0
    if resume is not None:
        step, first_interval, first_update = resume["step"], resume["interval"], resume["update"]
        state = state.replace(env_steps=types.UInt64(hi=step >> 32, lo=step & 0xFFFFFFFF))
    state = replicate(strong_types(state), devices)
    if resume is not None:
        local_key = jp.asarray(resume["local_key"])
    key_shape = jax.eval_shape(lambda k: jax.random.split(k, len(devices)), local_key)
    reset.begin()  # after the eager operations above: they would wait for the compile
    update = program_store.prepare(update, (state, env_shapes, key_shape), "update", programs).begin()

    env_state = reset.result()(reset_keys)
    leaves = resume["env_state"] if resume is not None else environments
    if leaves is not None:  # the environments as they were: same structure, saved leaves
        expected = jax.tree.leaves(env_state)
        fits = len(leaves) == len(expected) and all(np.shape(a) == b.shape for a, b in zip(leaves, expected))
        if not fits and resume is not None:
            raise ValueError("the saved environment state does not fit this run's environments")
        if fits:
            env_state = jax.tree.unflatten(jax.tree.structure(env_state),
                                           [jp.asarray(a, dtype=b.dtype) for a, b in zip(leaves, expected)])
        else:
            print("the saved environments do not fit this run's: they start afresh")
    env_state = strong_types(env_state)

    def host_params():
        return jax.tree.map(np.asarray, unpmap((state.normalizer_params, state.params.policy, state.params.value,
                                                 adam_of(state.optimizer_state))))

    def position(interval, done, key):
        return Position(step, interval, done, local_key, key, env_state)

    if on_interval is not None:
        host = host_params()
        on_interval(step, make_policy, host[:3], host[3], env_state, position(first_interval, first_update, None))
    compiled = False
    for interval in range(first_interval, intervals):
        if resume is not None and interval == first_interval and resume.get("key") is not None:
            key = jp.asarray(resume["key"])  # stopped within this interval: its keys as they were
        else:
            epoch_key, local_key = jax.random.split(local_key)
            key = jax.random.split(epoch_key, len(devices))
        for done in range(first_update if interval == first_interval else 0, updates_per_interval):
            if not compiled:  # the first update waits for its program
                update, compiled = update.result(), True
            state, env_state, key = update(state, env_state, key)
            step += steps_per_update
            if on_update is not None:
                jax.block_until_ready(state.params)  # the update has run: the progress line's clock is true
                on_update(step, env_state)
            if stop is not None and stop() and done + 1 < updates_per_interval:
                host = host_params()
                on_stop(step, host[:3], host[3], position(interval, done + 1, key))
                return host[:3]
        if on_interval is not None:
            host = host_params()
            on_interval(step, make_policy, host[:3], host[3], env_state, position(interval + 1, 0, None))
        if stop is not None and stop() and interval + 1 < intervals:
            host = host_params()
            on_stop(step, host[:3], host[3], position(interval + 1, 0, None))
            return host[:3]
    pmap.assert_is_replicated(state)
    pmap.synchronize_hosts()
    return jax.tree.map(np.asarray, unpmap((state.normalizer_params, state.params.policy, state.params.value)))
