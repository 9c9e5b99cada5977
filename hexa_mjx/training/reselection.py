"""A larger evaluation of a run's last checkpoints, to choose among them.

    python -m hexa_mjx.training.reselection runs/navigate-s1 --last 4 --episodes 256

A run's training evaluations (`--num_eval_envs`, 32 episodes by default) rank its late
checkpoints by a few episodes each: a fall rate of 3% against 0% there is one fall in 32. This
evaluates each of the run's last `--last` checkpoints again as training does (the same
environment, wrappers and deterministic policy, scored by the task's `selection_score`), over
`--episodes` episodes drawn from `--seed` (default: the run's seed + 1, so they are not its
training evaluations' episodes). The rows go to `RUN/selection.jsonl`, and from then on `RUN/best`
(hexa_mjx.training.selection) names the checkpoint that scored highest there, for as long as those
rows include the run's latest checkpoint: a run trained on past them is chosen by its training
evaluations again. Like training, it holds the run's lock while it writes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

SELECTION_FILE = "selection.jsonl"


def reselect(run_dir: Path, last: int = 4, episodes: int = 256, seed: int | None = None) -> list[dict]:
    """Evaluate the run's last `last` checkpoints over `episodes` episodes each and write their rows
    (step, episodes, seed, score and the training row's figures) to RUN/selection.jsonl."""
    from hexa_mjx import atomic
    from hexa_mjx.mdp import randomization
    from hexa_mjx.tasks import task_class
    from hexa_mjx.training import checks
    from hexa_mjx.training.checkpoints import list_checkpoints, load_checkpoint
    from hexa_mjx.training.config import load_config, make_env_for
    from hexa_mjx.training.jax_setup import prepare_jax
    from hexa_mjx.training.loop import evaluator_for, program_description
    from hexa_mjx.training.networks import templates
    from hexa_mjx.training.progress import evaluation_figures
    from hexa_mjx.training.run_lock import RunLock

    run_dir = Path(run_dir)
    cfg = load_config(run_dir)
    found = list_checkpoints(run_dir)[-last:]
    if not found:
        raise FileNotFoundError(f"run {run_dir} has no complete checkpoint to evaluate; train it first")
    seed = cfg.seed + 1 if seed is None else seed
    prepare_jax(cpu_devices=cfg.cpu_devices, compile_cache=cfg.compile_cache)
    with RunLock(run_dir):
        env = make_env_for(cfg)
        template, _ = templates(cfg, env)
        randomization_fn = randomization.randomization_fn(env) if cfg.randomize else None
        evaluator = evaluator_for(cfg, env, randomization_fn, template, episodes, seed,
                                  programs=program_description(cfg, 0))  # kept: a second call compiles nothing
        task, scales = task_class(cfg.task), checks.run_scales(cfg)
        rows = []
        for step, path in found:
            metrics = evaluator(load_checkpoint(path, template)[1])
            row = {"step": step, "episodes": episodes, "seed": seed, **evaluation_figures(metrics)}
            row["score"] = float(task.selection_score(row, scales))
            rows.append(row)
            print(f"step {step:>12,}: score {row['score']:.4f}, falls {row['fall_rate']:.2%} "
                  f"({episodes} episodes, {metrics['eval/epoch_eval_time']:.0f} s)", flush=True)
        atomic.write(run_dir / SELECTION_FILE, "".join(json.dumps(row) + "\n" for row in rows))
    return rows


def read_selection(run_dir: Path) -> list[dict]:
    """RUN/selection.jsonl's rows, none when the file is missing; a line that is not a row (a hand
    edit gone wrong) is left out, as metrics.jsonl's are."""
    from hexa_mjx.training.progress import read_rows

    return read_rows(run_dir, SELECTION_FILE)[0]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.training.reselection", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path, help="the run directory")
    parser.add_argument("--last", type=int, default=4,
                        help="how many of its latest checkpoints to evaluate (default 4)")
    parser.add_argument("--episodes", type=int, default=256, help="episodes per checkpoint (default 256)")
    parser.add_argument("--seed", type=int, default=None, help="the episodes' seed (default: the run's seed + 1)")
    args = parser.parse_args(argv)
    if args.last < 1 or args.episodes < 1:
        parser.error("--last and --episodes count checkpoints and episodes: give 1 or more")
    if not (args.run_dir / "config.json").is_file():
        parser.error(f"{args.run_dir} is not a run directory (it has no config.json)")
    reselect(args.run_dir, args.last, args.episodes, args.seed)
    from hexa_mjx.training import selection

    step, score = selection.best_step(args.run_dir)
    print(f"{args.run_dir / 'best'} is now step {step:,} (score {score:.4f})")


if __name__ == "__main__":
    main()
