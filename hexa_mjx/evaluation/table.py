"""eval.py's table: one line per figure, the task's own figures among them."""

from __future__ import annotations

from hexa_mjx.evaluation import gait


def format_table(summary: dict, task=None) -> str:
    """The summary as aligned rows; `task` (a hexa_mjx.tasks class) adds its own."""
    goal = task is None or task.has_goal  # a task without a goal (velocity) has no distance figures
    rows = [("episodes", f"{summary['episodes']}")]
    if goal:
        rows += [("success rate", f"{summary['success_rate']:.1%}"),
                 ("final distance, mean", f"{summary['final_distance_mean']:.3f} m"),
                 ("final distance, median", f"{summary['final_distance_median']:.3f} m"),
                 ("minimum distance, mean", f"{summary['min_distance_mean']:.3f} m"),
                 ("goal bonus, mean", f"{summary['goal_bonus_mean']:.1f}")]
    rows += [("return, mean +- std", f"{summary['return_mean']:.1f} +- {summary['return_std']:.1f}"),
            ("fall rate", f"{summary['fall_rate']:.1%}"),
            ("non-finite physics endings", f"{summary['nonfinite_rate']:.1%}"),
            ("mean speed", f"{summary['mean_speed']:.3f} m/s"),
            ("episode length, mean", f"{summary['episode_length_mean']:.0f} steps")]
    steps = summary["steps_to_goal_mean"]
    if goal:
        rows.append(("steps to the goal, mean of successes", "-" if steps is None else f"{steps:.0f}"))
    if goal and "body_contact_before_goal_mean" in summary:
        rows.append(("body contact before the goal, mean", f"{summary['body_contact_before_goal_mean']:.1f}"))
    # Without a goal, every step is "after" it (the goal stays at the start, within the radius at once).
    for phase in ("before_goal", "after_goal") if goal else ("after_goal",):
        if f"contacts_{phase}" in summary:
            counts = summary[f"contacts_{phase}"]
            counts = "-" if counts is None else ", ".join(f"{k} {v:.2f}" for k, v in counts.items())
            rows.append((f"floor contacts per step, {phase.replace('_', ' ') if goal else 'mean'}", counts))
    if "contact_points_max" in summary:
        cap = summary["contact_cap"]
        kept = (f"physics keeps {cap}; at that cap in {summary['steps_at_contact_cap']:,} of {summary['steps']:,} "
                "steps" if cap else "physics keeps every contact")
        rows.append(("floor contact points at once, most", f"{summary['contact_points_max']} ({kept})"))
    if "feet_only_steps" in summary:
        rows.append(("steps with only feet on the floor", f"{summary['feet_only_steps']:.2%}"))
    if "gait" in summary:
        rows += gait.table_rows(summary["gait"])
    rows += task.table_rows(summary) if task is not None else []
    rows += [(f"  reward/{k}, per episode", f"{v:.1f}") for k, v in summary["reward_terms"].items()]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
