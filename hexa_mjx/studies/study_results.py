"""A study's results from its run folders: tables (CSV, markdown), the report's figures, gait table.

`python -m hexa_mjx.studies.experiments aggregate --out DIR` calls `aggregate(DIR)`; every study command
ends with it.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

STUDIES = ("main", "ablation", "lr", "navigate", "energy")  # the study folders the figures know

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


