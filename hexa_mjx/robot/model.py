"""The MJCF model and what both engines read from it: legs, feet, control range, settled start.

`RobotModel` is built with MuJoCo C and NumPy only. The MJX environment (`hexa_mjx.engines.mjx_env`) and
the native-MuJoCo engine (`hexa_mjx.engines.native`: player, Gymnasium) both start from it, so they
share the start state, the action mapping and the contact rules.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from hexa_mjx.robot import constants as robot
from hexa_mjx.mdp import terrain as terrains
from hexa_mjx.mdp.config import EnvConfig
from hexa_mjx.robot.kinematics import namespace


def load_model(path: Path, max_contact_points: int = 0, terrain: terrains.Terrain | None = None) -> mujoco.MjModel:
    """The MJCF at `path` with MJX's contact cap set (0: none, whatever the file says) and its
    floor made a heightfield of `terrain` (None: as the file has it)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"model {path} not found; run `python -m hexa_mjx.robot.convert URDF -o {path}`")
    spec = mujoco.MjSpec.from_file(str(path))
    for numeric in spec.numerics:
        if numeric.name == "max_contact_points":
            spec.delete(numeric)
    if max_contact_points:
        spec.add_numeric(name="max_contact_points", data=[max_contact_points])
    spec.nuserdata = robot.COMMAND_SIZE  # a task's command is physics state (hexa_mjx.tasks.base)
    if terrain is None:
        return spec.compile()
    terrains.add_to_spec(spec, terrain, robot.FLOOR_GEOM, robot.FOOT_SUFFIX, robot.TORSO_GEOM)
    return spec.compile()


def action_to_ctrl(action, ctrl_lo, ctrl_hi):
    """Joint position targets (rad) for actions in [-1, 1] (clipped): -1 is the low end of each
    actuator's control range, +1 the high end."""
    xp = namespace(action)
    return ctrl_lo + (xp.clip(action, -1.0, 1.0) + 1.0) * 0.5 * (ctrl_hi - ctrl_lo)


class RobotModel:
    """The compiled model of an `EnvConfig`, the geoms the rewards read, and the settled start."""

    # Long by design: everything both engines read from the compiled model, read once, here.
    def __init__(self, config: EnvConfig):
        self.terrain = (terrains.generate(config.terrain, config.terrain_seed, config.terrain_difficulty,
                                          config.curriculum_levels) if config.terrain != "flat" else None)
        model = load_model(Path(config.model_path), config.max_contact_points, self.terrain)
        if config.solver_iterations is not None:
            model.opt.iterations = config.solver_iterations
        if config.ls_iterations is not None:
            model.opt.ls_iterations = config.ls_iterations
        self.mj_model = model
        self.n_substeps = substeps(model, config.ctrl_hz)

        self.floor = model.geom(robot.FLOOR_GEOM).id
        self.goal_mocap = int(model.body_mocapid[model.body(robot.GOAL_BODY).id])
        # A leg is whatever hangs from the torso above a foot sphere `<leg>_foot` (the converter
        # names them so), so any joint names work; legs in the model's order of feet.
        self.feet = np.array([g for g in range(model.ngeom) if (model.geom(g).name or "").endswith(robot.FOOT_SUFFIX)])
        if len(self.feet) == 0:
            raise ValueError(f"{config.model_path} has no foot geoms (spheres named <leg>{robot.FOOT_SUFFIX}); "
                             "convert the robot with `python -m hexa_mjx.robot.convert`")
        self.legs = [model.geom(g).name[: -len(robot.FOOT_SUFFIX)] for g in self.feet]
        # Leg index of every body from a foot up to the torso (the free joint's body); other
        # bodies below a leg body join that leg; the torso and the world are -1.
        self.torso = torso = int(model.jnt_bodyid[np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)[0]])
        body_leg = np.full(model.nbody, -1)
        for i, foot in enumerate(self.feet):
            b = model.geom_bodyid[foot]
            while b not in (torso, 0):
                body_leg[b] = i
                b = model.body_parentid[b]
        for b in range(1, model.nbody):  # parents precede children in MuJoCo's body order
            if body_leg[b] < 0 and b != torso and body_leg[model.body_parentid[b]] >= 0:
                body_leg[b] = body_leg[model.body_parentid[b]]
        self.geom_leg = body_leg[model.geom_bodyid]
        joints = model.actuator_trnid[:, 0]
        self.actuator_leg = body_leg[model.jnt_bodyid[joints]]  # leg index of each actuator
        self.actuator_qpos = model.jnt_qposadr[joints]  # each actuator's joint angle in qpos
        self.actuator_dof = model.jnt_dofadr[joints]  # each actuator's joint velocity in qvel
        self.actuator_joints = [model.joint(j).name for j in joints]  # the joint each actuator drives
        self.hips = [int(joints[np.flatnonzero(self.actuator_leg == i)[0]]) for i in range(len(self.legs))]  # joint ids
        for leg in config.disabled_legs:
            if leg > len(self.legs):
                raise ValueError(f"disabled_legs: leg {leg} does not exist; this robot has legs 1 to {len(self.legs)}")
        if config.leg_failure_weights and len(config.leg_failure_weights) != len(self.legs):
            raise ValueError(f"leg_failure_weights needs one weight per leg ({len(self.legs)}), "
                             f"got {len(config.leg_failure_weights)}")
        if len(config.disabled_legs) == len(self.legs):
            raise ValueError(f"disabled_legs disables all {len(self.legs)} legs; leave at least one working")
        self.geom_is_foot = np.isin(np.arange(model.ngeom), self.feet)
        self.foot_radius = model.geom_size[self.feet, 0]  # m
        self.ctrl_lo, self.ctrl_hi = (np.asarray(x, np.float32) for x in model.actuator_ctrlrange.T)
        hinges = model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
        self.joint_lo, self.joint_hi = (np.asarray(x, np.float32) for x in model.jnt_range[hinges].T)

        # Settle the start pose once with MuJoCo C; every episode starts from that state.
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
        for _ in range(config.settle_steps):
            mujoco.mj_step(model, data)
        self.qpos0, self.qvel0, self.ctrl0 = (np.array(x) for x in (data.qpos, data.qvel, data.ctrl))
        self.mass = float(model.body_subtreemass[torso])  # kg, the whole robot
        # m, hip axis to foot centre in the standing pose, mean over legs (for the Froude number)
        self.leg_length = float(np.mean(np.linalg.norm(data.xanchor[self.hips] - data.geom_xpos[self.feet], axis=1)))
        self.start_xy = self.qpos0[:2].copy()
        # Legs in their order around the torso (the hips' bearings from its centre): two legs are
        # adjacent when they are neighbours on that ring (--leg_failure_pairs fails two that are not).
        hips = (data.xanchor[self.hips] - data.xpos[torso]) @ data.xmat[torso].reshape(3, 3)  # torso frame
        self.hip_bearings = np.arctan2(hips[:, 1], hips[:, 0])  # rad, counter-clockwise from the torso's x axis
        ring = np.argsort(np.argsort(self.hip_bearings))
        n = len(self.legs)
        self.non_adjacent_pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)
                                            if min((ring[i] - ring[j]) % n, (ring[j] - ring[i]) % n) > 1],
                                           np.int32).reshape(-1, 2)  # leg indices from 0
        if config.leg_failure_pairs and not len(self.non_adjacent_pairs):
            raise ValueError(f"leg_failure_pairs fails two non-adjacent legs; this robot's {n} legs have no such pair: "
                             "leave it at 0")
        self.hold_ctrl = self.qpos0[self.actuator_qpos].astype(np.float32)  # a locked leg's targets, rad

    def ground(self, xy):
        """Ground height (m) under the points `xy` (..., 2): 0 on the flat floor."""
        return terrains.ground_height(self.terrain, xy)

    def floor_contact_geoms(self, geom1, geom2, dist):
        """(active robot-floor contact mask, the robot geom of each contact) from contact arrays of
        either engine."""
        xp = namespace(dist)
        on_floor = (dist < 0) & ((geom1 == self.floor) | (geom2 == self.floor))
        return on_floor, xp.where(geom1 == self.floor, geom2, geom1)

    def foot_stance(self, geom1, geom2, dist):
        """Whether each foot touches the floor, (legs,) bool, from contact arrays of either engine."""
        xp = namespace(dist)
        on_floor, other = self.floor_contact_geoms(geom1, geom2, dist)
        return (on_floor[None] & (other[None] == xp.asarray(self.feet)[:, None])).any(1)

    def contact_counts(self, geom1, geom2, dist, foot_pos, lift_clearance: float):
        """(leg contacts while that leg's foot is lifted more than `lift_clearance` m above the
        ground under it, contacts of any non-foot geom) among contacts with the floor, from contact
        arrays of either engine; `foot_pos` (feet, 3) are the foot spheres' centres."""
        xp = namespace(dist)
        on_floor, other = self.floor_contact_geoms(geom1, geom2, dist)
        leg = xp.asarray(self.geom_leg)[other]
        clearance = foot_pos[:, 2] - xp.asarray(self.foot_radius) - self.ground(foot_pos[:, :2])
        lifted = clearance[xp.maximum(leg, 0)] > lift_clearance
        bad = on_floor & (leg >= 0) & lifted
        return bad.sum(), (on_floor & ~xp.asarray(self.geom_is_foot)[other]).sum()


def servo_power(actuator_force, qvel, actuator_dof):
    """Mechanical power of the servos, sum over joints of |torque x joint velocity|, W."""
    return abs(actuator_force * qvel[actuator_dof]).sum()


def failed_ctrl(target, joint_angles, failed_actuators, mode: str, hold):
    """Servo targets with failed actuators disabled: a limp servo's target follows its joint's
    angle (no spring torque), a locked one's is `hold`. `mode` "mixed" reads which from
    `failed_actuators` (0 working, 1 limp, 2 locked). NumPy or JAX arrays."""
    xp = namespace(target)
    if mode == "mixed":  # each episode's failure is limp or locked: 1 limp, 2 locked, 0 working
        return xp.where(failed_actuators == 2, hold, xp.where(failed_actuators == 1, joint_angles, target))
    return xp.where(failed_actuators, joint_angles if mode == "limp" else hold, target)


def substeps(model: mujoco.MjModel, ctrl_hz: float) -> int:
    """Physics steps per control step; a clear error when `ctrl_hz` doesn't divide the physics rate."""
    n = 1.0 / (ctrl_hz * model.opt.timestep)
    if abs(n - round(n)) > 1e-3 or round(n) < 1:
        rate = round(1.0 / model.opt.timestep, 3)  # the MJCF stores the timestep to 6 digits
        choices = [round(rate / k, 3) for k in range(1, 13) if abs(rate / k - round(rate / k)) < 1e-3]
        raise ValueError(f"ctrl_hz={ctrl_hz} is not the {rate:g} Hz physics rate divided by a whole "
                         f"number; choose e.g. one of {choices}")
    return int(round(n))
