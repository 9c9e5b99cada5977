"""Domain randomization of the physics model: one `mjx.Model` variant per training environment.

    env = make_env(task="navigate")
    fn = randomization_fn(env, Ranges())        # brax ppo.train(..., randomization_fn=fn)
    models, in_axes = fn(env.mjx_model, keys)   # what the training wrappers vmap over
    NativeEnv(config, ranges=Ranges())          # native MuJoCo: a new variant every episode

The pattern of brax's `randomization_fn` and MuJoCo Playground's locomotion tasks: each
environment of the batch gets its own friction, link masses, torso payload, servo gain and force
limit, and joint damping and armature, drawn once per environment for the whole run (brax draws
the batch of models at the start of training). The wrappers (`hexa_mjx.engines.wrappers`) step each
environment with its own model and still redraw start states every episode.

Derived model fields: each variant is drawn on a copy of the MjModel and MuJoCo's mj_setConst
recomputes what depends on the masses (`body_subtreemass`, and `body_invweight0`/`dof_invweight0`,
which set the contact and joint-limit constraints' softness). Left stale, those moved a walking
step as far as the mass change itself did (tests/test_randomization.py).
"""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np


@dataclasses.dataclass(frozen=True)
class Ranges:
    """Uniform ranges (low, high) of each randomized quantity; a range (x, x) fixes it at x."""

    friction: tuple = (0.4, 1.25)  # sliding friction coefficient of every geom
    mass_scale: tuple = (0.8, 1.2)  # each link's mass and inertia, independently
    payload: tuple = (0.0, 1.5)  # kg, added at the torso's centre of mass
    kp_scale: tuple = (0.8, 1.2)  # servo position gain, all servos of an environment together
    force_scale: tuple = (0.8, 1.2)  # servo force limit
    damping_scale: tuple = (0.8, 1.2)  # joint damping
    armature_scale: tuple = (0.8, 1.2)  # joint armature (reflected rotor inertia)

    def check(self) -> None:
        for field in dataclasses.fields(self):
            low, high = getattr(self, field.name)
            if not (np.isfinite(low) and np.isfinite(high) and 0 <= low <= high):
                raise ValueError(f"randomization range {field.name} must be 0 <= low <= high, got ({low}, {high})")
        if self.friction[0] <= 0 or self.mass_scale[0] <= 0:
            raise ValueError("randomized friction and mass scale must stay above 0")


# Drawn (the first seven) or derived from them by MuJoCo's mj_setConst (the last three).
RANDOMIZED_FIELDS = ("geom_friction", "body_mass", "body_inertia", "actuator_gainprm", "actuator_biasprm",
                     "actuator_forcerange", "dof_damping", "dof_armature",
                     "body_subtreemass", "body_invweight0", "dof_invweight0")


def robot_bodies(model: mujoco.MjModel, torso: int) -> np.ndarray:
    """Mask of the torso and every body below it (not the world, not the goal marker)."""
    mask = np.zeros(model.nbody, bool)
    for b in range(1, model.nbody):  # parents come before their children
        mask[b] = b == torso or mask[model.body_parentid[b]]
    return mask


def draw(model: mujoco.MjModel, seed: int, ranges: Ranges, torso: int) -> dict:
    """One randomized variant of `model`: the RANDOMIZED_FIELDS as NumPy arrays. The derived
    constants (subtree masses, the constraint solver's inverse weights at qpos0) are recomputed
    by MuJoCo's mj_setConst on a copy of the model, so nothing is left stale."""
    rng = np.random.default_rng(seed)
    m = copy.copy(model)
    m.geom_friction[:, 0] = rng.uniform(*ranges.friction)
    scale = np.where(robot_bodies(model, torso), rng.uniform(*ranges.mass_scale, model.nbody), 1.0)
    m.body_mass[:] = model.body_mass * scale
    m.body_mass[torso] += rng.uniform(*ranges.payload)  # at the torso's centre of mass
    m.body_inertia[:] = model.body_inertia * scale[:, None]
    kp = rng.uniform(*ranges.kp_scale)
    m.actuator_gainprm[:, 0] = model.actuator_gainprm[:, 0] * kp
    m.actuator_biasprm[:, 1] = model.actuator_biasprm[:, 1] * kp  # position servo: bias = -kp * q
    m.actuator_forcerange[:] = model.actuator_forcerange * rng.uniform(*ranges.force_scale)
    m.dof_damping[:] = model.dof_damping * rng.uniform(*ranges.damping_scale)
    m.dof_armature[:] = model.dof_armature * rng.uniform(*ranges.armature_scale)
    mujoco.mj_setConst(m, mujoco.MjData(m))
    return {name: np.array(getattr(m, name)) for name in RANDOMIZED_FIELDS}


def per_device(models, in_axes, devices: int):
    """`randomization_fn`'s models with each per-environment field laid out (devices, environments
    per device, ...) for pmap (`in_axes` as its in_axes); shared fields stay as they are."""
    import jax

    return jax.tree.map(lambda axis, x: x if axis is None else x.reshape((devices, -1) + x.shape[1:]), in_axes, models,
                        is_leaf=lambda axis: axis is None)


def randomization_fn(env, ranges: Ranges = Ranges()):
    """brax's `randomization_fn(model, rng) -> (models, in_axes)` for an environment, `rng` a
    batch of keys: one model variant per key, drawn on the host when the wrappers are built."""
    import jax
    import jax.numpy as jp

    ranges.check()
    base, torso = env.robot.mj_model, env.robot.torso

    def fn(model, rng):
        seeds = np.asarray(jax.vmap(lambda key: jax.random.randint(key, (), 0, 2 ** 31 - 1))(rng))
        variants = [draw(base, int(seed), ranges, torso) for seed in seeds]
        models = model.tree_replace({name: jp.asarray(np.stack([v[name] for v in variants]), getattr(model, name).dtype)
                                     for name in RANDOMIZED_FIELDS})
        in_axes = jax.tree.map(lambda _: None, model).tree_replace({name: 0 for name in RANDOMIZED_FIELDS})
        return models, in_axes

    return fn
