"""Learning curves from run directories' metrics.jsonl.

    python -m hexa_mjx.evaluation.plots runs/goal_directed-s0 runs/goal_directed-s1 -o docs/img/curves.png
    python -m hexa_mjx.evaluation.plots --frames runs/goal_directed-s0/eval/episode_0.mp4 [--every 40 --count 6] -o frames.png

One panel per figure (final distance to goal, success rate, episodic return, goal bonus; for
navigation runs goals reached per episode instead of the bonus; with a curriculum also falls and
the mean level; with a leg-failure schedule falls and each leg's chance of failing) against
environment steps, one line per run, labelled by the run directory's name. `plot_paths` draws
torso tracks from above.
"""

from __future__ import annotations

from hexa_mjx import atomic

import argparse
import json
from pathlib import Path

LEG_P = "leg_failure/p_leg"  # metrics.jsonl's key prefix of each leg's chance of failing (hexa_mjx.mdp.failure_schedule)
PANELS = [("final_distance", "distance to goal at episode end (m)"), ("success_rate", "success rate"),
          ("episode_return", "episodic return"), ("goal_bonus", "goal bonus per episode")]
TRACKING = "eval/episode_reward/tracking_"  # the velocity task's tracking terms, weighted, per evaluation episode
VELOCITY_PANELS = [(TRACKING + "lin_vel", "planar tracking reward per episode"),
                   (TRACKING + "ang_vel", "yaw-rate tracking reward per episode"),
                   ("episode_return", "episodic return"), ("episode_length", "episode length (control steps)")]


def read_metrics(run_dir: Path) -> list[dict]:
    path = Path(run_dir) / "metrics.jsonl"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: is {run_dir} a train.py run directory?")
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def panels_for(rows: list[dict]) -> list[tuple[str, str]]:
    """The (metric, label) panels that suit a run: the tracking terms for velocity commands, which
    have no goal; goals per episode instead of the bonus for navigation; the mean curriculum level
    when the run had a curriculum."""
    if any(TRACKING + "lin_vel" in r for r in rows):
        panels = list(VELOCITY_PANELS)
    else:
        panels = list(PANELS)
        if any(r.get("goals_per_episode", 0) > 0 for r in rows):
            panels[3] = ("goals_per_episode", "goals reached per episode")
    falls = ("fall_rate", "falls (share of evaluation episodes)")
    if any("curriculum/level_mean" in r for r in rows):
        panels += [falls, ("curriculum/level_mean", "mean curriculum level (0: easiest)")]
    if any(f"{LEG_P}1" in r for r in rows):
        panels += [falls] * (falls not in panels) + [(f"{LEG_P}*", "chance of each leg being the failed one")]
    return panels


def series(rows: list[dict], key: str) -> dict[str, list[float]]:
    """{line label suffix: values} of a panel's `key`: one line, or one per leg for `<prefix>*`."""
    if not key.endswith("*"):
        return {"": [r.get(key, float("nan")) for r in rows]}
    legs = sorted({int(k[len(key) - 1:]) for r in rows for k in r if k.startswith(key[:-1])})
    return {f" leg {leg}": [r.get(f"{key[:-1]}{leg}", float("nan")) for r in rows] for leg in legs}


def plot_runs(run_dirs: list[Path], out: Path, title: str = "") -> Path:
    """Write a PNG of each run's panels (`panels_for` the first run), two rows."""
    import math

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [(Path(d).name, read_metrics(d)) for d in run_dirs]
    panels = panels_for(runs[0][1])
    cols = math.ceil(len(panels) / 2)
    fig, axes = plt.subplots(2, cols, figsize=(5.5 * cols, 7), constrained_layout=True)
    for name, rows in runs:
        steps = [r["step"] for r in rows]
        for ax, (key, label) in zip(axes.flat, panels):
            for suffix, values in series(rows, key).items():
                ax.plot(steps, values, marker="o", ms=3, label=name + suffix)
            if key.endswith("*"):
                ax.legend(fontsize=7)
            ax.set_xlabel("environment steps")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.remove()
    if panels[0][0] == "final_distance":
        axes.flat[0].axhline(0.5, color="grey", ls="--", lw=1)  # success radius
    axes.flat[0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return save_figure(fig, out)


def save_figure(fig, out: Path) -> Path:
    """Write `fig` to the PNG `out` atomically (creating its folder) and free it."""
    import matplotlib.pyplot as plt

    try:
        with atomic.replacing(out) as tmp:  # a full disk leaves no half-written PNG
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return out


def plot_paths(tracks: list, out: Path, corners=None, goals: list | None = None, title: str = "") -> Path:
    """Torso tracks (each (T, 2), m) from above, with a path through `corners` and/or goal points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(6, 6), constrained_layout=True)
    for i, track in enumerate(tracks):
        track = np.asarray(track)
        ax.plot(track[:, 0], track[:, 1], lw=1, alpha=0.7, label="torso" if i == 0 else None)
    if corners is not None:
        corners = np.asarray(corners)
        ax.plot(corners[:, 0], corners[:, 1], "k--", lw=1.5, label="path")
        ax.plot(corners[1:, 0], corners[1:, 1], "ko", ms=5)
    for i, points in enumerate(goals or []):
        points = np.asarray(points)
        ax.plot(points[:, 0], points[:, 1], "x", color=f"C{i % 10}", ms=7, label="goals" if i == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    return save_figure(fig, out)


def plot_contact_diagram(stance, dt: float, out: Path, legs: list[str], title: str = "") -> Path:
    """Foot-contact diagram: one row per leg against time (s), a bar where the foot is down."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    stance = np.asarray(stance, bool)
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(legs) + 1.2), constrained_layout=True)
    for row in range(stance.shape[1]):
        s = np.concatenate([[False], stance[:, row], [False]])
        starts, ends = np.flatnonzero(~s[:-1] & s[1:]), np.flatnonzero(s[:-1] & ~s[1:])
        ax.broken_barh([(a * dt, (b - a) * dt) for a, b in zip(starts, ends)], (row - 0.4, 0.8), color="0.2")
    ax.set_yticks(range(len(legs)), legs)
    ax.invert_yaxis()
    ax.set_xlim(0, len(stance) * dt)
    ax.set_xlabel("time (s); bars: foot on the floor")
    if title:
        ax.set_title(title, fontsize=10)
    return save_figure(fig, out)


def contact_sheet(video: Path, out: Path, count: int = 6, every: int = 40) -> Path:
    """A row of `count` frames, `every` frames apart, from an MP4 (half size)."""
    import imageio.v2 as imageio
    import numpy as np

    wanted = set(range(0, count * every, every))
    frames = [f[::2, ::2] for i, f in enumerate(imageio.get_reader(video)) if i in wanted]
    if not frames:
        raise ValueError(f"{video} has no frames")
    out.parent.mkdir(parents=True, exist_ok=True)
    imageio.imwrite(out, np.concatenate(frames, axis=1))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.evaluation.plots", description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="*", type=Path, help="run directories")
    parser.add_argument("--frames", type=Path, help="instead: a row of frames from this MP4")
    parser.add_argument("--every", type=int, default=40, help="with --frames: frames apart (default: 40)")
    parser.add_argument("--count", type=int, default=6, help="with --frames: how many (default: 6)")
    parser.add_argument("-o", "--out", type=Path, default=Path("curves.png"), help="PNG to write")
    parser.add_argument("--title", default="", help="figure title")
    args = parser.parse_args(argv)
    if args.frames:
        print(f"wrote {contact_sheet(args.frames, args.out, args.count, args.every)}")
    elif args.runs:
        print(f"wrote {plot_runs(args.runs, args.out, args.title)}")
    else:
        parser.error("give run directories or --frames VIDEO")


def plot_tracks(env, start, traj, out: Path, count: int = 8) -> Path:
    """Top view of the first episodes' torso tracks with their goals (or the waypoint path)."""
    import numpy as np

    tracks, goals = [], []
    for i in range(min(count, start.shape[0])):
        n = int(traj["alive"][:, i].sum())
        tracks.append(np.concatenate([start[i:i + 1, :2], traj["qpos"][:n, i, :2]]))
        goals.append(np.unique(traj["goal"][:n, i], axis=0))
    if env.config.waypoints:
        corners = np.vstack([start[0, :2], np.asarray(env.config.waypoints) + env.qpos0[:2]])
        return plot_paths(tracks, out, corners=corners, title="torso tracks along the waypoint path")
    return plot_paths(tracks, out, goals=goals, title=f"torso tracks and goals, {len(tracks)} episodes")


if __name__ == "__main__":
    main()

