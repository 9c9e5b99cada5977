"""Contact normals on a heightfield: native MuJoCo's collider against MJX's, on the same states.

    python -m hexa_mjx.evaluation.contact_check policies/navigate.onnx --terrain bumps --terrain_difficulty 0

A policy walks in native MuJoCo (`hexa_mjx.deploy.player`); every few control steps its state is kept, and
both engines' colliders run on the kept states: the share of tilted normals, which feet touch, how
many contacts each touching foot gets and how deep. On a zero-height heightfield the ground is flat,
so every contact normal should point straight up: the share of tilted normals is what each
collider adds. (docs/RESULTS.md, "Rough terrain": native MuJoCo's prisms give a foot sphere near a
cell's edge a contact through the neighbouring prism's side wall.)
"""

from __future__ import annotations

import argparse
import sys

import mujoco
import numpy as np

from hexa_mjx.deploy import player
from hexa_mjx.studies.robustness import CLEAN


def tilt_degrees(normal_z) -> np.ndarray:
    """Angle between each contact normal and the vertical, degrees (either sign of the normal)."""
    return np.degrees(np.arccos(np.minimum(1.0, np.abs(np.asarray(normal_z, np.float64)))))


def walk_states(policy, env, episodes: int, every: int) -> np.ndarray:
    """qpos after every `every`-th control step (the first included) of `episodes` seeded episodes."""
    return np.concatenate([player.run_episode(policy, env, seed, record=True)["trajectory"]["qpos"][1::every]
                           for seed in range(episodes)])


def native_contacts(model: mujoco.MjModel, states: np.ndarray) -> list[np.ndarray]:
    """Per state, the penetrating contacts MuJoCo C finds: rows of (geom1, geom2, dist m, normal z)."""
    data, out = mujoco.MjData(model), []
    for qpos in states:
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        c, n = data.contact, data.ncon
        rows = np.stack([c.geom1[:n], c.geom2[:n], c.dist[:n], c.frame[:n, 2]], axis=1)
        out.append(rows[rows[:, 2] < 0])
    return out


def mjx_contacts(model: mujoco.MjModel, states: np.ndarray) -> list[np.ndarray]:
    """Per state, the penetrating contacts MJX (JAX implementation) finds, as `native_contacts`."""
    import jax
    import jax.numpy as jp
    from mujoco import mjx

    from hexa_mjx.engines import contacts

    mx = mjx.put_model(model)

    def penetrations(qpos):
        data = mjx.forward(mx, mjx.make_data(mx).replace(qpos=qpos))
        geom1, geom2, dist = contacts.of(data)
        return geom1, geom2, dist, contacts.normals(data)[:, 2]

    g1, g2, dist, z = (np.asarray(x, np.float64) for x in
                       jax.jit(jax.vmap(penetrations))(jp.asarray(states, jp.float32)))
    rows = np.stack([g1, g2, dist, z], axis=-1)
    return [r[r[:, 2] < 0] for r in rows]


def native_tilts(model: mujoco.MjModel, states: np.ndarray) -> np.ndarray:
    """Normal tilts of the penetrating contacts MuJoCo C finds at each state."""
    return tilt_degrees(np.concatenate([r[:, 3] for r in native_contacts(model, states)]))


def foot_contacts(per_state: list[np.ndarray], feet: np.ndarray, floor: int) -> tuple[np.ndarray, np.ndarray]:
    """(contacts per foot with the floor, deepest dist per foot, m; 0 where none), each (states, feet)."""
    count, depth = np.zeros((len(per_state), len(feet))), np.zeros((len(per_state), len(feet)))
    for i, rows in enumerate(per_state):
        other = np.where(rows[:, 0] == floor, rows[:, 1], rows[:, 0])
        for k, foot in enumerate(feet):
            mine = rows[other == foot, 2]
            count[i, k], depth[i, k] = len(mine), mine.min() if len(mine) else 0.0
    return count, depth


def summary(per_state: list[np.ndarray], count: np.ndarray, depth: np.ndarray) -> str:
    """One line of an engine's contacts over the states, with their `foot_contacts`."""
    tilts = tilt_degrees(np.concatenate([r[:, 3] for r in per_state]))
    touching = count > 0
    return (f"{len(tilts)} penetrating contacts ({len(tilts) / len(per_state):.1f} per state); normals tilted over "
            f"10 deg {np.mean(tilts > 10):.0%}, over 45 deg {np.mean(tilts > 45):.0%}; feet touching per state "
            f"{touching.sum(1).mean():.2f}, contacts per touching foot {count[touching].mean():.2f} (most "
            f"{int(count.max())}), its deepest {1000 * depth[touching].mean():.2f} mm")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hexa_mjx.evaluation.contact_check", description=__doc__.split("\n\n")[0])
    p.add_argument("policy", help="exported .onnx policy that walks the robot")
    p.add_argument("--terrain", default="bumps", help="hexa_mjx.mdp.terrain kind")
    p.add_argument("--terrain_difficulty", type=float, default=0.0, help="0: a flat heightfield")
    p.add_argument("--terrain_seed", type=int, default=1)
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--steps", type=int, default=300, help="control steps per episode at most")
    p.add_argument("--every", type=int, default=3, help="keep every this many control steps")
    args = p.parse_args(argv)
    if min(args.episodes, args.steps, args.every) < 1:
        p.error("--episodes, --steps and --every must be at least 1")
    try:
        policy = player.OnnxPolicy(args.policy)
        env = player.env_for(policy, terrain=args.terrain, terrain_difficulty=args.terrain_difficulty,
                             terrain_seed=args.terrain_seed, episode_length=args.steps, **CLEAN)
    except (FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    states = walk_states(policy, env, args.episodes, args.every)
    print(f"{len(states)} states of {args.policy} walking on {args.terrain} at difficulty {args.terrain_difficulty:g}")
    touching = []
    for label, per_state in (("native MuJoCo:", native_contacts(env.mj_model, states)),
                             ("MJX:          ", mjx_contacts(env.mj_model, states))):
        count, depth = foot_contacts(per_state, env.robot.feet, env.robot.floor)
        print(label, summary(per_state, count, depth))
        touching.append(count > 0)
    print(f"states where the engines differ on which feet touch: {(touching[0] != touching[1]).any(1).mean():.1%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
