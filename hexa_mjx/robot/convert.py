"""URDF to MJX-friendly MJCF.

    python -m hexa_mjx.robot.convert path/to/robot.urdf -o models/hexapod.xml
    python -m hexa_mjx.robot.convert quad.urdf -o models/quad.xml --legs "lf:hip_lf,knee_lf,ankle_lf rf:hip_rf,knee_rf,ankle_rf ..."

MuJoCo's own URDF importer reads the file (fusing fixed joints into their parent
bodies); this module then writes a clean MJCF with the URDF's masses, inertias,
joint axes and limits, collision primitives fitted to the meshes (a box for the
torso, a capsule per leg link, a sphere at each leg tip), robot-floor collisions
only, position servos on the leg joints, a floor, lights, a tracking camera and a
mocap goal marker. The meshes are read at conversion time and not referenced by
the output, so the MJCF stands alone.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mujoco
import numpy as np

from hexa_mjx import atomic
from hexa_mjx.robot import constants as robot
from hexa_mjx.robot.urdf import ConversionError, Leg, load_urdf, parse_legs  # noqa: F401 (ConversionError: API)


def body_vertices(model: mujoco.MjModel, body: int) -> np.ndarray:
    """Vertices of all mesh geoms of `body`, in the body frame."""
    out = []
    for g in np.flatnonzero(model.geom_bodyid == body):
        mesh = model.geom_dataid[g]
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH or mesh < 0:
            continue
        start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        out.append(model.geom_pos[g] + model.mesh_vert[start : start + count] @ rot.reshape(3, 3).T)
    return np.concatenate(out) if out else np.zeros((0, 3))


def fit_box(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounding box: (centre, half sizes)."""
    lo, hi = verts.min(0), verts.max(0)
    return (lo + hi) / 2, (hi - lo) / 2


def fit_capsule(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Capsule along the principal axis: (end a, end b, radius)."""
    centre = verts.mean(0)
    _, _, vt = np.linalg.svd(verts - centre, full_matrices=False)
    axis = vt[0]
    t = (verts - centre) @ axis
    radial = np.linalg.norm(verts - centre - np.outer(t, axis), axis=1)
    radius = float(np.percentile(radial, robot.CAPSULE_RADIUS_PERCENTILE))
    lo, hi = t.min() + radius, t.max() - radius
    if hi < lo:  # shorter than it is wide
        lo = hi = (t.min() + t.max()) / 2
    return centre + lo * axis, centre + hi * axis, radius


# ---------------------------------------------------------------------------
# Writing the MJCF


def _add_scene(spec: mujoco.MjSpec) -> None:
    spec.add_texture(name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                     rgb1=[0.2, 0.3, 0.4], rgb2=[0.1, 0.2, 0.3], width=300, height=300, mark=mujoco.mjtMark.mjMARK_EDGE,
                     markrgb=[0.8, 0.8, 0.8])
    spec.add_material(name="grid", texrepeat=[5, 5], reflectance=0.1, textures=["", "grid"])
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.3, 0.5, 0.7], rgb2=[0, 0, 0], width=512, height=512)
    world = spec.worldbody
    # Floor: collides with the robot only (contype 0, conaffinity 1; robot geoms are the reverse).
    world.add_geom(name=robot.FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05], material="grid",
                   contype=0, conaffinity=1, friction=[robot.FRICTION, 0.005, 0.0001])
    world.add_light(name="sun", pos=[0, 0, 3], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, diffuse=[0.7, 0.7, 0.7])
    world.add_light(name="spot", mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM, pos=[0, -1, 2], dir=[0, 0.5, -1],
                    diffuse=[0.3, 0.3, 0.3])
    # Goal marker: a mocap body the environment moves; a disc shows the success radius.
    goal = world.add_body(name=robot.GOAL_BODY, mocap=True, pos=[1.5, 0, 0])
    goal.add_geom(name="goal_disc", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.5, 0.001, 0], pos=[0, 0, 0.001],
                  rgba=[0.1, 0.9, 0.2, 0.25], contype=0, conaffinity=0, group=1)
    goal.add_geom(name="goal_pole", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.01, 0.15, 0], pos=[0, 0, 0.15],
                  rgba=[0.1, 0.9, 0.2, 1], contype=0, conaffinity=0, group=1)


def _collision_geom(body: mujoco.MjsBody, name: str, **kwargs) -> None:
    body.add_geom(name=name, contype=1, conaffinity=0, condim=3, friction=[robot.FRICTION, 0.005, 0.0001],
                  rgba=[0.75, 0.75, 0.8, 1], **kwargs)


# Long by design: the MJCF is built in the order its parts appear in the file it writes.
def build_spec(urdf_path: str | Path, legs: list[Leg] | None = None) -> mujoco.MjSpec:
    """Build the MJCF spec for a URDF robot (see module docstring)."""
    src, root_link, legs = load_urdf(urdf_path, legs)
    spec = mujoco.MjSpec()
    spec.modelname = Path(urdf_path).stem
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option.timestep = robot.PHYSICS_DT
    spec.option.iterations = robot.SOLVER_ITERATIONS
    spec.option.ls_iterations = robot.SOLVER_LS_ITERATIONS
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    _add_scene(spec)

    leg_joints = {j: leg for leg in legs for j in leg.joints}
    tip_body = {src.joint(leg.joints[-1]).bodyid[0]: leg for leg in legs}
    root_id = src.body(root_link).id
    made: dict[int, mujoco.MjsBody] = {0: spec.worldbody}
    for b in range(1, src.nbody):  # parents precede children in MuJoCo's body order
        parent = made[int(src.body_parentid[b])]
        body = parent.add_body(name=src.body(b).name, pos=src.body_pos[b], quat=src.body_quat[b],
                               mass=src.body_mass[b], ipos=src.body_ipos[b], iquat=src.body_iquat[b],
                               inertia=src.body_inertia[b], explicitinertial=True)
        made[b] = body
        for j in np.flatnonzero(src.jnt_bodyid == b):
            name = src.joint(j).name
            if src.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                body.add_freejoint(name="root")
            elif name in leg_joints:
                body.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_HINGE, pos=src.jnt_pos[j], axis=src.jnt_axis[j],
                               range=src.jnt_range[j], limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                               damping=robot.JOINT_DAMPING, armature=robot.ARMATURE)
            else:
                raise ConversionError(f"joint {name!r} is not a leg joint; only leg joints and fixed joints are supported")
        verts = body_vertices(src, b)
        if len(verts) == 0:
            continue
        if b == root_id:
            centre, half = fit_box(verts)
            _collision_geom(body, robot.TORSO_GEOM, type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre, size=half)
            continue
        a, c, radius = fit_capsule(verts)
        if b in tip_body:
            leg = tip_body[b]
            anchor = src.jnt_pos[src.joint(leg.joints[-1]).id]
            tip = verts[np.argmax(np.linalg.norm(verts - anchor, axis=1))]
            along = (tip - anchor) / np.linalg.norm(tip - anchor)
            foot = tip - robot.FOOT_RADIUS * along
            # The shin capsule stops above the foot sphere, so a foot planted on the floor
            # is the only contact of that leg (otherwise contact terms would misfire).
            if (c - a) @ along > 0:  # make `a` the end nearer the foot
                a, c = c, a
            # Along the leg, the capsule's surface must end where the foot sphere's top is.
            excess = (a - tip) @ along + radius + 2 * robot.FOOT_RADIUS
            if excess > 0:
                axis = (c - a) / max(np.linalg.norm(c - a), 1e-9)
                a = a + axis * min(excess / max(-(axis @ along), 1e-3), np.linalg.norm(c - a))
            _collision_geom(body, robot.foot_geom(leg.name), type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=foot,
                            size=[robot.FOOT_RADIUS, 0, 0])
        name = f"{src.body(b).name}_geom"
        if np.linalg.norm(a - c) < 1e-3:  # a link about as long as it is wide
            _collision_geom(body, name, type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=(a + c) / 2, size=[radius, 0, 0])
        else:
            _collision_geom(body, name, type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=np.concatenate([a, c]),
                            size=[radius, 0, 0])

    torso = made[root_id]
    torso.add_camera(name=robot.TRACKING_CAMERA, mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM, pos=[-0.6, -0.9, 0.7],
                     xyaxes=[0.83, -0.55, 0, 0.3, 0.45, 0.84])
    for leg in legs:
        for j in leg.joints:
            spec.add_actuator(name=j, target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                              ctrlrange=src.jnt_range[src.joint(j).id], ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE,
                              forcerange=[-robot.TORQUE_LIMIT, robot.TORQUE_LIMIT],
                              forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
                              gaintype=mujoco.mjtGain.mjGAIN_FIXED, gainprm=[robot.KP] + [0] * 9,
                              biastype=mujoco.mjtBias.mjBIAS_AFFINE, biasprm=[0, -robot.KP, 0] + [0] * 7)
    _add_home_keyframe(spec)
    return spec


def _add_home_keyframe(spec: mujoco.MjSpec) -> None:
    """'home': joints at zero, the lowest foot resting on the floor (no penetration)."""
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    feet = (model.geom_contype == 1) & (model.geom_type == mujoco.mjtGeom.mjGEOM_SPHERE)
    lowest = np.min(data.geom_xpos[feet, 2] - model.geom_size[feet, 0])
    qpos = model.qpos0.copy()
    qpos[2] = -lowest
    spec.add_key(name="home", qpos=qpos, ctrl=np.zeros(model.nu), mpos=model.body_pos[model.body(robot.GOAL_BODY).id])


def convert(urdf_path: str | Path, legs: str = "") -> str:
    """The MJCF text for a URDF robot; `legs` maps leg names to joints ("" finds `<leg>_<kind>`)."""
    spec = build_spec(urdf_path, parse_legs(legs) if legs else None)
    xml = spec.to_xml()
    mujoco.MjModel.from_xml_string(xml)  # the output must load on its own
    return xml


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.robot.convert", description=__doc__.split("\n\n")[0])
    parser.add_argument("urdf", type=Path, help="URDF file; meshes beside it or in meshes/ next to it")
    parser.add_argument("-o", "--output", type=Path, default=robot.MODEL_XML, help="MJCF file to write")
    parser.add_argument("--legs", default="", help='leg mapping for other joint names: "NAME:JOINT,JOINT,... '
                        'NAME:..." (joints from the body outward; default: joints named <leg>_hip/knee/ankle)')
    args = parser.parse_args(argv)
    if args.output.is_dir():
        print(f"error: -o {args.output} is a folder; name the MJCF file to write (e.g. {args.output / 'robot.xml'})",
              file=sys.stderr)
        return 2
    try:
        xml = convert(args.urdf, args.legs)
    except ConversionError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        atomic.write(args.output, xml)
    except OSError as e:
        print(f"error: cannot write {args.output}: {e.strerror or e}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
