"""Every target of one policy for all of it, on native MuJoCo: a velocity policy walks the 2 m
square through the path follower (a navigation policy, given its corners as waypoints; a drive
policy either way, `--goal_mode`) on flat ground, on rough ground, under pushes, at the corners of
the physics grid and with failed legs.

    python -m hexa_mjx.studies.generalist POLICY.onnx --episodes 32 --workers 2 --json out.json

Each condition runs the same seeded starts (random heading, the policy's joint noise) with
everything else nominal (no pushes, latency, noise or failures but the condition's own). An
episode succeeds when the path's last waypoint counts (within the success radius, in order)
before the episode's time runs out (`--episode_length`, control steps); it ends there. Speed is
the path's length over the median time of the completed episodes, and its share of the flat,
intact robot's. Terrains are drawn at `--terrain_seed`, by default one the training never saw.
Each group has its target (TARGETS); the table marks the conditions that miss it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from hexa_mjx.deploy import player
from hexa_mjx.engines.terrain_contacts import MODES as CONTACT_MODES
from hexa_mjx.studies.path_following import PATHS
from hexa_mjx.studies.robustness import CLEAN, run_conditions, settings
from hexa_mjx.tasks import TASKS

SQUARE = PATHS["square"]  # m from the start, world frame
PATH_LENGTH = float(np.linalg.norm(np.diff([(0.0, 0.0), *SQUARE], axis=0), axis=1).sum())  # m: 8
FLAT = {**CLEAN, "terrain": "flat"}  # every condition's base: the policy may have trained on a terrain
EPISODE_LENGTH = 1800  # control steps to finish the path in: 30 s at 60 Hz
# Group -> (least success, least speed share of intact, most falls); None: no such target.
TARGETS = {"flat": (0.95, None, 0.02), "rough": (0.90, None, None), "push": (None, None, 0.05),
           "physics": (0.90, None, None), "one leg": (0.90, 0.70, None), "two legs": (0.75, None, None)}


def conditions(policy: player.OnnxPolicy, terrain_seed: int) -> list[tuple[str, str, dict, object]]:
    """(group, name, EnvConfig overrides, fixed physics ranges or None) of every condition."""
    env = player.env_for(policy, **FLAT)
    rows = [("flat", "flat, intact", {}, None)]
    for name, kind in (("bumps 4 cm", "bumps"), ("slopes 15 deg", "steep"), ("stairs 5 cm", "stairs")):
        rows.append(("rough", name, {"terrain": kind, "terrain_seed": terrain_seed, "terrain_difficulty": 1.0}, None))
    rows.append(("push", "pushes up to 0.5 m/s", {"push_speed": 0.5}, None))
    for friction in (0.4, 1.25):
        for mass in (0.8, 1.2):
            for payload in (0.0, 1.5):
                _, ranges = settings({"friction": friction, "mass": mass, "payload": payload})
                rows.append(("physics", f"friction {friction}, mass x{mass}, payload {payload} kg", {}, ranges))
    for mode in ("limp", "locked"):
        for leg in range(1, len(env.robot.legs) + 1):
            rows.append(("one leg", f"leg {leg} {mode}", {"disabled_legs": (leg,), "failure_mode": mode}, None))
    for i, j in env.robot.non_adjacent_pairs + 1:
        rows.append(("two legs", f"legs {i} + {j} limp", {"disabled_legs": (int(i), int(j)), "failure_mode": "limp"},
                     None))
    return rows


def battery(policy_path: str, episodes: int, seed: int = 0, workers: int = 1, terrain_seed: int = 1,
            episode_length: int = EPISODE_LENGTH, terrain_contacts: str = "all", groups=None,
            goal_mode: bool = False) -> list[dict]:
    """One row per condition: its group, name, path figures (player.summarize) and speed share.
    `terrain_contacts`: the native engine's heightfield contacts (hexa_mjx.engines.terrain_contacts);
    `groups`: only these of TARGETS' groups (the flat row always runs: the speed shares need it);
    `goal_mode`: a drive policy walks the square in its goal mode, given the corners as waypoints."""
    policy = player.OnnxPolicy(policy_path)
    task = TASKS.get(policy.metadata["task"])
    if goal_mode and not (task is not None and task.uses_command and task.follows_waypoints):
        raise ValueError(f"goal mode is a drive policy's; {policy_path} is a {policy.metadata['task']} policy")
    rows = [r for r in conditions(policy, terrain_seed) if not groups or r[0] in groups or r[0] == "flat"]
    base = {**base_settings(episode_length, terrain_contacts), **({"goal_mode_share": 1.0} if goal_mode else {})}
    summaries = run_conditions(policy_path, [({**base, **o}, r)
                                             for _, _, o, r in rows], episodes, seed, workers, path=SQUARE)
    out = [{"group": group, "condition": name, **summary} for (group, name, _, _), summary in zip(rows, summaries)]
    intact = out[0]["path_time_s_median"]
    for row in out:
        time = row["path_time_s_median"]
        row["speed"] = PATH_LENGTH / time if time else None
        row["speed_share_of_intact"] = intact / time if time and intact else None
        row["meets_target"] = meets(row)
    return out


def base_settings(episode_length: int = EPISODE_LENGTH, terrain_contacts: str = "all") -> dict:
    """Every condition's settings before its own overrides: FLAT, the time to finish the path and
    the native engine's heightfield contacts."""
    return {**FLAT, "episode_length": episode_length, "terrain_contacts": terrain_contacts}


def meets(row: dict) -> bool:
    """Whether a row meets its group's target (TARGETS)."""
    success, share, falls = TARGETS[row["group"]]
    return ((success is None or row["path_completed_rate"] >= success)
            and (share is None or (row["speed_share_of_intact"] or 0.0) >= share)
            and (falls is None or row["fall_rate"] <= falls))


def table(rows: list[dict]) -> str:
    """Markdown: one row per condition, a mark where it misses its group's target."""
    lines = ["| group | condition | path completed | falls | speed | share of intact | target |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        speed = "-" if r["speed"] is None else f"{r['speed']:.2f} m/s"
        share = "-" if r["speed_share_of_intact"] is None else f"{r['speed_share_of_intact']:.0%}"
        lines.append(f"| {r['group']} | {r['condition']} | {r['path_completed_rate']:.0%} | {r['fall_rate']:.0%} | "
                     f"{speed} | {share} | {'met' if r['meets_target'] else 'MISSED'} |")
    met = sum(r["meets_target"] for r in rows)
    lines.append(f"\n{met} of {len(rows)} conditions meet their targets")
    return "\n".join(lines)


def gait_table(rows: list[dict]) -> str:
    """Markdown: each condition's gait over its episodes (player.summarize's, the whole episode
    less its first half second): the commonest class, each leg's duty factor, cost of transport."""
    lines = ["| condition | gait (share of episodes) | duty factor, legs 1-6 | cost of transport (median) |",
             "|---|---|---|---|"]
    for r in rows:
        g = r.get("gait") or {}
        shares = ", ".join(f"{c} {v:.0%}" for c, v in g.get("class_shares", {}).items() if v)
        duty = " ".join(f"{d:.2f}" for d in g.get("duty_factor", [])) or "-"
        cot = g.get("cost_of_transport_median")
        lines.append(f"| {r['condition']} | {shares or '-'} | {duty} | {'-' if cot is None else f'{cot:.2f}'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.generalist", description=__doc__.split("\n\n")[0])
    p.add_argument("policy", help="exported velocity-, drive- or navigate-task policy (.onnx)")
    p.add_argument("--episodes", type=int, default=32, help="per condition")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--terrain_seed", type=int, default=1, help="the rough conditions' terrain")
    p.add_argument("--episode_length", type=int, default=EPISODE_LENGTH, help="control steps to finish the path in (30 s)")
    p.add_argument("--workers", type=int, default=1, help="processes that share the episodes")
    p.add_argument("--terrain_contacts", default="all", choices=CONTACT_MODES,
                   help="the rough conditions' heightfield contacts: MuJoCo C's own, or made as MJX makes them "
                        "(hexa_mjx.engines.terrain_contacts)")
    p.add_argument("--groups", nargs="+", default=None, choices=list(TARGETS), help="only these groups (and flat)")
    p.add_argument("--goal_mode", action="store_true",
                   help="a drive policy walks the square in its goal mode, given the corners as waypoints "
                        "(default: its command mode, through the path follower)")
    p.add_argument("--json", default="", help="write the rows here")
    args = p.parse_args(argv)
    if args.episodes < 1 or args.workers < 1 or args.episode_length < 1:
        p.error("--episodes, --workers and --episode_length must be at least 1")
    try:
        rows = battery(args.policy, args.episodes, args.seed, args.workers, args.terrain_seed, args.episode_length,
                       args.terrain_contacts, args.groups, args.goal_mode)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(table(rows))
    print()
    print(gait_table(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
