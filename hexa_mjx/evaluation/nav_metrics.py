"""Navigation figures from recorded episodes: per-goal outcomes, sector and distance tables, paths.

Pure NumPy over eval's time-major arrays (T steps x N episodes), so every figure can be checked
on hand-made trajectories. Bearings are measured from the torso's heading when the goal is drawn
(0 = straight ahead, positive = to the left), in degrees.
"""

from __future__ import annotations

import numpy as np

from hexa_mjx.robot import constants as robot

SECTOR_DEG = 45.0
BAND_M = 0.5


def heading(qpos: np.ndarray) -> np.ndarray:
    """Torso yaw, rad, of qpos rows (..., nq) with the free joint's (w, x, y, z) quaternion at 3:7."""
    w, x, y, z = (qpos[..., i] for i in range(3, 7))
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def wrap_deg(angle: np.ndarray) -> np.ndarray:
    """Angles in degrees wrapped to [-180, 180)."""
    return (np.asarray(angle) + 180.0) % 360.0 - 180.0


def goals_of_episodes(start_qpos, qpos, goal, completed, alive, fell, dt: float) -> list[dict]:
    """One record per goal an episode was given.

    qpos (T, N, nq): state after each step; goal (T, N, 2): the goal each step was scored against;
    completed (T, N): 1 on the step a goal was completed; alive (T, N): 1 inside the episode.
    A goal is drawn at the start or on the step its predecessor is completed; it counts as given
    if the episode has at least one step left for it. `closest`: the torso's least distance to it
    (m), which tells a goal that stays, never completed, from one never reached; `fell_after_s`,
    on the goal an episode fell walking to or standing on: the time from its draw to the fall.
    """
    steps, episodes = alive.shape
    records = []
    for i in range(episodes):
        length = int(alive[:, i].sum())
        events = [int(t) for t in np.nonzero(completed[:length, i] > 0)[0]]
        draws = [-1] + events  # step after which each goal is the one to walk to (-1: the start)
        for k, drawn in enumerate(draws):
            first = drawn + 1
            if first >= length:
                break
            where = start_qpos[i] if drawn < 0 else qpos[drawn, i]
            target = goal[first, i]
            offset = target - where[:2]
            bearing = wrap_deg(np.degrees(np.arctan2(offset[1], offset[0]) - heading(where)))
            reached = k < len(events)
            last = events[k] if reached else length - 1
            closest = np.linalg.norm(qpos[first:last + 1, i, :2] - target, axis=-1).min()
            record = {"episode": i, "index": k, "bearing_deg": float(bearing),
                      "distance": float(np.linalg.norm(offset)), "closest": float(closest), "reached": reached,
                      "fell": bool(fell[i]) and not reached}
            if record["fell"]:
                record["fell_after_s"] = (length - 1 - drawn) * dt
            if reached:
                arrive = events[k]
                pos = qpos[arrive, i]
                to_goal = np.degrees(np.arctan2(*(target - pos[:2])[::-1]))
                record.update(seconds=(arrive - drawn) * dt,
                              heading_error_deg=float(abs(wrap_deg(np.degrees(heading(pos)) - to_goal))))
            records.append(record)
    return records


def fall_phases(records: list[dict], fell, alive, success_radius: float, dt: float) -> dict:
    """Where the episodes that fell did so: walking to a goal (the goal in force never within
    `success_radius`, m) or on a goal (standing on one that stays, or on an arrival's last step);
    the median time of a fall, s into the episode; and, over the falls walking to a goal, the
    medians of that goal's distance when it was drawn (m), of the share of it closed before the fall
    and of the time from its draw to the fall, s (None where there are no such falls)."""
    fell = np.asarray(fell, bool)
    walks = [r for r in records if r["fell"] and r["closest"] >= success_radius]
    seconds = np.asarray(alive)[:, fell].sum(0) * dt
    distance = np.array([r["distance"] for r in walks])
    closed = (distance - np.array([r["closest"] for r in walks])) / np.maximum(distance, 1e-9)
    median = lambda x: float(np.median(x)) if len(x) else None  # noqa: E731
    return {"walking_to_a_goal": len(walks), "on_a_goal": int(fell.sum()) - len(walks),
            "seconds_median": median(seconds), "goal_distance_median": median(distance),
            "share_closed_median": median(closed),
            "seconds_after_draw_median": median([r["fell_after_s"] for r in walks])}


def sector_of(bearing_deg) -> np.ndarray:
    """Index of the 45-degree sector centred on 0, 45, ..., 315 degrees (0 = ahead, 90 = left)."""
    return np.round(np.asarray(bearing_deg) / SECTOR_DEG).astype(int) % int(360 / SECTOR_DEG)


def band_of(distance, low: float) -> np.ndarray:
    """Index of the 0.5 m distance band starting at `low` (a goal drawn at `low` that float32
    rounding puts a hair below it counts in the first band)."""
    return np.maximum(np.floor((np.asarray(distance) - low) / BAND_M + 1e-9).astype(int), 0)


def navigation_summary(records: list[dict], episodes: int, success_radius: float, body_length: float,
                       low: float, high: float) -> dict:
    """Success per sector and band (each episode's first goal), goals per episode, time per metre,
    speed toward the goal, heading error on arrival."""
    first = [r for r in records if r["index"] == 0]
    reached = [r for r in records if r["reached"]]
    success = np.array([r["reached"] for r in first], float)
    sectors, bands = sector_of([r["bearing_deg"] for r in first]), band_of([r["distance"] for r in first], low)

    def table(index, labels):
        return {label: {"goals": int((index == j).sum()),
                        "success": float(success[index == j].mean()) if (index == j).any() else None}
                for j, label in enumerate(labels)}

    n_bands = max(int(np.ceil((high - low) / BAND_M - 1e-9)), 1)
    band_labels = [f"{low + j * BAND_M:.1f}-{min(low + (j + 1) * BAND_M, high):.1f} m" for j in range(n_bands)]
    over = bands >= n_bands  # goals beyond the range (a longer eval range): their own band
    if over.any():
        band_labels.append(f">{high:.1f} m")
        bands = np.where(over, n_bands, bands)
    seconds = np.array([r["seconds"] for r in reached])
    dist = np.array([r["distance"] for r in reached])
    speed = np.maximum(dist - success_radius, 0.0) / np.maximum(seconds, 1e-9)
    per_episode = np.bincount([r["episode"] for r in reached], minlength=episodes)
    return {
        "first_goal_success": float(success.mean()) if len(success) else None,
        "sectors": table(sectors, [f"{wrap_deg(j * SECTOR_DEG) if j * SECTOR_DEG != 180 else 180:+.0f} deg"
                                  for j in range(int(360 / SECTOR_DEG))]),
        "bands": table(bands, band_labels),
        "goals_per_episode_mean": float(per_episode.mean()),
        "goals_per_episode_min": int(per_episode.min()),
        "seconds_per_metre": float((seconds / dist).mean()) if len(reached) else None,
        "speed_to_goal": float(speed.mean()) if len(reached) else None,
        "speed_to_goal_body_lengths": float(speed.mean() / body_length) if len(reached) else None,
        "heading_error_deg_mean": float(np.mean([r["heading_error_deg"] for r in reached])) if reached else None,
    }


def waypoint_summary(start_qpos, qpos, completed, alive, fell, waypoints, dt: float) -> dict:
    """Arrival times at each waypoint (mean over episodes that arrive), paths completed, and the
    largest distance of the torso from the straight segments start -> w1 -> w2 -> ...."""
    points = np.asarray(waypoints, float)
    n = len(points)
    arrivals, deviation, done = [], [], []
    for i in range(alive.shape[1]):
        length = int(alive[:, i].sum())
        events = np.nonzero(completed[:length, i] > 0)[0][:n]
        arrivals.append(list((events + 1) * dt) + [None] * (n - len(events)))
        done.append(len(events) == n)
        # Segment k runs from waypoint k-1 (the start position for k = 0) to waypoint k.
        corners = np.vstack([start_qpos[i, :2], points])
        target = np.searchsorted(events, np.arange(length), side="left")  # waypoints completed before step t
        walking = target < n
        xy, k = qpos[:length, i, :2][walking], target[walking]
        deviation.append(float(segment_distance(xy, corners[k], corners[k + 1]).max()) if walking.any() else 0.0)
    arrivals_arr = np.array(arrivals, dtype=object)
    mean_arrival = [float(np.mean([a for a in arrivals_arr[:, j] if a is not None]))
                    if any(a is not None for a in arrivals_arr[:, j]) else None for j in range(n)]
    return {
        "waypoints": points.tolist(),
        "completed_rate": float(np.mean(done)),
        "arrival_s_mean": mean_arrival,
        "max_deviation_mean": float(np.mean(deviation)),
        "max_deviation_median": float(np.median(deviation)),
        "fall_rate": float(np.mean(fell)),
        "per_episode": {"completed": done, "arrival_s": arrivals, "max_deviation": deviation},
    }


def segment_distance(p, a, b) -> np.ndarray:
    """Distance from each point p to the segment a-b (rows), m."""
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def body_length(env) -> float:
    """Length of the torso box along its forward axis, m."""
    return 2.0 * float(env.mj_model.geom(robot.TORSO_GEOM).size[0])


def table_rows(summary: dict) -> list[tuple[str, str]]:
    """eval.py's rows of the navigation figures: per-sector and per-band success, goals, speed; or a path."""
    pct = lambda x: "-" if x is None else f"{x:.1%}"  # noqa: E731
    num = lambda x, fmt: "-" if x is None else format(x, fmt)  # noqa: E731
    rows = []
    if "navigation" in summary:
        nav = summary["navigation"]
        rows.append(("first goal reached", pct(nav["first_goal_success"])))
        for key, title in (("sectors", "  bearing"), ("bands", "  distance")):
            rows += [(f"{title} {label}", f"{pct(v['success'])} of {v['goals']}") for label, v in nav[key].items()]
        rows += [("goals reached per episode, mean (min)",
                  f"{nav['goals_per_episode_mean']:.2f} ({nav['goals_per_episode_min']})"),
                 ("seconds per metre of goal distance", num(nav["seconds_per_metre"], ".2f")),
                 ("speed toward the goal", f"{num(nav['speed_to_goal'], '.3f')} m/s = "
                                           f"{num(nav['speed_to_goal_body_lengths'], '.2f')} torso lengths/s"),
                 ("heading error on arrival, mean", f"{num(nav['heading_error_deg_mean'], '.0f')} deg")]
        if "falls" in nav:  # evaluations written before the breakdown lack it
            falls = nav["falls"]
            rows.append(("falls: walking to a goal, on a goal (median time)",
                         f"{falls['walking_to_a_goal']}, {falls['on_a_goal']} "
                         f"({num(falls['seconds_median'], '.1f')} s)"))
            if "goal_distance_median" in falls:
                rows.append(("  walking: their goal's distance, share of it walked, time since it was drawn "
                             "(medians)", f"{num(falls['goal_distance_median'], '.2f')} m, "
                             f"{pct(falls['share_closed_median'])}, {num(falls['seconds_after_draw_median'], '.1f')} s"))
    if "waypoints" in summary:
        path = summary["waypoints"]
        rows += [("waypoints", " ".join(f"{x:g},{y:g}" for x, y in path["waypoints"])),
                 ("path completed", pct(path["completed_rate"])),
                 ("arrival at each waypoint, mean", ", ".join(num(t, ".1f") + " s" for t in path["arrival_s_mean"])),
                 ("largest deviation from the path, mean (median)",
                  f"{path['max_deviation_mean']:.3f} m ({path['max_deviation_median']:.3f} m)")]
    return rows
