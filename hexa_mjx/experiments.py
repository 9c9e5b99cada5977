"""The report's studies as grids of train.py runs, and their aggregation into figures and tables.

    python -m hexa_mjx.experiments main       [--timesteps N] [--seeds K] [--out DIR] [--max_contact_points N]
    python -m hexa_mjx.experiments ablation   [...]
    python -m hexa_mjx.experiments lr         [...]
    python -m hexa_mjx.experiments navigate   [...]     # the navigation task, 3 seeds
    python -m hexa_mjx.experiments ablation --task navigate   # a study on the navigation task
    python -m hexa_mjx.experiments aggregate  --out DIR      # figures and tables from existing runs

Runs go to <out>/<study>/<condition>-s<seed>/, each the folder train.py writes. A finished run
(latest checkpoint at or past its budget) is skipped, an interrupted one resumed, so a study can
be re-run until it is complete. A run whose settings equal a finished run of another study in the
same --out folder is linked to it instead of trained again. Runs execute one after another in
this process, each split over one XLA CPU device per core (brax's pmap), so one run keeps every
core busy: running seeds side by side would not finish sooner on a CPU. Each run pays its own compile (about 1.5 min here):
brax's PPO traces afresh per call.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import sys
from pathlib import Path

from hexa_mjx import checkpoints, config, jax_setup, tasks, training

STUDIES = ("main", "ablation", "lr", "navigate", "energy")
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
         num_envs: int = 256, task: str = "goal", **common) -> list[Run]:
    """The runs of one study (report sections 4.2 to 4.4, or the navigation task's seeds) on `task`;
    `common` sets other TrainConfig fields of every run. A study on another task than the report's
    goes to <out>/<study>-<task>/."""
    if study not in STUDIES:
        raise ValueError(f"unknown study {study!r}; choose one of {STUDIES}")
    seeds = DEFAULT_SEEDS[study] if seeds is None else seeds
    if study == "navigate":
        study, task = "seeds", "navigate"
    elif study in ("main", "energy") and task != "goal":
        raise ValueError(f"the {study} study compares rewards of the report's task; run it without --task")
    folder = study if task == "goal" else f"{study}-{task}"
    if seeds < 1:
        raise ValueError(f"--seeds must be at least 1, got {seeds}")
    if study == "main":
        conditions = {reward: {"reward": reward} for reward in MAIN_REWARDS}
    elif study == "energy":  # the report's reward against the energy-minimizing one (issue: gait)
        conditions = {reward: {"reward": reward} for reward in ENERGY_REWARDS}
    elif study == "seeds":
        # The settings of the documented navigation run (docs/RESULTS.md): 4 epochs, joint start noise.
        conditions = {"navigate": {"update_epochs": 4, "start_joint_noise": 0.1}}
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
            cfg = dataclasses.replace(cfg, reward=cfg.reward or tasks.task_class(task).rewards[0])
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


def run_study(runs: list[Run], train_fn=training.train) -> dict[str, int]:
    """Train every run that is not finished; returns how many were skipped, reused from an
    identical finished run of another study (linked, not trained again), resumed and started."""
    counts = {"done": 0, "reused": 0, "partial": 0, "new": 0}
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
            train_fn(dataclasses.replace(run.config, resume=state == "partial"))
    return counts


# ---------------------------------------------------------------------------
# Aggregation


def load_runs(out: Path) -> list[dict]:
    """Every run folder under <out>/<study>/ with its metrics rows."""
    found = []
    for metrics in sorted(Path(out).glob("*/*/metrics.jsonl")):
        run_dir = metrics.parent
        condition, _, seed = run_dir.name.rpartition("-s")
        rows = [json.loads(line) for line in metrics.read_text().splitlines() if line.strip()]
        if rows and seed.isdigit():
            found.append({"study": run_dir.parent.name, "condition": condition, "seed": int(seed), "rows": rows})
    return found


def _mean_std(values):
    values = [v for v in values if v is not None and math.isfinite(v)]
    if not values:
        return math.nan, math.nan
    mean = sum(values) / len(values)
    return mean, math.sqrt(sum((v - mean) ** 2 for v in values) / len(values))


def final_table(runs: list[dict]) -> list[dict]:
    """Per (study, condition): final success rate, distance and return, mean and std over seeds."""
    groups: dict[tuple, list[dict]] = {}
    for run in runs:
        groups.setdefault((run["study"], run["condition"]), []).append(run["rows"][-1])
    table = []
    for (study, condition), last in sorted(groups.items()):
        row = {"study": study, "condition": condition, "seeds": len(last), "steps": min(r["step"] for r in last)}
        for key in ("success_rate", "final_distance", "episode_return"):
            row[f"{key}_mean"], row[f"{key}_std"] = _mean_std([r.get(key) for r in last])
        table.append(row)
    return table


def write_tables(table: list[dict], out: Path) -> tuple[Path, Path]:
    csv_path, md_path = out / "results.csv", out / "results.md"
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table)
    lines = ["| study | condition | seeds | steps | success rate | final distance (m) | return |", "|---|---|---|---|---|---|---|"]
    for r in table:
        lines.append(f"| {r['study']} | {r['condition']} | {r['seeds']} | {r['steps']:,} | "
                     f"{r['success_rate_mean']:.2f} +- {r['success_rate_std']:.2f} | "
                     f"{r['final_distance_mean']:.3f} +- {r['final_distance_std']:.3f} | "
                     f"{r['episode_return_mean']:.1f} +- {r['episode_return_std']:.1f} |")
    md_path.write_text("\n".join(lines) + "\n")
    return csv_path, md_path


def gait_table(out: Path) -> list[dict]:
    """Per (study, condition), from each run's `eval/metrics.json` (python eval.py --ckpt RUN):
    success, gait classes over seeds, path speed and cost of transport, mean and std over seeds."""
    groups: dict[tuple, list[dict]] = {}
    for path in sorted(Path(out).glob("*/*/eval/metrics.json")):
        summary = json.loads(path.read_text())["summary"]
        if "gait" in summary:
            run_dir = path.parent.parent
            groups.setdefault((run_dir.parent.name, run_dir.name.rpartition("-s")[0]), []).append(summary)
    table = []
    for (study, condition), runs in sorted(groups.items()):
        row = {"study": study, "condition": condition, "seeds": len(runs),
               "gait_classes": ", ".join(r["gait"]["class"] for r in runs)}
        row["success_mean"], _ = _mean_std([r["success_rate"] for r in runs])
        row["speed_mean"], row["speed_std"] = _mean_std([r["gait"].get("speed") for r in runs])
        row["cot_mean"], row["cot_std"] = _mean_std([r["gait"].get("cost_of_transport_median") for r in runs])
        table.append(row)
    return table


def write_gait_table(table: list[dict], out: Path) -> Path:
    lines = ["| study | condition | seeds | success | gait class per seed | path speed (m/s) | cost of transport |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['study']} | {r['condition']} | {r['seeds']} | {r['success_mean']:.0%} | {r['gait_classes']} | "
              f"{r['speed_mean']:.3f} +- {r['speed_std']:.3f} | {r['cot_mean']:.2f} +- {r['cot_std']:.2f} |"
              for r in table]
    path = out / "gait.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _curves(ax, runs, key, label_of):
    """Mean line and +-std band over seeds for each label."""
    by_label: dict[str, list[dict]] = {}
    for run in runs:
        by_label.setdefault(label_of(run), []).append(run)
    for label, group in sorted(by_label.items()):
        steps = sorted({r["step"] for run in group for r in run["rows"]})
        stats = [_mean_std([next((r.get(key) for r in run["rows"] if r["step"] == s), None) for run in group])
                 for s in steps]
        mean = [m for m, _ in stats]
        ax.plot(steps, mean, label=label)
        ax.fill_between(steps, [m - s for m, s in stats], [m + s for m, s in stats], alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.grid(alpha=0.3)


def plot_figures(runs: list[dict], out: Path) -> list[Path]:
    """The report's Figures 1 to 4, for the studies present under `out`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    by_study = {s: [r for r in runs if r["study"] == s] for s in STUDIES}

    def save(fig, name):
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        written.append(out / name)

    if by_study["main"]:
        fig, axes = plt.subplots(1, 3, figsize=(15, 4), constrained_layout=True)
        for ax, (key, label) in zip(axes, [("final_distance", "(a) distance to goal (m)"),
                                           ("episode_return", "(b) episodic return"),
                                           ("goal_bonus", "(c) goal bonus")]):
            _curves(ax, by_study["main"], key, lambda r: r["condition"])
            ax.set_ylabel(label)
        axes[0].legend()
        save(fig, "fig1_main.png")
        fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
        for run in by_study["main"]:
            if run["condition"] == "goal_directed":
                ax.plot([r["step"] for r in run["rows"]], [r["final_distance"] for r in run["rows"]],
                        label=f"seed {run['seed']}")
        ax.set_xlabel("environment steps")
        ax.set_ylabel("distance to goal (m), goal-directed")
        ax.legend()
        save(fig, "fig2_seeds.png")
    for study, name, label_of in (("lr", "fig3_lr.png", lambda r: r["condition"]),
                                  ("ablation", "fig4_ablation.png", lambda r: r["condition"])):
        if by_study[study]:
            fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
            _curves(ax, by_study[study], "final_distance", label_of)
            ax.set_ylabel("distance to goal (m)")
            ax.legend()
            save(fig, name)
    navigation = [r for r in runs if r["study"].endswith("-navigate")]
    if navigation:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
        label_of = lambda r: f"{r['study']}/{r['condition']}"  # noqa: E731
        _curves(axes[0], navigation, "goals_per_episode", label_of)
        axes[0].set_ylabel("goals reached per episode")
        _curves(axes[1], navigation, "fall_rate", label_of)
        axes[1].set_ylabel("fall rate")
        axes[0].legend()
        save(fig, "fig5_navigate.png")
    return written


def aggregate(out: Path) -> list[Path]:
    """Figures, CSV and markdown tables from the run folders under `out` (gait.md from the runs
    that eval.py has evaluated: `python eval.py --ckpt RUN` writes RUN/eval/metrics.json)."""
    runs = load_runs(out)
    if not runs:
        raise FileNotFoundError(f"no run folders with metrics.jsonl under {out}/<study>/")
    written = plot_figures(runs, Path(out)) + list(write_tables(final_table(runs), Path(out)))
    gaits = gait_table(Path(out))  # runs evaluated with eval.py (gait and cost of transport)
    return written + ([write_gait_table(gaits, Path(out))] if gaits else [])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.experiments", description=__doc__.split("\n\n")[0])
    parser.add_argument("study", choices=[*STUDIES, "aggregate"], help="which study to run, or aggregate only")
    parser.add_argument("--timesteps", type=int, default=2_000_000, help="env steps per run (default: 2M)")
    parser.add_argument("--seeds", type=int, default=None, help="seeds per condition (default: main 5, ablation 1, lr 2, navigate 3)")
    parser.add_argument("--num_envs", type=int, default=256, help="environments per run (default: 256)")
    parser.add_argument("--out", type=Path, default=Path("experiments"), help="output folder (default: experiments)")
    parser.add_argument("--task", default="goal", choices=sorted(tasks.TASKS),
                        help="the task every run trains on (default: goal, the report's)")
    parser.add_argument("--max_contact_points", type=int, default=0,
                        help="MJX keeps only this many deepest robot-floor contact points per step (default 0: all)")
    args = parser.parse_args(argv)
    try:
        if args.study != "aggregate":
            jax_setup.prepare_jax()  # before anything starts JAX: one device per core
            runs = grid(args.study, args.out, args.timesteps, args.seeds, args.num_envs, task=args.task,
                        max_contact_points=args.max_contact_points)
            for run in runs:  # every run's settings are checked before the first one compiles
                config.validate(dataclasses.replace(run.config, resume=status(run) != "new"))
            print(run_study(runs))
        paths = aggregate(args.out)
    except (ValueError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for path in paths:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
