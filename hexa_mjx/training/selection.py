"""The evaluation-chosen checkpoint: `RUN/best` names the checkpoint whose training evaluation
scored highest, by its task's `selection_score` (falls count against every task).

    python eval.py --ckpt runs/velocity-s0/best
    python -m hexa_mjx.deploy.export runs/velocity-s0/best -o velocity.onnx

A run keeps a checkpoint at every evaluation and a row for it in metrics.jsonl, so the choice is
read from those rows whenever it is asked for; nothing extra is written during training. It
guards against a policy that became unstable late in a run (docs/RESULTS.md, "The
evaluation-chosen checkpoint"). Ties go to the later checkpoint. The score comes from the run's
own evaluation episodes (`--num_eval_envs`, 32 by default), so measure the chosen checkpoint with
eval.py's larger evaluation before trusting it; `python -m hexa_mjx.training.reselection RUN`
evaluates the last checkpoints again over more episodes, and the choice is then made among those.
"""

from __future__ import annotations

import math
from pathlib import Path


def scored_rows(run_dir: Path) -> list[tuple[int, float]]:
    """(step, score) of each evaluation row of a run that has a complete checkpoint, in step order."""
    from hexa_mjx.tasks import task_class
    from hexa_mjx.training import checks, config, reselection
    from hexa_mjx.training.checkpoints import list_checkpoints
    from hexa_mjx.training.progress import read_rows

    cfg = config.load_config(run_dir)
    task, scales = task_class(cfg.task), checks.run_scales(cfg)
    saved = {step for step, _ in list_checkpoints(run_dir)}
    rows = reselection.read_selection(run_dir)
    if not saved or max(saved) not in {row["step"] for row in rows}:  # it chooses while it covers the latest
        rows = read_rows(run_dir)[0]
    scores = {}
    for row in rows:
        if row["step"] in saved:
            score = float(task.selection_score(row, scales))
            scores[row["step"]] = score if math.isfinite(score) else -math.inf
    return sorted(scores.items())


def best_step(run_dir: Path) -> tuple[int, float]:
    """(step, score) of the run's evaluation-chosen checkpoint; FileNotFoundError if no
    checkpoint has an evaluation row."""
    rows = scored_rows(run_dir)
    if not rows:
        raise FileNotFoundError(f"run {run_dir} has no checkpoint with an evaluation row in metrics.jsonl to choose "
                                "from; pass the run directory for its latest checkpoint")
    return max(reversed(rows), key=lambda item: item[1])
