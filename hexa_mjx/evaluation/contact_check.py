"""Contact normals on a heightfield: native MuJoCo's collider against MJX's, on the same states.

    python -m hexa_mjx.evaluation.contact_check policies/navigate.onnx --terrain bumps --terrain_difficulty 0

A policy walks in native MuJoCo (`hexa_mjx.deploy.player`); every few control steps its state is kept, and
both engines' colliders run on the kept states. On a zero-height heightfield the ground is flat,
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


def native_tilts(model: mujoco.MjModel, states: np.ndarray) -> np.ndarray:
    """Normal tilts of the penetrating contacts MuJoCo C finds at each state."""
    data, tilts = mujoco.MjData(model), []
    for qpos in states:
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        tilts += [tilt_degrees(c.frame[2]) for c in data.contact[:data.ncon] if c.dist < 0]
    return np.array(tilts)


def mjx_tilts(model: mujoco.MjModel, states: np.ndarray) -> np.ndarray:
    """Normal tilts of the penetrating contacts MJX (JAX implementation) finds at each state."""
    import jax
    import jax.numpy as jp
    from mujoco import mjx

    from hexa_mjx.engines import contacts

    mx = mjx.put_model(model)

    def penetrations(qpos):
        data = mjx.forward(mx, mjx.make_data(mx).replace(qpos=qpos))
        return contacts.of(data)[2], contacts.normals(data)[:, 2]

    dist, z = (np.asarray(x) for x in jax.jit(jax.vmap(penetrations))(jp.asarray(states, jp.float32)))
    return tilt_degrees(z[dist < 0])


def summary(tilts: np.ndarray, states: int) -> str:
    return (f"{len(tilts)} penetrating contacts ({len(tilts) / states:.1f} per state); normals tilted over 10 deg "
            f"{np.mean(tilts > 10):.0%}, over 45 deg {np.mean(tilts > 45):.0%}")


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
    print("native MuJoCo:", summary(native_tilts(env.mj_model, states), len(states)))
    print("MJX:          ", summary(mjx_tilts(env.mj_model, states), len(states)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
