"""Several seeds' evaluations in one table: each seed's figures, then the median, the
interquartile range and the worst seed (rliable's way of reporting few runs: Agarwal et al. 2021).

    python -m hexa_mjx.studies.seed_summary runs/velocity-s*/eval256/metrics.json
    python -m hexa_mjx.studies.seed_summary runs/velocity-s*/native.json --json summary.json
    python -m hexa_mjx.studies.seed_summary --targets runs/nav-s*/eval256/metrics.json
    python -m hexa_mjx.studies.seed_summary --battery runs/gen-s*/battery-mjx.json
    python -m hexa_mjx.studies.seed_summary --legs runs/legfail-s*/sweep-leg.json

Reads eval.py's metrics.json and play.py's --json files alike; a figure one of them lacks is "-".
Navigation's evaluations add the worst 45-degree sector or distance band and the goals per episode.
With --targets, a `*` marks each figure that misses the task's targets (`Task.targets`) and a last
line counts the runs that meet every one.
With --battery, the files are the generalist battery's (`hexa_mjx.studies.generalist --json`), and
the table has one row per condition: each seed's path completion, the median, IQR and worst, and
how many seeds meet the condition's target. With --legs, they are leg-failure sweeps
(`hexa_mjx.studies.leg_failure_sweep --out`): one row per set of failed legs, each seed's success
and share of its intact speed, and how many seeds meet the generalist battery's target for one or
two failed legs.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np


def worst_cell(navigation: dict) -> float:
    """The lowest success over eval.py's navigation sectors and distance bands (cells with goals)."""
    cells = [c["success"] for table in ("sectors", "bands") for c in navigation.get(table, {}).values()
             if c.get("success") is not None]
    return min(cells) if cells else math.nan


# (name, where in the file, unit, "max" if the largest value is the worst else "min"); a path is a
# list of alternatives, each a key path: eval.py and play.py name a few figures differently.
FIGURES = (
    ("planar RMS error", [("summary", "tracking", "velocity_rms"), ("tracking", "velocity_rms")], "m/s", "max"),
    ("yaw-rate RMS error", [("summary", "tracking", "yaw_rate_rms"), ("tracking", "yaw_rate_rms")], "rad/s", "max"),
    ("drift told to stand", [("summary", "tracking", "stand_drift", "speed_mean"),
                             ("tracking", "stand_drift", "speed_mean")], "m/s", "max"),
    ("success", [("summary", "success_rate")], "%", "min"),
    ("no fall", [("summary", "fall_rate")], "%", "min"),
    ("feet only", [("summary", "feet_only_steps"), ("summary", "feet_only_share")], "%", "min"),
    # navigation: the first goal's success in its worst 45-degree sector or 0.5 m distance band
    ("worst sector or band", [("summary", "navigation", worst_cell)], "%", "min"),
    ("goals per episode", [("summary", "navigation", "goals_per_episode_mean")], "", "min"),
)
SHARES = {"success", "no fall", "feet only", "worst sector or band"}  # fractions, shown in percent


def _lookup(doc: dict, paths) -> float:
    for path in paths:
        value = doc
        for key in path:  # a key, or a function of the dict reached so far
            if not isinstance(value, dict):
                value = None
                break
            value = key(value) if callable(key) else value.get(key)
        if isinstance(value, (int, float)) and math.isfinite(value):
            return float(value)
    return math.nan


def task_of(doc: dict) -> str | None:
    """The task an evaluation file ran: play.py names it at the top, eval.py in the run's config."""
    return doc.get("task") or (doc.get("config") or {}).get("task")


def figures(doc: dict) -> dict:
    """The FIGURES of one evaluation file's contents (NaN where it has none, and success for a
    task without goals), shares in percent."""
    from hexa_mjx.tasks import TASKS

    task = TASKS.get(task_of(doc))
    out = {}
    for name, paths, _, _ in FIGURES:
        value = math.nan if name == "success" and task is not None and not task.has_goal else _lookup(doc, paths)
        if name == "no fall":
            value = 1.0 - value
        out[name] = 100.0 * value if name in SHARES else value
    return out


def summarize(rows: list[dict]) -> dict:
    """Per figure: median, 25th and 75th percentiles and the worst value over `rows` (NaNs left out)."""
    out = {}
    for name, _, _, worst in FIGURES:
        values = np.array([r[name] for r in rows if math.isfinite(r[name])])
        if values.size:
            q25, median, q75 = np.percentile(values, [25, 50, 75])
            out[name] = {"median": median, "q25": q25, "q75": q75,
                         "worst": values.max() if worst == "max" else values.min()}
    return out


def _cell(name: str, value: float) -> str:
    return "-" if not math.isfinite(value) else (f"{value:.2f}" if name in SHARES else f"{value:.3f}")


def misses(row: dict, targets: dict[str, tuple[str, float]]) -> list[str]:
    """The figures of `row` that miss `targets` (a task's: name -> (">=" or "<=", bound)); a figure
    the row lacks misses."""
    return [name for name, (sense, bound) in targets.items()
            if not (math.isfinite(row.get(name, math.nan))
                    and (row[name] >= bound if sense == ">=" else row[name] <= bound))]


def table(labels: list[str], rows: list[dict], targets: dict | None = None) -> str:
    """A markdown table: one row per run, then median, IQR and worst, of the figures any run has.
    With `targets` (a task's), a `*` marks each figure that misses its target, a target row follows
    and a last line counts the runs that meet every one."""
    stats = summarize(rows)
    names = [n for n, *_ in FIGURES if n in stats]
    units = {n: u for n, _, u, _ in FIGURES}
    missed = [misses(r, targets or {}) for r in rows]
    lines = ["| run | " + " | ".join(f"{n} ({units[n]})" if units[n] else n for n in names) + " |",
             "|---" * (len(names) + 1) + "|"]
    lines += [f"| {label} | " + " | ".join(_cell(n, r[n]) + ("*" if n in m else "") for n in names) + " |"
              for label, r, m in zip(labels, rows, missed)]
    lines.append("| median | " + " | ".join(_cell(n, stats[n]["median"]) for n in names) + " |")
    lines.append("| IQR | " + " | ".join(f"{_cell(n, stats[n]['q25'])} to {_cell(n, stats[n]['q75'])}"
                                         for n in names) + " |")
    lines.append("| worst | " + " | ".join(_cell(n, stats[n]["worst"]) for n in names) + " |")
    if targets:
        lines.append("| target | " + " | ".join(f"{targets[n][0]} {_cell(n, targets[n][1])}" if n in targets else ""
                                                for n in names) + " |")
        meeting = [label for label, m in zip(labels, missed) if not m]
        lines.append(f"\nevery target on {len(meeting)} of {len(rows)} runs"
                     + (f" ({', '.join(meeting)})" if meeting else "") + "; `*`: the run misses that target")
    return "\n".join(lines)


def battery_table(labels: list[str], batteries: list[list[dict]]) -> str:
    """Markdown: one row per battery condition (hexa_mjx.studies.generalist), each seed's share of
    paths completed (`*`: that seed misses the condition's target), their median, IQR and worst, and
    the seeds that meet the target; last, the conditions every seed meets."""
    names = [r["condition"] for r in batteries[0]]
    for label, rows in zip(labels, batteries):
        if [r["condition"] for r in rows] != names:
            raise ValueError(f"{label} ran other conditions than {labels[0]}: give batteries of the same groups")
    lines = ["| condition | " + " | ".join(labels) + " | median | IQR | worst | seeds meeting its target |",
             "|---" * (len(labels) + 5) + "|"]
    every = 0
    for i, name in enumerate(names):
        rows = [rows[i] for rows in batteries]
        done = np.array([100.0 * r["path_completed_rate"] for r in rows])
        q25, median, q75 = np.percentile(done, [25, 50, 75])
        met = sum(bool(r["meets_target"]) for r in rows)
        every += met == len(rows)
        cells = [f"{d:.0f}%{'' if r['meets_target'] else '*'}" for d, r in zip(done, rows)]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {median:.0f}% | {q25:.0f} to {q75:.0f}% | "
                     f"{done.min():.0f}% | {met} of {len(rows)} |")
    lines.append(f"\n{every} of {len(names)} conditions met by every seed (paths completed; `*`: a seed misses "
                 "the target, which for some groups also bounds falls or speed)")
    return "\n".join(lines)


def _percentiles(values: np.ndarray) -> tuple[float, float, float]:
    return tuple(np.nanpercentile(values, [25, 50, 75])) if np.isfinite(values).any() else (math.nan,) * 3


def sweep_table(labels: list[str], sweeps: list[list[dict]]) -> str:
    """Markdown: one row per set of failed legs in leg-failure sweeps (hexa_mjx.studies.leg_failure_sweep),
    each seed's success and share of its intact speed (`*`: that seed misses the target, the
    generalist battery's for one or two failed legs), the median, IQR and worst of each, and the
    seeds that meet the target; last, the failures every seed meets."""
    from hexa_mjx.studies.generalist import meets

    conditions = [tuple(r["failed_legs"]) for r in sweeps[0]]
    for label, rows in zip(labels, sweeps):
        if [tuple(r["failed_legs"]) for r in rows] != conditions:
            raise ValueError(f"{label} failed other legs than {labels[0]}: give sweeps of the same conditions")
    lines = ["| failed legs | " + " | ".join(labels) + " | success: median, IQR, worst | "
             "share of intact speed: median, IQR, worst | seeds meeting its target |",
             "|---" * (len(labels) + 4) + "|"]
    every = failures = 0
    for i, legs in enumerate(conditions):
        rows = [rows[i] for rows in sweeps]
        success = np.array([100.0 * r["success_rate"] for r in rows])
        share = np.array([math.nan if r.get("speed_share_of_intact") is None else 100.0 * r["speed_share_of_intact"]
                          for r in rows])
        group = ("one leg" if len(legs) == 1 else "two legs") if legs else None
        met = [group is None or meets({"group": group, "path_completed_rate": r["success_rate"],
                                       "speed_share_of_intact": r.get("speed_share_of_intact"),
                                       "fall_rate": r.get("fall_rate")}) for r in rows]
        cells = [f"{s:.0f}% / {f'{h:.1f}%' if math.isfinite(h) else '-'}{'' if m else '*'}"
                 for s, h, m in zip(success, share, met)]
        stats = []
        for values in (success, share):
            q25, median, q75 = _percentiles(values)
            stats.append(f"{median:.0f}%, {q25:.0f} to {q75:.0f}%, {np.nanmin(values):.0f}%" if math.isfinite(median)
                         else "-")
        if group is not None:
            failures += 1
            every += all(met)
        lines.append(f"| {' + '.join(map(str, legs)) or 'none'} | " + " | ".join(cells) + f" | {stats[0]} | "
                     f"{stats[1]} | {f'{sum(met)} of {len(met)}' if group else '-'} |")
    lines.append(f"\n{every} of {failures} failures met by every seed (cells: success / share of that seed's intact "
                 "speed; `*`: a seed misses the target, at least 90% and 70% with one leg failed, 75% success "
                 "with two)")
    return "\n".join(lines)


def labels_of(paths: list[Path]) -> list[str]:
    """Each file's run folder, or folder and file name where two files share a folder."""
    folders = [p.parent.name for p in paths]
    return folders if len(set(folders)) == len(folders) else [f"{p.parent.name}/{p.stem}" for p in paths]


def label_of(path: Path) -> str:
    """A run's name from its file: the run folder's (eval.py's metrics.json sits one folder down)."""
    parent = path.parent
    return parent.parent.name if path.name == "metrics.json" else f"{parent.name}/{path.stem}"


# --battery and --legs: (a key every row has, the table, what the files are)
LIST_FILES = {"battery": ("meets_target", battery_table, "the generalist battery's --json files"),
              "legs": ("failed_legs", sweep_table, "the leg-failure sweep's --out files")}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="+", type=Path, help="eval.py metrics.json or play.py --json files, one per seed")
    parser.add_argument("--json", type=Path, help="also write the per-run figures and the summary here")
    parser.add_argument("--battery", action="store_true",
                        help="the files are generalist batteries (python -m hexa_mjx.studies.generalist --json)")
    parser.add_argument("--legs", action="store_true",
                        help="the files are leg-failure sweeps (python -m hexa_mjx.studies.leg_failure_sweep --out)")
    parser.add_argument("--targets", action="store_true",
                        help="mark the figures that miss the task's targets and count the runs that meet every "
                             "one (for the task's own evaluation: eval.py over 256 episodes, no waypoints)")
    args = parser.parse_args(argv)
    if args.battery and args.legs:
        parser.error("--battery and --legs read different files: give one of them")
    if args.targets and (args.battery or args.legs):
        parser.error("--targets applies to evaluation files; the battery and the sweep mark their own targets")
    missing = [str(f) for f in args.files if not f.is_file()]
    if missing:
        parser.error(f"no such file: {', '.join(missing)} (give eval.py's metrics.json or play.py's --json output)")
    mode = "battery" if args.battery else "legs" if args.legs else None
    if mode is not None:  # files of one list of conditions each, told apart by a key of their rows
        key, make_table, what = LIST_FILES[mode]
        docs = [json.loads(f.read_text()) for f in args.files]
        if not all(isinstance(d, list) and d and key in d[0] for d in docs):
            parser.error(f"--{mode} reads {what} (a list of conditions)")
        try:
            print(make_table(labels_of(args.files), docs))
        except ValueError as e:
            parser.error(str(e))
        return
    docs = [json.loads(f.read_text()) for f in args.files]
    rows = [figures(doc) for doc in docs]
    labels = [label_of(f) for f in args.files]
    targets = None
    if args.targets:
        from hexa_mjx.tasks import TASKS

        tasks = {task_of(doc) for doc in docs}
        task = TASKS.get(next(iter(tasks))) if len(tasks) == 1 else None
        if task is None or not task.targets:
            with_targets = sorted(name for name, cls in TASKS.items() if cls.targets)
            parser.error(f"--targets needs evaluations of one task with targets ({', '.join(with_targets)}); "
                         f"these are of {sorted(map(str, tasks))}")
        targets = task.targets
    print(table(labels, rows, targets))
    if args.json:
        out = {"runs": dict(zip(labels, rows)), "summary": summarize(rows)}
        if targets:  # each run's figures that miss their target
            out["misses"] = {label: misses(row, targets) for label, row in zip(labels, rows)}
        args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
