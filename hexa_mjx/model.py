"""The MJCF model and what both engines read from it: legs, feet, control range, settled start.

`RobotModel` is built with MuJoCo C and NumPy only. The MJX environment (`hexa_mjx.env`) and
the native-MuJoCo engine (`hexa_mjx.native`: player, Gymnasium) both start from it, so they
share the start state, the action mapping and the contact rules.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from hexa_mjx import robot
from hexa_mjx.env_config import EnvConfig
from hexa_mjx.kinematics import namespace


def load_model(path: Path, max_contact_points: int = 0) -> mujoco.MjModel:
    """The MJCF at `path` with MJX's contact cap set (0: none, whatever the file says)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"model {path} not found; run `python -m hexa_mjx.convert URDF -o {path}`")
    spec = mujoco.MjSpec.from_file(str(path))
    for numeric in spec.numerics:
        if numeric.name == "max_contact_points":
            spec.delete(numeric)
    if max_contact_points:
        spec.add_numeric(name="max_contact_points", data=[max_contact_points])
    return spec.compile()


def action_to_ctrl(action, ctrl_lo, ctrl_hi):
    """Joint position targets (rad) for actions in [-1, 1] (clipped): -1 is the low end of each
    actuator's control range, +1 the high end."""
    xp = namespace(action)
    return ctrl_lo + (xp.clip(action, -1.0, 1.0) + 1.0) * 0.5 * (ctrl_hi - ctrl_lo)


class RobotModel:
    """The compiled model of an `EnvConfig`, the geoms the rewards read, and the settled start."""

    def __init__(self, config: EnvConfig):
        model = load_model(Path(config.model_path), config.max_contact_points)
        if config.solver_iterations is not None:
            model.opt.iterations = config.solver_iterations
        if config.ls_iterations is not None:
            model.opt.ls_iterations = config.ls_iterations
        self.mj_model = model
        self.n_substeps = substeps(model, config.ctrl_hz)

        self.floor = model.geom(robot.FLOOR_GEOM).id
        self.torso = model.body(robot.TORSO_BODY).id
        self.goal_mocap = int(model.body_mocapid[model.body(robot.GOAL_BODY).id])
        legs = sorted({model.joint(j).name.split("_")[0] for j in range(model.njnt)
                       if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE}, key=lambda s: int(s[3:]))
        self.feet = np.array([model.geom(robot.foot_geom(leg)).id for leg in legs])  # foot geom ids
        # Leg index of every geom (-1 for the torso and the world), and whether it is a foot.
        body_leg = np.full(model.nbody, -1)
        for i, leg in enumerate(legs):
            for j in range(model.njnt):
                if model.joint(j).name.startswith(leg + "_"):
                    body_leg[model.jnt_bodyid[j]] = i
        for b in range(1, model.nbody):  # bodies without joints inherit their parent's leg
            if body_leg[b] < 0 and model.body_parentid[b] > 0:
                body_leg[b] = body_leg[model.body_parentid[b]]
        self.geom_leg = body_leg[model.geom_bodyid]
        self.geom_is_foot = np.isin(np.arange(model.ngeom), self.feet)
        self.foot_radius = model.geom_size[self.feet, 0]  # m
        self.ctrl_lo, self.ctrl_hi = (np.asarray(x, np.float32) for x in model.actuator_ctrlrange.T)
        hinges = model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
        self.joint_names = [model.joint(j).name for j in np.flatnonzero(hinges)]
        self.joint_lo, self.joint_hi = (np.asarray(x, np.float32) for x in model.jnt_range[hinges].T)

        # Settle the start pose once with MuJoCo C; every episode starts from that state.
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        for _ in range(config.settle_steps):
            mujoco.mj_step(model, data)
        self.qpos0, self.qvel0, self.ctrl0 = (np.array(x) for x in (data.qpos, data.qvel, data.ctrl))
        self.start_xy = self.qpos0[:2].copy()

    def contact_counts(self, geom1, geom2, dist, foot_z, lift_clearance: float):
        """(leg contacts while that leg's foot is lifted more than `lift_clearance` m, contacts of
        any non-foot geom) among contacts with the floor, from contact arrays of either engine."""
        xp = namespace(dist)
        on_floor = (dist < 0) & ((geom1 == self.floor) | (geom2 == self.floor))
        other = xp.where(geom1 == self.floor, geom2, geom1)
        leg = xp.asarray(self.geom_leg)[other]
        lifted = (foot_z - xp.asarray(self.foot_radius))[xp.maximum(leg, 0)] > lift_clearance
        bad = on_floor & (leg >= 0) & lifted
        return bad.sum(), (on_floor & ~xp.asarray(self.geom_is_foot)[other]).sum()


def substeps(model: mujoco.MjModel, ctrl_hz: float) -> int:
    """Physics steps per control step; a clear error when `ctrl_hz` doesn't divide the physics rate."""
    n = 1.0 / (ctrl_hz * model.opt.timestep)
    if abs(n - round(n)) > 1e-3 or round(n) < 1:
        rate = round(1.0 / model.opt.timestep, 3)  # the MJCF stores the timestep to 6 digits
        choices = [round(rate / k, 3) for k in range(1, 13) if abs(rate / k - round(rate / k)) < 1e-3]
        raise ValueError(f"ctrl_hz={ctrl_hz} is not the {rate:g} Hz physics rate divided by a whole "
                         f"number; choose e.g. one of {choices}")
    return int(round(n))
