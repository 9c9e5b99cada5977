"""Train a hexapod to walk to a goal with Brax PPO on MuJoCo MJX.

    python train.py --num_envs 256
    python train.py --preset paper --seed 1
    python train.py --run_dir runs/goal_directed-s0 --resume

Flags and defaults: `python train.py --help` (hexa_mjx/config.py, TrainConfig).
"""

import sys

try:
    from hexa_mjx.training import config, distributed, jax_setup, loop as training, resume
    from hexa_mjx.training.checkpoints import CheckpointWriteError
    from hexa_mjx.training.progress import RowWriteError
    from hexa_mjx.training.run_lock import RunLocked
except ImportError as e:  # a missing package, or a MUJOCO_GL that MuJoCo cannot use
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)


def main(argv=None) -> int:
    # A scheduler's SIGTERM (and Ctrl-C) stop training at the next update, with a checkpoint to
    # resume from exactly (hexa_mjx.training.resume); a second one stops at once.
    preemption = resume.Preemption().install()
    cfg = config.parse_args(argv)
    jax_setup.prepare_jax(cfg.cpu_devices, cfg.compile_cache)  # before anything starts JAX
    try:
        distributed.initialize(cfg.coordinator, cfg.num_processes, cfg.process_id, cfg.coordinator_timeout)
    except distributed.DistributedError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    error = ""
    try:
        config.validate(cfg, writes=distributed.is_main())
    except (config.ConfigError, ValueError, TypeError) as e:
        error = str(e)
    # Every process of a multi-process run checks the others' settings, so all stop together.
    error = distributed.agree(cfg, error, config.PER_PROCESS)
    if error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        training.train(cfg, stop=preemption)
    except RunLocked as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except (CheckpointWriteError, RowWriteError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except resume.Preempted as e:
        run_dir = e.path.parent.parent if e.path is not None else cfg.run_dir
        print(f"stopped at step {e.step:,} with a checkpoint; continue exactly with: python train.py --run_dir "
              f"{run_dir} --resume", file=sys.stderr)
        return resume.EXIT_CODE
    except KeyboardInterrupt:
        print("\ninterrupted: the last complete checkpoint is kept; continue with --resume", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
