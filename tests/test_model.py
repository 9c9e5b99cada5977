"""The committed MJCF: structure, standing, solver accuracy, and that it is the converter's output."""

import mujoco
import numpy as np
import pytest

from hexa_mjx.robot import convert, constants as robot
from hexa_mjx.studies.benchmark import solver_error


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_path(str(robot.MODEL_XML))


def test_structure(model):
    assert model.nu == 18
    assert [model.actuator(i).name for i in range(model.nu)] == list(robot.JOINT_NAMES)
    assert (model.jnt_type == mujoco.mjtJoint.mjJNT_FREE).sum() == 1
    feet = [model.geom(robot.foot_geom(leg)) for leg in robot.LEGS]
    assert all(f.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE for f in feet)
    np.testing.assert_allclose(model.actuator_forcerange, [[-robot.TORQUE_LIMIT, robot.TORQUE_LIMIT]] * 18)
    assert model.opt.timestep == pytest.approx(1 / 240, rel=1e-5)
    assert not (model.geom_type == mujoco.mjtGeom.mjGEOM_MESH).any()  # primitives only
    # The URDF's joint limits (MuJoCo's XML writer keeps 6 significant digits) and total mass.
    hips, knees, ankles = (model.jnt_range[1:][i::3] for i in range(3))
    np.testing.assert_allclose(hips, [[-0.785398, 0.785398]] * 6, atol=1e-5)
    np.testing.assert_allclose(knees, [[-1.570796, 1.570796]] * 6, atol=1e-5)
    np.testing.assert_allclose(ankles, [[-1.047198, 3.141593]] * 6, atol=1e-5)
    assert model.body_subtreemass[model.body(robot.TORSO_BODY).id] == pytest.approx(10.23, abs=0.01)


def test_no_self_collision(model):
    robot_geoms = model.geom_bodyid != 0
    robot_geoms[model.body(robot.GOAL_BODY).id == model.geom_bodyid] = False
    ct, ca = model.geom_contype[robot_geoms], model.geom_conaffinity[robot_geoms]
    assert not (np.bitwise_and.outer(ct, ca) | np.bitwise_and.outer(ca, ct)).any()


def test_holds_start_pose_for_five_seconds(model):
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    z0 = data.qpos[2]
    for _ in range(int(5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert abs(data.qpos[2] - z0) < 0.01  # m
    up = np.zeros(9)
    mujoco.mju_quat2Mat(up, data.qpos[3:7])
    assert up[8] > np.cos(0.05)  # torso tilt under 0.05 rad
    feet = {model.geom(robot.foot_geom(leg)).id for leg in robot.LEGS}
    assert {int(c.geom[1]) for c in data.contact[: data.ncon]} == feet


def test_fast_solver_stays_close_to_tight_solver(env):
    pos, joint = solver_error(env, steps=15)  # 0.25 s of a gait
    assert pos < 0.01 and joint < 0.15


@pytest.mark.skipif(not robot.SEED_URDF.is_file(), reason=f"reference robot {robot.SEED_URDF} absent (../shared)")
def test_committed_model_is_converter_output():
    assert convert.convert(robot.SEED_URDF) == robot.MODEL_XML.read_text(), (
        "models/hexapod.xml is stale: run `python -m hexa_mjx.robot.convert ../shared/robots/seed_hexapod/hexapod.urdf`")
