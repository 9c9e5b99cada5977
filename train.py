"""Train a hexapod to walk to a goal with Brax PPO on MuJoCo MJX.

    python train.py --num_envs 256
    python train.py --preset paper --seed 1
    python train.py --run_dir runs/goal_directed-s0 --resume

Flags and defaults: `python train.py --help` (hexa_mjx/config.py, TrainConfig).
"""

import signal
import sys

try:
    from hexa_mjx.training import config, distributed, jax_setup, loop as training
except ImportError as e:  # a missing package, or a MUJOCO_GL that MuJoCo cannot use
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main(argv=None) -> int:
    # A scheduler's SIGTERM (and Ctrl-C) stop training between programs, keeping the last checkpoint.
    signal.signal(signal.SIGTERM, _interrupt)
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
        training.train(cfg)
    except KeyboardInterrupt:
        print("\ninterrupted: the last complete checkpoint is kept; continue with --resume", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
