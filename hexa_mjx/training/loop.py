"""Brax PPO over the hexapod environment: the training run, its start and its evaluations.

`train.py` is the command-line face of `train(config)`. A run directory holds `config.json`,
`metrics.jsonl` (one row per evaluation), TensorBoard events in `tb/` and `checkpoints/<step>/`;
see `hexa_mjx.training.config`, `hexa_mjx.training.checkpoints` and `hexa_mjx.training.progress`;
the networks are `hexa_mjx.training.networks`'s.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import math
import time
import types
from pathlib import Path

import jax
import jax.numpy as jp

from hexa_mjx.training import distributed, crash_points as faults, ppo, resume as exact, selection, symmetry
from hexa_mjx.mdp import randomization
from hexa_mjx.training.checkpoints import (BEST, checkpoint_dir, list_checkpoints, load_checkpoint, load_latest,
                                           load_resume, remove_temporaries, resolve_checkpoint, save_checkpoint)
from hexa_mjx.training.checks import observation_size
from hexa_mjx.training.config import TrainConfig, init_checkpoint, load_config, make_env_for, validate
from hexa_mjx.mdp.curriculum import level_summary
from hexa_mjx.mdp.failure_schedule import schedule_summary
from hexa_mjx.training.jax_setup import devices_for, prepare_jax
from hexa_mjx.training.progress import Logger, keep_rows_up_to
from hexa_mjx.training.run_lock import RunLock
from hexa_mjx.evaluation.run_evaluator import RunEvaluator
from hexa_mjx.engines.wrappers import POLICY_KEY, mean_last_return
from hexa_mjx.training.critic import with_critic
from hexa_mjx.training.warm_start import widened
from hexa_mjx.training.networks import init_params, network_factory, policy_maker, templates
from hexa_mjx import atomic


def ppo_settings(cfg: TrainConfig, num_timesteps: int, num_evals: int, seed: int,
                 devices: int | None = None) -> ppo.PPOSettings:
    """The algorithm and rollout shape of `cfg` for `num_timesteps` steps in `num_evals - 1`
    intervals, as `hexa_mjx.training.ppo.train` (and brax's `ppo.train`) take them."""
    return ppo.PPOSettings(num_timesteps=num_timesteps, num_evals=num_evals, seed=seed, num_envs=cfg.num_envs,
                           episode_length=cfg.episode_length, unroll_length=cfg.unroll_length,
                           batch_size=cfg.batch_size, num_minibatches=cfg.num_minibatches,
                           num_updates_per_batch=cfg.update_epochs, learning_rate=cfg.lr, entropy_cost=cfg.ent_coef,
                           discounting=cfg.discount, reward_scaling=cfg.reward_scaling, clipping_epsilon=cfg.clip,
                           gae_lambda=cfg.gae_lambda, max_grad_norm=cfg.max_grad_norm,
                           vf_loss_coefficient=cfg.vf_coef, max_devices_per_host=devices)


def evals_for(cfg: TrainConfig, remaining: int) -> int:
    """brax's num_evals for `remaining` of the run's steps, at least as dense as the run's own
    spacing: a resumed run must not crowd all of its evaluations into the steps it has left (brax
    counts the evaluation before training as one of them)."""
    return 1 + max(1, math.ceil((cfg.num_evals - 1) * remaining / cfg.num_timesteps))


def wrap_env_fn(env, randomized: bool = False, track_returns: bool = False, failure_schedule: dict | None = None,
                critic_observation: bool = False):
    """brax's training wrappers, or ours that redraw the start state (and first goal) every episode,
    give each environment its own randomized model, keep each environment's latest return for the
    progress line (`track_returns`), schedule leg failures (`failure_schedule`,
    hexa_mjx.mdp.failure_schedule) and give the critic its own observation (`critic_observation`)."""
    from hexa_mjx.engines import wrappers

    fresh_starts = env.fresh_starts or randomized
    if not track_returns and failure_schedule is None and not critic_observation:
        return wrappers.wrap_for_training if fresh_starts else None
    return functools.partial(wrappers.wrap_for_training, track_returns=track_returns, fresh_starts=fresh_starts,
                             failure_schedule=failure_schedule, critic_observation=critic_observation)


def failure_schedule_for(cfg: TrainConfig, start_step: int) -> dict | None:
    """`LegFailureSchedule`'s settings for a run (None without a schedule): `--leg_failure_after` in
    control steps per environment, counted from `start_step` (a resumed run's checkpoint)."""
    if not (cfg.leg_failure_after or cfg.leg_failure_adaptive):
        return None
    after = max(0, cfg.leg_failure_after - start_step)
    return dict(start_after=-(-after // cfg.num_envs), adaptive=cfg.leg_failure_adaptive)


HOST_ONLY = ("run_dir", "resume", "progress", "record_optimizer", "compile_cache", "process_wait_timeout",
             "coordinator_timeout")  # config fields no compiled program depends on


def evaluator_for(cfg: TrainConfig, eval_env, randomization_fn, template, episodes: int, seed: int, done: int = 0,
                  programs=None) -> RunEvaluator:
    """The run's evaluation (`RunEvaluator`) of `episodes` deterministic episodes from `seed`,
    wrapped as training wraps its own environments: what its rows and `RUN/best` are scored on."""
    return RunEvaluator(eval_env, wrap_env_fn(eval_env, cfg.randomize), randomization_fn, policy_maker(cfg, eval_env),
                        template, episodes, cfg.episode_length, seed=seed, done=done, programs=programs)


def program_description(cfg: TrainConfig, offset: int) -> dict:
    """What a run's environments, wrappers and networks are made from, as `program_store` keys its
    compiled programs: the config less its host-only fields, and the step its counts start from."""
    return {**{k: v for k, v in dataclasses.asdict(cfg).items() if k not in HOST_ONLY}, "offset": offset}


def load_start(cfg: TrainConfig, env, template) -> tuple[int, object]:
    """--init_from's (step, params) in the structure of `template`: a source trained without a
    privileged critic gets one that starts as its own critic (`critic.with_critic`), one whose task
    observes fewer values zero weights on the rest (`warm_start.widened`)."""
    path = init_checkpoint(cfg)
    source = load_config(resolve_checkpoint(path)[0])
    observed = observation_size(source.task, cfg.model)
    if observed < env.observation_size:  # a task whose observation this one extends (checked by init_checkpoint)
        shorter = types.SimpleNamespace(observation_size=observed, action_size=env.action_size)
        step, params = load_checkpoint(path, init_params(cfg, shorter))
        return step, widened(params, template)
    if not cfg.privileged_critic or source.privileged_critic:
        return load_checkpoint(path, template)
    step, params = load_checkpoint(path, init_params(dataclasses.replace(cfg, privileged_critic=False), env))
    return step, with_critic(params, template)


def resume_point(cfg: TrainConfig, run_dir: Path, template, optimizer_template) -> tuple[int, object, object, object]:
    """(step, params, Adam state, saved position) to continue from: (0, None, None, None) for a new
    run, or one with no readable checkpoint; the Adam state is None for a checkpoint saved without
    it, the saved position (hexa_mjx.training.resume) None for one saved without it."""
    if remove_temporaries(run_dir):
        print(f"removed half-written checkpoint folders in {checkpoint_dir(run_dir)}")
    if not cfg.resume:
        return 0, None, None, None
    if not list_checkpoints(run_dir):
        print(f"{run_dir} has no complete checkpoint yet (it stopped before its first): starting again from step 0")
        return 0, None, None, None
    start_step, restore, optimizer, path = load_latest(run_dir, template, optimizer_template)
    if restore is None:
        print(f"{run_dir} has no readable checkpoint: starting again from step 0")
        return 0, None, None, None
    return start_step, restore, optimizer, load_resume(path)


def train(cfg: TrainConfig, on_eval=None, stop=None) -> dict:
    """Run (or resume) PPO for `cfg`; returns the last evaluation row. `on_eval(row)` is called with
    each evaluation's metrics.jsonl row (a sweep reports them to its scheduler). When `stop()` says
    so (after an update), the run writes a checkpoint and raises `resume.Preempted`."""
    prepare_jax(cpu_devices=cfg.cpu_devices, compile_cache=cfg.compile_cache)
    main = distributed.is_main()  # process 0 (or the only one) reads and writes the run directory
    cfg = validate(cfg, writes=main)
    with RunLock(cfg.run_dir) if main else contextlib.nullcontext():  # one writer per run directory
        return run(cfg, main, on_eval, stop)


# Long by design: the run's steps top to bottom (environment, resume point, logger, PPO, the
# last evaluation), each a call to a named helper, as a CleanRL script reads.
def run(cfg: TrainConfig, main: bool, on_eval=None, stop=None) -> dict:
    """`train`'s run of a validated config, by the process that holds the run directory (`main`)
    or another process of a multi-process run."""
    run_dir = Path(cfg.run_dir)
    # The curriculum shapes the training environment only: evaluations see the full task. The
    # evaluation's own environment object (process 0's) is traced on the evaluator's compile thread.
    env = make_env_for(cfg, curriculum_levels=cfg.curriculum_levels)
    eval_env = make_env_for(cfg) if main else env
    template, optimizer_template = templates(cfg, env)
    start_step, restore, optimizer, saved, logged = 0, None, None, None, set()
    if main:
        start_step, restore, optimizer, saved = resume_point(cfg, run_dir, template, optimizer_template)
        if restore is None and cfg.init_from:  # a fine-tuning run's own checkpoints come first on resume
            source_step, restore = load_start(cfg, env, template)
            print(f"starting from the params of {cfg.init_from} (its step {source_step:,}); Adam starts afresh")
        # One row per evaluation: rows past the checkpoint go, and the checkpoint's own evaluation is
        # logged again only if its row is missing (a run from before rows were written first).
        logged = keep_rows_up_to(run_dir, start_step)
        atomic.write(run_dir / "config.json", json.dumps(dataclasses.asdict(cfg), indent=2))
    distributed.wait_for_main("reading the run directory", cfg.process_wait_timeout)
    start_step, restored, adam, row_kept = (int(x) for x in distributed.share(
        jp.array([start_step, restore is not None, optimizer is not None, start_step in logged])))
    if restored:
        restore = distributed.share(restore if main else template)
    if adam:
        optimizer = distributed.share(optimizer if main else optimizer_template)
    position, environments = None, None
    if start_step > 0:  # resumed from the run's own checkpoint (none is written at step 0)
        saved = exact.shared(saved)
        position, why = exact.exact_resume(saved, cfg, start_step, jax.process_count(), jax.process_index())
        if not position:  # a new schedule, but the same environments: episodes and curriculum levels go on
            environments = exact.saved_environments(saved, cfg, jax.process_count(), jax.process_index())
        if main:
            print(f"resuming {run_dir} from step {start_step:,}"
                  + (": exactly, as if it had not stopped" if position else f", not exactly: {why}")
                  + ("; its environments carry on" if environments else "")
                  + ("" if adam else " (its checkpoint has no optimizer state: Adam starts afresh)"))
    remaining = cfg.num_timesteps - start_step
    if remaining <= 0:
        print(f"{run_dir} already has {start_step:,} of {cfg.num_timesteps:,} steps; nothing to do")
        return {}

    logger = Logger(run_dir, cfg, start_step) if main else None
    # A fresh run's schedule counts steps from 0; any resume that is not exact starts a new
    # schedule over the steps left, counted from where it resumed (the offset); an exact resume
    # continues its checkpoint's schedule, counted from that schedule's own start.
    offset = position["origin"] if position else start_step
    schedule = failure_schedule_for(cfg, offset)

    # A fresh run evaluates its untrained params if asked; a resumed one its checkpoint's only if
    # that row is missing (a crash between the two, or a run from before rows were written first).
    evaluate_start = not row_kept and (cfg.eval_at_start or start_step > 0) and not position
    randomization_fn = randomization.randomization_fn(env) if cfg.randomize else None
    programs = program_description(cfg, offset)  # what the kept compiled programs are keyed by
    evaluator = evaluator_for(cfg, eval_env, randomization_fn, template, cfg.num_eval_envs, seed=cfg.seed + offset,
                              done=position["evaluations"] if position else 0, programs=programs) if main else None

    def on_interval(step, make_policy, params, adam, env_state, at):  # before training, after each interval
        first = step == start_step - offset
        if first and not evaluate_start:
            return
        arrays = None if first else exact.position_arrays(at)  # every process takes part
        if not main:  # process 0 evaluates and writes alone; the others wait for it here, not in a collective
            distributed.wait_for_main(f"evaluation and checkpoint at step {offset + step:,}", cfg.process_wait_timeout)
            return
        logger.evaluating()
        metrics = evaluator(params)
        # Where the curriculum's environments are (levels restart at 0 on resume), and the failure schedule.
        if cfg.curriculum_levels:
            metrics.update(level_summary(env_state.info["level"], cfg.curriculum_levels))
        if schedule:
            metrics.update(schedule_summary(env_state.info))
        faults.point("evaluated")
        logger(offset + step, metrics)
        if first:
            faults.point("training-started")
        else:
            # Row first, then checkpoint: a crash between them loses neither, because a resume drops
            # the rows past its checkpoint and trains those steps again.
            faults.point("row-written")
            save_checkpoint(run_dir, offset + step, params, adam if cfg.record_optimizer else None,
                            (arrays, exact.position_facts(at, evaluator.calls, cfg)))
        distributed.wait_for_main(f"evaluation and checkpoint at step {offset + step:,}", cfg.process_wait_timeout)
        if on_eval:  # a sweep's scheduler may stop the run here: its checkpoint is saved
            on_eval(logger.last)

    def on_update(step, env_state):
        if isinstance(stop, exact.Preemption):
            stop.trained()  # from here a stop saves a checkpoint
        if not main:
            return
        # The training programs have compiled and run: the evaluation's compiles beside training.
        evaluator.compile_in_background()
        if cfg.progress:
            logger.progress(offset + step, lambda: mean_last_return(env_state))
            faults.point("update-done")

    def on_stop(step, params, adam, at):  # asked to stop: a checkpoint here, then out
        arrays = exact.position_arrays(at)  # every process takes part
        path = save_checkpoint(run_dir, offset + step, params, adam,
                               (arrays, exact.position_facts(at, evaluator.calls, cfg))) if main else None
        distributed.wait_for_main(f"checkpoint at the stop, step {offset + step:,}", cfg.process_wait_timeout)
        raise exact.Preempted(offset + step, path)

    def asked_to_stop():  # the same answer on every process, whichever of them got the signal
        return distributed.any_process(stop is not None and stop())

    t0 = time.time()
    devices = devices_for(cfg)
    processes = f" x {jax.process_count()} processes" if jax.process_count() > 1 else ""
    print(f"training {cfg.task}: {cfg.reward} (ablate {cfg.ablate or 'none'}) seed {cfg.seed}: {remaining:,} steps on "
          f"{cfg.num_envs} envs ({devices} {jax.default_backend()} device{'s' * (devices > 1)}{processes}), "
          f"{cfg.steps_per_update:,} steps per update -> {run_dir}", flush=True)
    if logger:
        logger.compiling(evaluation_first=evaluate_start)
    faults.point("compiling")
    left = cfg.num_timesteps - offset  # the schedule's steps: the whole run's for a fresh run and its exact resumes
    settings = ppo_settings(cfg, left, evals_for(cfg, left), cfg.seed + offset, devices)
    extra_loss = None
    if cfg.symmetry_loss:
        obs_maps, act_maps = symmetry.maps_for(env, cfg.symmetry_turns)
        extra_loss = functools.partial(symmetry.mirror_loss, weight=cfg.symmetry_loss, obs_maps=obs_maps,
                                       act_maps=act_maps, policy_key=POLICY_KEY if cfg.privileged_critic else None)
    ppo.train(env, settings, network_factory(cfg),
              # Returns are kept whether or not this process prints them: every process runs one program.
              wrap_env_fn=wrap_env_fn(env, cfg.randomize, track_returns=True, failure_schedule=schedule,
                                      critic_observation=cfg.privileged_critic),
              randomization_fn=randomization_fn, restore_params=restore, restore_adam=optimizer,
              anneal_lr=(offset, cfg.num_timesteps) if cfg.anneal_lr else None,
              on_interval=on_interval, on_update=on_update, resume=position, environments=environments,
              stop=asked_to_stop if stop is not None else None, on_stop=on_stop,
              programs=programs, extra_loss=extra_loss)
    total = time.time() - t0
    if logger is None:
        print(f"process {jax.process_index()} done: {remaining:,} steps in {total / 60:.1f} min")
        return {}
    logger.close()
    last = logger.last
    figure = (f"success {last.get('success_rate', math.nan):.0%}, distance {last.get('final_distance', math.nan):.2f} m"
              if logger.task.has_goal or not last else logger.task.progress_figure(last, logger.scales))
    print(f"done: {cfg.num_timesteps:,} steps in {total / 60:.1f} min; last evaluation: {figure}, "
          f"return {last.get('episode_return', math.nan):.1f}; checkpoints in {checkpoint_dir(run_dir)}")
    with contextlib.suppress(FileNotFoundError):  # none when the run saved no checkpoint with a row
        best, _ = selection.best_step(run_dir)
        print(f"the evaluations chose step {best:,}: {run_dir / BEST} (hexa_mjx.training.selection)")
    return last
