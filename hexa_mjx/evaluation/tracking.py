"""How well a policy follows velocity commands, from a batch of recorded episodes (NumPy only).

Inputs per control step (time first, then episodes): the command in force (`command`, the model's
userdata), the (vx, vy, yaw rate) it asks for (`commanded`), the torso's measured (vx, vy, yaw
rate) after the step (`velocity`), `alive`, foot stance, servo power and qpos.

Definitions (docs/EVALUATION.md):
- Steps within SETTLE_S of a command change (or of the episode's start) are left out: the robot
  is still changing speed.
- The measured velocity is averaged over the last AVERAGE_S (about one stride), since a walking
  torso sways within every stride; the instantaneous error is reported beside it.
- Each command's class is exact (hexa_mjx.tasks.velocity.CLASSES): the draw sets the other
  components to zero. Commands in heading mode are their own class, "heading".
- Tracking share: the measured velocity projected on the command, over the command's size (sums
  over the class's steps); 1 is perfect, below 1 too slow.
- Drift while commanded to stand: each zero command's net displacement (and turn) after settling,
  over its time.
- Speed bands: every settled command whose yaw rate is zero, analysed as one gait window
  (hexa_mjx.evaluation.gait), grouped by its commanded planar speed.
- Falls by command: each fallen episode's command at its last step, its class, and how long that
  command had been in force (a fall within SETTLE_S of a change is a fall in the change).
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.robot.kinematics import yaw

SETTLE_S = 1.0  # s left out after each command change
AVERAGE_S = 0.25  # s, the measured velocity's averaging window (a stride at about 4 Hz)
SPEED_BANDS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5)  # m/s, commanded planar speed


def command_class(command: np.ndarray, classes) -> np.ndarray:
    """The class index of each command (..., 4) in `classes` (+ "heading" last), by which of its
    components are nonzero."""
    vx, vy, wz, mode = (command[..., i] for i in range(4))
    nx, ny, nw = vx != 0, vy != 0, wz != 0
    name = np.select([mode > 0.5, ~nx & ~ny & ~nw, nx & ~ny & ~nw & (vx > 0), nx & ~ny & ~nw & (vx < 0),
                      ~nx & ny & ~nw, ~nx & ~ny & nw, nx & ny & ~nw],
                     ["heading", "zero", "forward", "backward", "sideways", "turn", "diagonal"], "walk and turn")
    order = {c: i for i, c in enumerate([*classes, "heading"])}
    return np.vectorize(order.get)(name)


def command_age(command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(control steps since each step's command came into force, segment id of each step within
    its episode), both (time, episodes)."""
    changed = np.concatenate([np.ones((1, command.shape[1]), bool),
                              np.any(command[1:] != command[:-1], axis=-1)], axis=0)
    t = np.arange(len(command))[:, None]
    return t - np.maximum.accumulate(np.where(changed, t, 0), axis=0), np.cumsum(changed, axis=0) - 1


def settled_steps(command: np.ndarray, alive: np.ndarray, dt: float):
    """(whether each step is at least SETTLE_S past its command's start and alive, segment id of
    each step within its episode)."""
    age, segment = command_age(command)
    return (age >= round(SETTLE_S / dt)) & (alive > 0), segment


def falls_by_command(command, classes, commanded, alive, fell, dt: float, names) -> dict:
    """Each fallen episode's command at its last step: counts by class, and per fall its class
    (`classes`: each step's index in `names`), the seconds that command had been in force and the
    (vx, vy, yaw rate) it asked for."""
    fell = np.asarray(fell, bool)
    last = np.maximum(alive.sum(0).astype(int) - 1, 0)
    age, _ = command_age(command)
    falls = []
    for i in np.flatnonzero(fell):
        t = last[i]
        falls.append({"class": names[classes[t, i]], "seconds_into_command": round(float(age[t, i] * dt), 3),
                      "commanded": [round(float(v), 3) for v in commanded[t, i]]})
    by_class = {name: sum(f["class"] == name for f in falls) for name in names}
    return {"episodes": int(fell.size), "falls": len(falls), "by_class": {k: v for k, v in by_class.items() if v},
            "within_settle": sum(f["seconds_into_command"] < SETTLE_S for f in falls), "each": falls}


def averaged(values: np.ndarray, steps: int) -> np.ndarray:
    """Each step's mean over the last `steps` steps (fewer at the start), along time."""
    total = np.cumsum(values, axis=0)
    out = total.copy()
    out[steps:] = total[steps:] - total[:-steps]
    count = np.minimum(np.arange(1, len(values) + 1), steps).reshape(-1, *([1] * (values.ndim - 1)))
    return out / count


def _errors(commanded, velocity, mask) -> dict:
    """RMS planar-velocity and yaw-rate errors and tracking shares over the `mask`ed steps."""
    n = int(mask.sum())
    if n == 0:
        return {"steps": 0}
    c, v = commanded[mask], velocity[mask]
    planar = np.sum((c[:, :2] - v[:, :2]) ** 2, axis=1)
    cc, cw = np.sum(c[:, :2] ** 2), np.sum(c[:, 2] ** 2)
    return {"steps": n, "velocity_rms": float(np.sqrt(planar.mean())),
            "yaw_rate_rms": float(np.sqrt(np.mean((c[:, 2] - v[:, 2]) ** 2))),
            "velocity_share": float(np.sum(c[:, :2] * v[:, :2]) / cc) if cc > 0 else None,
            "yaw_rate_share": float(np.sum(c[:, 2] * v[:, 2]) / cw) if cw > 0 else None}


def episode_errors(commanded, velocity, command, dt: float) -> dict:
    """One episode's RMS errors and tracking shares (arrays with time first, no episode axis)."""
    settled, _ = settled_steps(command[:, None], np.ones((len(command), 1)), dt)
    return _errors(commanded, averaged(velocity, max(1, round(AVERAGE_S / dt))), settled[:, 0])


def tracking_summary(task, dt: float, traj: dict, alive: np.ndarray, fell) -> tuple[dict, dict]:
    """eval.py's tracking figures (summary, per-episode) of a velocity task's rollout."""
    from hexa_mjx.evaluation import gait
    from hexa_mjx.tasks.velocity import CLASSES

    command, commanded, instant = traj["command"], traj["commanded"], traj["velocity"]
    settled, segment = settled_steps(command, alive, dt)
    velocity = averaged(instant, max(1, round(AVERAGE_S / dt)))
    classes = command_class(command, CLASSES)
    names = [*CLASSES, "heading"]
    per_class = {names[i]: _errors(commanded, velocity, settled & (classes == i)) for i in range(len(names))}
    overall = _errors(commanded, velocity, settled)
    instant_err = _errors(commanded, instant, settled)

    drift, bands = [], {band: [] for band in range(len(SPEED_BANDS) - 1)}
    qpos, robot = traj["qpos"], task.robot
    for i in range(command.shape[1]):
        for s in np.unique(segment[settled[:, i], i]):
            steps = np.flatnonzero(settled[:, i] & (segment[:, i] == s))
            if len(steps) < 2:
                continue
            kind, duration = names[classes[steps[0], i]], len(steps) * dt
            if kind == "zero":
                xy = qpos[steps, i, :2]
                turn = np.angle(np.exp(1j * np.diff(yaw(qpos[steps, i, 3:7].T))).prod())
                drift.append((np.linalg.norm(xy[-1] - xy[0]) / duration, abs(turn) / duration))
            elif "stance" in traj and commanded[steps[0], i, 2] == 0 and kind != "heading":
                speed = float(np.linalg.norm(commanded[steps[0], i, :2]))
                band = np.searchsorted(SPEED_BANDS, speed, side="right") - 1
                if 0 <= band < len(bands):
                    bands[band].append(gait.analyze(traj["stance"][steps, i], traj["power"][steps, i],
                                                    qpos[steps, i, :2], dt, robot.mass, robot.leg_length))
    drift = np.array(drift).reshape(-1, 2)
    summary = {
        "settle_s": SETTLE_S, "average_s": AVERAGE_S, **{k: v for k, v in overall.items()},
        "velocity_rms_instant": instant_err.get("velocity_rms"), "yaw_rate_rms_instant": instant_err.get("yaw_rate_rms"),
        "classes": {name: figures for name, figures in per_class.items() if figures["steps"]},
        "stand_drift": {"commands": len(drift), "speed_mean": float(drift[:, 0].mean()) if len(drift) else None,
                        "speed_p95": float(np.percentile(drift[:, 0], 95)) if len(drift) else None,
                        "yaw_rate_mean": float(drift[:, 1].mean()) if len(drift) else None},
        "falls": None if fell is None else falls_by_command(command, classes, commanded, alive, fell, dt, names),
        "speed_bands": [_band(SPEED_BANDS[b], SPEED_BANDS[b + 1], records) for b, records in bands.items() if records],
    }
    per_episode = {"velocity_rms": [_errors(commanded[:, i], velocity[:, i], settled[:, i]).get("velocity_rms")
                                    for i in range(command.shape[1])]}
    return summary, per_episode


def _band(lo: float, hi: float, records: list[dict]) -> dict:
    """One speed band's gait: class shares, mean duty factor, measured speed, cost of transport."""
    from hexa_mjx.evaluation import gait

    valid = [r for r in records if "duty_factor" in r]
    cot = np.array([r["cost_of_transport"] for r in valid], float)
    shares = {c: sum(r["class"] == c for r in records) / len(records) for c in gait.CLASSES}
    return {"band": [lo, hi], "commands": len(records), "class": max(shares, key=shares.get), "class_shares": shares,
            "duty_factor": float(np.mean([r["duty_factor"].mean() for r in valid])) if valid else None,
            "speed": float(np.mean([r["speed"] for r in valid])) if valid else None,
            "cost_of_transport_median": float(np.nanmedian(cot)) if np.isfinite(cot).any() else None,
            "points": [(float(r["speed"]), float(r["cost_of_transport"]), r["class"]) for r in valid
                       if np.isfinite(r["cost_of_transport"])]}


def table_rows(summary: dict) -> list[tuple[str, str]]:
    """eval.py's table rows of the tracking figures."""
    t = summary["tracking"]
    pct = lambda x: "-" if x is None else f"{x:.0%}"  # noqa: E731
    if not t["steps"]:  # every command changed (or the episode ended) within the settling window
        return [("velocity and yaw-rate RMS errors", f"none: no step came {t['settle_s']} s after a command "
                 "change; use longer episodes (--episode_length)")]
    rows = [(f"velocity RMS error ({t['average_s']} s average; instantaneous)",
             f"{t['velocity_rms']:.3f} m/s ({t['velocity_rms_instant']:.3f})"),
            ("yaw-rate RMS error (average; instantaneous)", f"{t['yaw_rate_rms']:.3f} rad/s ({t['yaw_rate_rms_instant']:.3f})"),
            ("  steps left out after each command change", f"{t['settle_s']} s")]
    for name, c in t["classes"].items():
        rows.append((f"  {name}: velocity, yaw rate RMS; tracking share",
                     f"{c['velocity_rms']:.3f} m/s, {c['yaw_rate_rms']:.3f} rad/s; "
                     f"{pct(c['velocity_share'])} v, {pct(c['yaw_rate_share'])} yaw"))
    d = summary["tracking"]["stand_drift"]
    if d["commands"]:
        rows.append(("drift commanded to stand: mean (95th pct), yaw",
                     f"{d['speed_mean']:.3f} ({d['speed_p95']:.3f}) m/s, {d['yaw_rate_mean']:.3f} rad/s"))
    f = t.get("falls")
    if f and f["falls"]:
        classes = ", ".join(f"{name} {n}" for name, n in f["by_class"].items())
        rows.append(("falls by the command in force", f"{classes}; {f['within_settle']} within {t['settle_s']} s "
                     "of a change"))
    for b in t["speed_bands"]:
        cot = "-" if b["cost_of_transport_median"] is None else f"{b['cost_of_transport_median']:.2f}"
        duty = "-" if b["duty_factor"] is None else f"{b['duty_factor']:.2f}"
        rows.append((f"  {b['band'][0]:.2f}-{b['band'][1]:.2f} m/s: gait, duty, cost of transport",
                     f"{b['class']} ({b['commands']} commands), {duty}, {cot}"))
    return rows


def plot_tracking(task, dt: float, traj: dict, out):
    """Episode 0's commands against the measured velocity, and cost of transport against speed by
    gait class (the speed bands' points)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    alive = traj["alive"][:, 0] > 0
    t = np.arange(alive.sum()) * dt
    velocity = averaged(traj["velocity"], max(1, round(AVERAGE_S / dt)))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for j, (label, color) in enumerate((("vx, m/s", "C0"), ("vy, m/s", "C1"), ("yaw rate, rad/s", "C2"))):
        axes[0].plot(t, traj["commanded"][alive, 0, j], color=color, ls="--", label=f"{label} commanded")
        axes[0].plot(t, velocity[alive, 0, j], color=color, label=f"{label} measured")
    axes[0].set_xlabel("time, s")
    axes[0].set_title("episode 0: command (dashed) and measured")
    axes[0].legend(fontsize=7, ncol=2)
    summary, _ = tracking_summary(task, dt, traj, traj["alive"], None)
    points = [p for band in summary["speed_bands"] for p in band["points"]]
    for k, cls in enumerate(sorted({p[2] for p in points})):
        xs = [p[0] for p in points if p[2] == cls]
        axes[1].scatter(xs, [p[1] for p in points if p[2] == cls], s=10, color=f"C{k}", label=cls)
    axes[1].set_xlabel("measured speed, m/s")
    axes[1].set_ylabel("cost of transport")
    axes[1].set_title("cost of transport against speed, by gait")
    if points:
        axes[1].legend()
    fig.tight_layout()
    from hexa_mjx.evaluation.plots import save_figure

    return save_figure(fig, out)


def standing_still(task, draws: int = 100_000, seed: int = 0) -> tuple[float, float]:
    """The tracking terms' mean per step for a robot that stands still, over `draws` commands of
    `task` (its ranges and class shares): what a policy that has learnt nothing scores."""
    from hexa_mjx.engines.native import NumpyDraws

    rng = NumpyDraws(np.random.default_rng(seed))
    c = np.array([task.draw_command(rng, None)[0] for _ in range(draws)])
    sigma = task.widths()
    return (float(np.exp(-(c[:, :2] ** 2).sum(1) / sigma["tracking_lin_vel"]).mean()),
            float(np.exp(-c[:, 2] ** 2 / sigma["tracking_ang_vel"]).mean()))


def learning_curves(run_dirs, out):
    """The tracking terms' mean per step (unscaled) at each training evaluation of velocity runs,
    beside what standing still scores on each run's commands (one line per distinct range)."""
    import json
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hexa_mjx.evaluation.plots import save_figure
    from hexa_mjx.training.checks import run_scales
    from hexa_mjx.training.config import load_config, make_env_for

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    baselines = {}
    for k, run in enumerate(map(Path, run_dirs)):
        cfg = load_config(run)
        scales = run_scales(cfg)
        ranges = (tuple(cfg.command_vx), tuple(cfg.command_vy), tuple(cfg.command_yaw_rate),
                  cfg.tracking_sigma, cfg.yaw_tracking_sigma)
        if ranges not in baselines:  # an environment is built only for commands not yet seen
            task = make_env_for(cfg).task
            baselines[ranges] = (standing_still(task, draws=20_000), task.widths())
        rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines() if line.strip()]
        for ax, term in zip(axes, ("tracking_lin_vel", "tracking_ang_vel")):
            ax.plot([r["step"] / 1e6 for r in rows],
                    [r[f"eval/episode_reward/{term}"] / r["episode_length"] / scales[term] for r in rows],
                    "o-", color=f"C{k}", label=run.name)
    for ax, title, i in zip(axes, ("planar velocity", "yaw rate"), (0, 1)):
        for n, (ranges, (still, widths)) in enumerate(baselines.items()):
            vx, _, wz = ranges[:3]
            sigma = widths[("tracking_lin_vel", "tracking_ang_vel")[i]]
            ax.axhline(still[i], color="gray", ls=("--", ":", "-.")[n % 3],
                       label=f"standing still, vx to {vx[1]:g} m/s, yaw to {wz[1]:g} rad/s, sigma {sigma:g}")
        ax.set_xlabel("env steps, millions")
        ax.set_title(f"{title} tracking per step, exp(-error^2 / sigma)", fontsize=9)
        ax.set_ylim(0, 1)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, Path(out))


def main(argv=None) -> None:
    """`python -m hexa_mjx.evaluation.tracking RUN [RUN ...] -o curves.png`: velocity runs' learning curves."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.evaluation.tracking", description=main.__doc__)
    parser.add_argument("runs", nargs="+", help="velocity-task run directories")
    parser.add_argument("-o", "--out", default="velocity_curves.png")
    args = parser.parse_args(argv)
    print(f"wrote {learning_curves(args.runs, args.out)}")


if __name__ == "__main__":
    main()
