"""Train a hexapod to walk to a goal with Brax PPO on MuJoCo MJX.

    python train.py --num_envs 256
    python train.py --preset paper --seed 1
    python train.py --run_dir runs/goal_directed-s0 --resume

Flags and defaults: `python train.py --help` (hexa_mjx/config.py, TrainConfig).
"""

import os
import sys
from pathlib import Path

try:
    from hexa_mjx.training import checkpoints, config, distributed, jax_setup, loop as training, resume
    from hexa_mjx.training.checkpoints import CheckpointWriteError
    from hexa_mjx.training.progress import RowWriteError
    from hexa_mjx.training.run_lock import RunLocked
except ImportError as e:  # a missing package, or a MUJOCO_GL that MuJoCo cannot use
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)


def kept(run_dir) -> str:
    """What a stopped run leaves to resume from."""
    saved = checkpoints.list_checkpoints(Path(run_dir))
    return f"its last complete checkpoint (step {saved[-1][0]:,}) is kept" if saved else "it has no checkpoint yet"


def main(argv=None) -> int:
    # A scheduler's SIGTERM (and Ctrl-C) stop training at the next update, with a checkpoint to
    # resume from exactly (hexa_mjx.training.resume); before the first update, and at a second
    # signal, at once.
    preemption = resume.Preemption().install()
    cfg = None
    try:
        cfg = config.parse_args(argv)
        return run(cfg, preemption)
    except resume.StoppedBeforeTraining as e:
        where = f"{kept(cfg.run_dir)}; continue with: python train.py --run_dir {cfg.run_dir} --resume" if cfg else ""
        print(f"{e}: stopped before the first update, with nothing new to save; {where}", file=sys.stderr)
        return resume.EXIT_CODE
    except KeyboardInterrupt:
        print(f"\ninterrupted: {kept(cfg.run_dir) if cfg else 'nothing was trained'}; continue with --resume",
              file=sys.stderr)
        return 130


def run(cfg, preemption) -> int:
    """train.py for a parsed config: errors as one line and an exit code."""
    jax_setup.prepare_jax(cfg.cpu_devices, cfg.compile_cache)  # before anything starts JAX
    try:
        if distributed.initialize(cfg.coordinator, cfg.num_processes, cfg.process_id, cfg.coordinator_timeout):
            # jax.distributed takes SIGTERM for its own preemption notifier; ours answers it as in a
            # one-process run, and the processes agree on the stop at the next update.
            preemption.install()
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
    except (CheckpointWriteError, RowWriteError, distributed.WaitedTooLong) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except resume.Preempted as e:
        run_dir = e.path.parent.parent if e.path is not None else cfg.run_dir
        print(f"stopped at step {e.step:,} with a checkpoint; continue exactly with: python train.py --run_dir "
              f"{run_dir} --resume", file=sys.stderr)
        return resume.EXIT_CODE
    return 0


if __name__ == "__main__":
    code = main()
    if code in (resume.EXIT_CODE, 130):
        # Stopped when asked: every row and checkpoint is on disk, but a compile may still run on a
        # daemon thread (the evaluation's, beside training), and the interpreter's teardown under it
        # can crash (SIGSEGV) instead of exiting with the documented code. So leave at once.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
