"""The report's studies as grids of train.py runs, and their aggregation into figures and tables.

    python -m hexa_mjx.studies.experiments main       [--timesteps N] [--seeds K] [--out DIR] [--max_contact_points N]
    python -m hexa_mjx.studies.experiments ablation   [...]
    python -m hexa_mjx.studies.experiments lr         [...]
    python -m hexa_mjx.studies.experiments navigate   [...]     # the navigation task, 3 seeds, with and without curriculum
    python -m hexa_mjx.studies.experiments ablation --task navigate   # a study on the navigation task
    python -m hexa_mjx.studies.experiments aggregate  --out DIR      # figures and tables from existing runs
    python -m hexa_mjx.studies.experiments main --ray [ADDRESS] [--run_cpus N] [--run_gpus F]   # runs as Ray tasks
    python -m hexa_mjx.studies.experiments sweep --space SPACE.json --samples N [--ray ADDRESS]  # Ray Tune + ASHA

Runs go to <out>/<study>/<condition>-s<seed>/, each the folder train.py writes. A finished run
(latest checkpoint at or past its budget) is skipped, an interrupted one resumed, so a study can
be re-run until it is complete. A run whose settings equal a finished run of another study in the
same --out folder is linked to it instead of trained again. Runs execute one after another in
this process, each split over one XLA CPU device per core (brax's pmap), so one run keeps every
core busy: running seeds side by side would not finish sooner on a CPU. Each run pays its own compile (about 1.5 min here):
brax's PPO traces afresh per call. With --ray, each run is a Ray task holding --run_cpus cores
(and --run_gpus GPUs) on a local Ray instance or a cluster: hexa_mjx.studies.ray_runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

from hexa_mjx.training import checkpoints, config, jax_setup, loop as training
from hexa_mjx import tasks
from hexa_mjx.studies.study_results import STUDIES, aggregate

MAIN_REWARDS = ("goal_directed", "forward_motion")
ABLATION_CONDITIONS = {"full": [], "no_contact": ["contact"], "no_height": ["height"],
                       "no_stability": ["stability"], "no_velocity": ["velocity"]}
LEARNING_RATES = (1e-4, 3e-4, 1e-3)
DEFAULT_SEEDS = {"main": 5, "ablation": 1, "lr": 2, "navigate": 3, "energy": 3}
ENERGY_REWARDS = ("goal_directed", "energy")


@dataclasses.dataclass(frozen=True)
class Run:
    study: str
    condition: str
    seed: int
    config: config.TrainConfig


def grid(study: str, out: Path, timesteps: int = 2_000_000, seeds: int | None = None,
         num_envs: int = 256, task: str = tasks.DEFAULT_TASK, **common) -> list[Run]:
    """The runs of one study (report sections 4.2 to 4.4, or the navigation task's seeds) on `task`;
    `common` sets other TrainConfig fields of every run. A study on another task than the report's
    goes to <out>/<study>-<task>/."""
    if study not in STUDIES:
        raise ValueError(f"unknown study {study!r}; choose one of {STUDIES}")
    seeds = DEFAULT_SEEDS[study] if seeds is None else seeds
    if study == "navigate":
        study, task = "seeds", "navigate"
    elif study in ("main", "energy") and task != tasks.DEFAULT_TASK:
        raise ValueError(f"the {study} study compares rewards of the report's task; run it without --task")
    folder = study if task == tasks.DEFAULT_TASK else f"{study}-{task}"
    if seeds < 1:
        raise ValueError(f"--seeds must be at least 1, got {seeds}")
    if study == "main":
        conditions = {reward: {"reward": reward} for reward in MAIN_REWARDS}
    elif study == "energy":  # the report's reward against the energy-minimizing one (issue: gait)
        conditions = {reward: {"reward": reward} for reward in ENERGY_REWARDS}
    elif study == "seeds":
        # The settings of the documented navigation runs (docs/RESULTS.md): 4 epochs, joint start noise;
        # with and without the curriculum.
        recipe = {"update_epochs": 4, "start_joint_noise": 0.1}
        conditions = {"navigate": recipe, "curriculum": {**recipe, "curriculum_levels": 5}}
    elif study == "ablation":
        conditions = {name: {"ablate": ablate} for name, ablate in ABLATION_CONDITIONS.items()}
    else:
        conditions = {f"lr_{lr:g}": {"lr": lr} for lr in LEARNING_RATES}
    runs = []
    for condition, settings in conditions.items():
        for seed in range(seeds):
            run_dir = Path(out) / folder / f"{condition}-s{seed}"
            cfg = config.TrainConfig(num_envs=num_envs, num_timesteps=timesteps, seed=seed, task=task,
                                     run_dir=str(run_dir), **common, **settings)
            cfg = dataclasses.replace(cfg, reward=cfg.reward or tasks.default_reward(task))
            runs.append(Run(study, condition, seed, cfg))
    return runs


def _finished(run_dir: Path, budget: int) -> bool:
    """Whether the run in `run_dir` has a checkpoint at or past `budget` steps."""
    found = checkpoints.list_checkpoints(run_dir)
    return bool(found) and found[-1][0] >= budget


def status(run: Run) -> str:
    """'done', 'partial' (resumable) or 'new'."""
    run_dir = Path(run.config.run_dir)
    if _finished(run_dir, run.config.num_timesteps):
        return "done"
    return "partial" if (run_dir / "config.json").is_file() else "new"


def finished_twin(run: Run) -> Path | None:
    """A finished run of any study in the same output folder with exactly this run's settings
    (the grids overlap: the main study's goal_directed seeds, the ablation's "full" and the lr
    study's 3e-4 are the same training at the same budget, and training is deterministic)."""
    run_dir = Path(run.config.run_dir)
    same = dataclasses.replace(run.config, run_dir="", resume=False)
    for saved_config in sorted(run_dir.parent.parent.glob("*/*/config.json")):
        other = saved_config.parent
        if other == run_dir or other.is_symlink():
            continue
        saved = dataclasses.replace(config.load_config(other), run_dir="", resume=False)
        if saved == same and _finished(other, run.config.num_timesteps):
            return other
    return None


def plan(runs: list[Run]) -> tuple[list[config.TrainConfig], dict[str, int]]:
    """The configs still to train (resume set for interrupted ones) and how many runs were skipped
    as finished, reused from an identical finished run of another study (linked, not trained
    again), resumed and started."""
    counts = {"done": 0, "reused": 0, "partial": 0, "new": 0}
    todo = []
    for run in runs:
        state = status(run)
        run_dir = Path(run.config.run_dir)
        if run_dir.is_symlink() and state != "done":
            # A link to another study's run that now has a larger budget: never train into that run.
            run_dir.unlink()
            state = "new"
        twin = finished_twin(run) if state == "new" else None
        if twin is not None:
            state = "reused"
            run_dir.parent.mkdir(parents=True, exist_ok=True)
            run_dir.symlink_to(os.path.relpath(twin, run_dir.parent), target_is_directory=True)
            print(f"reuse {run_dir}: links to {twin}, a finished run with the same settings")
        counts[state] += 1
        if state == "done":
            print(f"skip {run.config.run_dir}: finished")
        elif state != "reused":
            todo.append(dataclasses.replace(run.config, resume=state == "partial"))
    return todo, counts


def run_study(runs: list[Run], train_fn=training.train) -> dict[str, int]:
    """Train every run that is not finished, one after another; returns plan()'s counts."""
    todo, counts = plan(runs)
    for cfg in todo:
        train_fn(cfg)
    return counts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.experiments", description=__doc__.split("\n\n")[0])
    parser.add_argument("study", choices=[*STUDIES, "aggregate", "sweep"],
                        help="which study to run, aggregate only, or a hyperparameter sweep on Ray Tune")
    parser.add_argument("--timesteps", type=int, default=2_000_000, help="env steps per run (default: 2M)")
    parser.add_argument("--seeds", type=int, default=None, help="seeds per condition (default: main 5, ablation 1, lr 2, navigate 3)")
    parser.add_argument("--num_envs", type=int, default=256, help="environments per run (default: 256)")
    parser.add_argument("--out", type=Path, default=Path("experiments"), help="output folder (default: experiments)")
    parser.add_argument("--task", default=tasks.DEFAULT_TASK, choices=sorted(tasks.TASKS),
                        help="the task every run trains on (default: goal, the report's)")
    parser.add_argument("--max_contact_points", type=int, default=0,
                        help="MJX keeps only this many deepest robot-floor contact points per step (default 0: all)")
    parser.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                        help="run each training as a Ray task: on the cluster at ADDRESS (HOST:PORT, ray://HOST:PORT, "
                             "auto), or with no ADDRESS on a local Ray instance")
    parser.add_argument("--run_cpus", type=int, default=1, help="with --ray: CPU cores each run holds (default 1)")
    parser.add_argument("--run_gpus", type=float, default=0.0,
                        help="with --ray: GPUs each run holds; a fraction shares one GPU (default 0)")
    parser.add_argument("--space", type=Path, help="sweep: JSON search space over train.py flags (ray_runs.load_space)")
    parser.add_argument("--samples", type=int, default=8, help="sweep: trials (default 8)")
    parser.add_argument("--metric", default="episode_return", choices=["episode_return", "success_rate"],
                        help="sweep: the evaluation figure ASHA ranks trials by (default episode_return, which "
                             "separates trials long before any reaches the goal)")
    parser.add_argument("--num_evals", type=int, default=10, help="sweep: evaluations per trial, ASHA's rungs (default 10)")
    args = parser.parse_args(argv)
    try:
        if args.run_cpus < 1 or args.run_gpus < 0:
            raise ValueError(f"--run_cpus must be at least 1 and --run_gpus at least 0, got {args.run_cpus}, {args.run_gpus}")
        if args.study == "sweep":
            return sweep_main(args)
        if args.study != "aggregate":
            if args.ray is None:
                jax_setup.prepare_jax()  # before anything starts JAX: one device per core
            runs = grid(args.study, args.out, args.timesteps, args.seeds, args.num_envs, task=args.task,
                        max_contact_points=args.max_contact_points)
            for run in runs:  # every run's settings are checked before the first one compiles
                config.validate(dataclasses.replace(run.config, resume=status(run) != "new"))
            if args.ray is None:
                print(run_study(runs))
            else:
                from hexa_mjx.studies import ray_runs

                ray_runs.check_address(args.ray)
                todo, counts = plan(runs)
                ray_runs.start(args.ray)
                ray_runs.run_grid(todo, args.run_cpus, args.run_gpus)
                print(counts)
        paths = aggregate(args.out)
    except (ValueError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except RuntimeError as e:  # a run failed on Ray; the others are finished and kept
        print(f"error: {e}", file=sys.stderr)
        return 1
    for path in paths:
        print(f"wrote {path}")
    return 0


def sweep_main(args) -> int:
    """`experiments sweep`: Ray Tune over --space, results table and plot, the best run's command."""
    from hexa_mjx.studies import ray_runs

    if args.space is None:
        raise ValueError("sweep needs --space SPACE.json, e.g. "
                         '{"lr": {"loguniform": [1e-4, 1e-3]}, "update_epochs": {"choice": [2, 4, 8]}}')
    if args.samples < 1:
        raise ValueError(f"--samples must be at least 1, got {args.samples}")
    space = ray_runs.load_space(args.space)
    base = config.TrainConfig(num_envs=args.num_envs, num_timesteps=args.timesteps, task=args.task,
                              num_evals=args.num_evals, max_contact_points=args.max_contact_points)
    base = dataclasses.replace(base, reward=tasks.default_reward(args.task),
                               cpu_devices=ray_runs.cpu_devices(base, args.run_cpus, args.run_gpus))
    config.check_ranges(base)
    ray_runs.check_address(args.ray or "local")
    ray_runs.start(args.ray or "local")
    out = args.out / "sweep"
    rows = ray_runs.sweep(base, space, args.samples, out, args.metric, args.run_cpus, args.run_gpus)
    for path in ray_runs.write_sweep(rows, space, args.metric, out):
        print(f"wrote {path}")
    top = ray_runs.best(rows, args.metric, base.num_timesteps)
    cfg = dataclasses.replace(base, **{k: top[k] for k in space}, run_dir="runs/sweep-best")
    print(f"best: {args.metric} {top[args.metric]:.4g} (success {top['success_rate']:.0%}, return "
          f"{top['episode_return']:.1f}) in {top['run_dir']}\nrepeat it with:\n  {ray_runs.command_line(cfg)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
