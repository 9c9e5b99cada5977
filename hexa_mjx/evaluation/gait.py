"""How the robot walks, from a recorded episode: duty factor, stride frequency, phase offsets,
gait class, Froude number and cost of transport (NumPy only).

Inputs are per control step: which feet touch the floor (`stance`, steps x legs), the mechanical
power of the actuators (sum over joints of |torque x joint velocity|, W) and the torso's planar
position. Only the steps of the analysis window count (eval.py: the walk to the first goal in the
report's task, the whole episode in navigation, where goals keep coming).

Contact flicker is filtered first: a swing or stance shorter than MIN_PHASE_STEPS control steps
(33 ms at 60 Hz) is merged into its neighbours, so a foot grazing the floor for one step is not a step.

Gait classes (phases are each leg's touchdown time within leg 1's stride, 0 to 1):
- irregular: a leg makes fewer than 2 steps in the window, or the legs' stride frequencies differ
  by more than 25% (coefficient of variation), or no rule below fits;
- tripod: the six phases form two groups of three half a stride apart (each within 0.15 of its
  group's nominal phase);
- tetrapod: three groups of two a third of a stride apart (within 0.1);
- wave: a mean duty factor of 0.7 or more with the six phases spread out (no two within 0.08).
"""

from __future__ import annotations

import numpy as np

G = 9.81  # m/s^2
CLASSES = ("tripod", "tetrapod", "wave", "irregular")
MIN_PHASE_STEPS = 2  # control steps; shorter swings and stances are contact flicker


def debounce(stance: np.ndarray, min_steps: int = MIN_PHASE_STEPS) -> np.ndarray:
    """One leg's stance sequence with swings, then stances, shorter than `min_steps` removed."""
    s = np.asarray(stance, bool).copy()
    for value in (False, True):  # fill short swings first, then drop short stances
        edges = np.flatnonzero(np.diff(np.concatenate([[False], s == value, [False]]).astype(int)))
        for start, end in zip(edges[::2], edges[1::2]):
            if end - start < min_steps and start > 0 and end < len(s):  # interior runs only
                s[start:end] = not value
    return s


def touchdowns(stance: np.ndarray) -> np.ndarray:
    """Step indices where a foot lands (swing -> stance) in one leg's stance sequence."""
    s = np.asarray(stance, bool)
    return np.flatnonzero(~s[:-1] & s[1:]) + 1


def phase_offsets(stance: np.ndarray) -> np.ndarray:
    """Each leg's mean touchdown phase within leg 1's stride cycle, in [0, 1) (NaN if unknown)."""
    ref = touchdowns(stance[:, 0])
    out = np.full(stance.shape[1], np.nan)
    if len(ref) < 2:
        return out
    for leg in range(stance.shape[1]):
        phases = []
        for t in touchdowns(stance[:, leg]):
            k = np.searchsorted(ref, t, side="right") - 1
            if 0 <= k < len(ref) - 1:
                phases.append((t - ref[k]) / (ref[k + 1] - ref[k]))
        if phases:  # circular mean
            angle = np.angle(np.mean(np.exp(2j * np.pi * np.asarray(phases))))
            out[leg] = (angle / (2 * np.pi)) % 1.0
    return out


def _grouped(phase: np.ndarray, groups: int, tol: float) -> bool:
    """Whether the phases sit near `groups` evenly spaced values, with equally many legs at each."""
    scaled = phase * groups
    nearest = np.round(scaled)
    if np.any(np.abs(scaled - nearest) / groups > tol):
        return False
    counts = np.bincount(nearest.astype(int) % groups, minlength=groups)
    return bool(np.all(counts == len(phase) // groups))


def classify(duty: np.ndarray, stride_hz: np.ndarray, steps: np.ndarray, phase: np.ndarray) -> str:
    """The gait class of the rule in the module docstring."""
    if np.any(steps < 2) or np.any(np.isnan(phase)) or np.std(stride_hz) > 0.25 * np.mean(stride_hz):
        return "irregular"
    if len(phase) % 2 == 0 and _grouped(phase, 2, 0.15):
        return "tripod"
    if len(phase) % 3 == 0 and _grouped(phase, 3, 0.1):
        return "tetrapod"
    gaps = np.diff(np.sort(np.concatenate([phase, phase[:1] + 1.0])))
    if np.mean(duty) >= 0.7 and gaps.min() >= 0.08:
        return "wave"
    return "irregular"


def analyze(stance: np.ndarray, power: np.ndarray, xy: np.ndarray, dt: float, mass: float,
            leg_length: float) -> dict:
    """Gait figures of one window: stance (T, legs) bool, power (T,) W, xy (T, 2) m; dt s, mass kg,
    leg length m. Speed and cost of transport use the torso's path length over the window."""
    stance = np.stack([debounce(column) for column in np.asarray(stance, bool).T], axis=1)
    steps = len(stance)
    if steps < 2:
        return {"class": "irregular", "steps": steps}
    duration = steps * dt
    strides = np.array([len(touchdowns(stance[:, leg])) for leg in range(stance.shape[1])])
    duty = stance.mean(0)
    stride_hz = strides / duration
    phase = phase_offsets(stance)
    path = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
    speed = path / duration
    return {"class": classify(duty, stride_hz, strides, phase), "steps": steps, "duty_factor": duty,
            "stride_hz": stride_hz, "phase": phase, "speed": speed, "froude": speed ** 2 / (G * leg_length),
            "cost_of_transport": float(np.sum(power) * dt / (mass * G * path)) if path > 0.05 else float("nan")}


SETTLE_STEPS = 30  # control steps (0.5 s at 60 Hz) left out at a window's start: the first step off a standing pose


def of_episodes(stance, power, xy, window, dt: float, mass: float, leg_length: float) -> list[dict]:
    """`analyze` for every episode of a batch: stance (T, N, legs), power (T, N), xy (T, N, 2), and
    window (T, N) marking each episode's analysed steps, a prefix of the episode."""
    records = []
    for i in range(window.shape[1]):
        n = int(window[:, i].sum())
        sl = slice(min(SETTLE_STEPS, n), n)
        records.append(analyze(stance[sl, i], power[sl, i], xy[sl, i], dt, mass, leg_length))
    return records


def summarize(records: list[dict]) -> dict:
    """Means over episodes (cost of transport: median too); the share of each gait class."""
    valid = [r for r in records if "duty_factor" in r]
    shares = {c: sum(r["class"] == c for r in records) / len(records) for c in CLASSES}
    if not valid:
        return {"class_shares": shares, "class": max(shares, key=shares.get)}
    cot = np.array([r["cost_of_transport"] for r in valid])
    phase = np.array([r["phase"] for r in valid])
    mean_phase = (np.angle(np.nanmean(np.exp(2j * np.pi * phase), axis=0)) / (2 * np.pi)) % 1.0
    return {
        "class": max(shares, key=shares.get), "class_shares": shares,
        "duty_factor": np.mean([r["duty_factor"] for r in valid], axis=0).round(3).tolist(),
        "stride_hz": np.mean([r["stride_hz"] for r in valid], axis=0).round(3).tolist(),
        "phase": mean_phase.round(3).tolist(),
        "speed": float(np.mean([r["speed"] for r in valid])),
        "froude": float(np.mean([r["froude"] for r in valid])),
        "cost_of_transport_mean": float(np.nanmean(cot)) if np.isfinite(cot).any() else None,
        "cost_of_transport_median": float(np.nanmedian(cot)) if np.isfinite(cot).any() else None,
    }


def table_rows(summary: dict) -> list[tuple[str, str]]:
    """eval.py's table rows for a gait summary."""
    shares = ", ".join(f"{c} {v:.0%}" for c, v in summary["class_shares"].items() if v)
    rows = [("gait class (share of episodes)", f"{summary['class']} ({shares})")]
    if "duty_factor" in summary:
        fmt = lambda xs, f: " ".join(format(x, f) for x in xs)  # noqa: E731
        cot = summary["cost_of_transport_mean"]
        rows += [("  duty factor per leg", fmt(summary["duty_factor"], ".2f")),
                 ("  stride frequency per leg", fmt(summary["stride_hz"], ".2f") + " Hz"),
                 ("  touchdown phase per leg (leg 1 = 0)", fmt(summary["phase"], ".2f")),
                 ("  speed along the path, Froude number", f"{summary['speed']:.3f} m/s, {summary['froude']:.3f}"),
                 ("  cost of transport, mean (median)", "-" if cot is None else
                  f"{cot:.2f} ({summary['cost_of_transport_median']:.2f})")]
    return rows
