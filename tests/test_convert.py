"""The URDF converter on a small robot this test builds, and its error cases."""

import struct
from pathlib import Path

import mujoco
import numpy as np
import pytest

from hexa_mjx.robot import convert, constants as robot


def write_box_stl(path: Path, lo, hi, scale=1000.0):
    """A binary STL of the box [lo, hi] (metres), stored in millimetres like the CAD export."""
    lo, hi = np.asarray(lo) * scale, np.asarray(hi) * scale
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for tri in faces:
            f.write(struct.pack("<12fH", 0, 0, 0, *corners[list(tri)].ravel(), 0))


LINK = """<link name="{name}">
  <inertial><origin xyz="{com}"/><mass value="{mass}"/>
    <inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" iyz="0" ixz="0"/></inertial>
  <collision><geometry><mesh filename="package://toy_description/meshes/{name}.stl" scale="0.001 0.001 0.001"/></geometry></collision>
</link>"""
JOINT = """<joint name="{name}" type="{type}"><origin xyz="{xyz}"/><parent link="{parent}"/><child link="{child}"/>
  <axis xyz="{axis}"/><limit lower="{lo}" upper="{hi}" effort="10" velocity="10"/></joint>"""

# link: (box lo, box hi in the link frame, m), mass kg
BOXES = {
    "base_link": ((-0.1, -0.06, -0.03), (0.1, 0.06, 0.01), 2.0),
    "servo": ((-0.02, -0.02, -0.02), (0.02, 0.02, 0.02), 0.1),
    "hip": ((0.0, -0.01, -0.01), (0.03, 0.01, 0.01), 0.1),
    "femur": ((0.0, -0.01, -0.01), (0.08, 0.01, 0.01), 0.2),
    "tibia": ((-0.01, -0.01, -0.15), (0.01, 0.01, 0.0), 0.2),
}


def make_toy(tmp_path: Path, legs=2, drop_joint=None, missing_mesh=None, joint_name="leg{i}_{kind}") -> Path:
    """A URDF with `legs` legs in pairs along +-y (hip/knee/ankle each, named by `joint_name`),
    a fixed servo link, and box meshes."""
    mesh_dir = tmp_path / "meshes"
    mesh_dir.mkdir(exist_ok=True)
    links, joints = [], []

    def add_link(name, kind):
        lo, hi, mass = BOXES[kind]
        if name != missing_mesh:
            write_box_stl(mesh_dir / f"{name}.stl", lo, hi)
        links.append(LINK.format(name=name, com=" ".join(str((a + b) / 2) for a, b in zip(lo, hi)), mass=mass))

    add_link("base_link", "base_link")
    add_link("servo", "servo")
    joints.append(JOINT.format(name="Rigid 1", type="fixed", xyz="0 0 0.03", parent="base_link", child="servo",
                               axis="0 0 1", lo=0, hi=0))
    for i in range(1, legs + 1):
        side = 1 if i % 2 else -1
        for kind in ("hip", "femur", "tibia"):
            add_link(f"{kind}_{i}", kind)
        x = 0.08 * ((i - 1) // 2 - (legs / 2 - 1) / 2)  # pairs spread along the body
        spec = [("hip", "base_link", f"hip_{i}", f"{x} {0.06 * side} -0.01", "0 0 1", -0.7, 0.7),
                ("knee", f"hip_{i}", f"femur_{i}", "0.03 0 0", "0 1 0", -1.5, 1.5),
                ("ankle", f"femur_{i}", f"tibia_{i}", "0.08 0 0", "0 1 0", -1.0, 3.0)]
        for kind, parent, child, xyz, axis, lo, hi in spec:
            name = joint_name.format(i=i, kind=kind)
            if name != drop_joint:
                joints.append(JOINT.format(name=name, type="revolute", xyz=xyz, parent=parent, child=child,
                                           axis=axis, lo=lo, hi=hi))
            else:  # keep the tree connected with a fixed joint instead
                joints.append(JOINT.format(name=name + "_fixed", type="fixed", xyz=xyz, parent=parent, child=child,
                                           axis=axis, lo=0, hi=0))
    path = tmp_path / "toy.urdf"
    path.write_text('<?xml version="1.0"?>\n<robot name="toy">\n' + "\n".join(links + joints) + "\n</robot>\n")
    return path


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    urdf = make_toy(tmp_path_factory.mktemp("toy"))
    return urdf, mujoco.MjModel.from_xml_string(convert.convert(urdf))


def test_toy_converts_with_legs_feet_and_servos(toy):
    _, model = toy
    assert model.nu == 6
    assert [model.actuator(i).name for i in range(6)] == [f"leg{i}_{k}" for i in (1, 2) for k in robot.JOINT_KINDS]
    assert (model.jnt_type == mujoco.mjtJoint.mjJNT_FREE).sum() == 1
    for leg in ("leg1", "leg2"):
        assert model.geom(robot.foot_geom(leg)).type[0] == mujoco.mjtGeom.mjGEOM_SPHERE
    assert model.ngeom > 0 and not (model.geom_type == mujoco.mjtGeom.mjGEOM_MESH).any()
    np.testing.assert_allclose(model.actuator_forcerange[0], [-robot.TORQUE_LIMIT, robot.TORQUE_LIMIT])
    np.testing.assert_allclose(model.jnt_range[model.joint("leg2_ankle").id], [-1.0, 3.0])
    np.testing.assert_allclose(model.jnt_axis[model.joint("leg1_knee").id], [0, 1, 0])


def test_toy_fuses_fixed_joints_and_keeps_mass(toy):
    _, model = toy
    names = {model.body(b).name for b in range(model.nbody)}
    assert "servo" not in names  # fused into base_link
    total = sum(m for _, _, m in BOXES.values()) - BOXES["hip"][2] - BOXES["femur"][2] - BOXES["tibia"][2]
    total += 2 * (BOXES["hip"][2] + BOXES["femur"][2] + BOXES["tibia"][2])
    assert model.body_subtreemass[model.body("base_link").id] == pytest.approx(total)


def test_toy_primitives_cover_the_meshes(toy):
    _, model = toy
    torso = model.geom(robot.TORSO_GEOM)
    # base box z -0.03..0.01 and the fused servo box at z 0.03 +- 0.02: union z -0.03..0.05
    np.testing.assert_allclose(torso.size, [0.1, 0.06, 0.04], atol=1e-6)
    foot = model.geom(robot.foot_geom("leg1"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    tibia_tip = data.xpos[model.body("tibia_1").id] + [0, 0, -0.15]
    # The foot sphere sits inside the tibia's end, its bottom at the mesh tip (box corner within 1.5 cm).
    assert np.linalg.norm(data.geom_xpos[foot.id] - tibia_tip) < 0.02
    assert data.geom_xpos[foot.id][2] - robot.FOOT_RADIUS == pytest.approx(tibia_tip[2], abs=0.002)


def test_toy_home_pose_rests_on_feet(toy):
    _, model = toy
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    feet = [model.geom(robot.foot_geom(leg)).id for leg in ("leg1", "leg2")]
    lowest = min(data.geom_xpos[f, 2] - model.geom_size[f, 0] for f in feet)
    assert lowest == pytest.approx(0.0, abs=1e-6)


def test_cli_writes_the_file(toy, tmp_path):
    urdf, _ = toy
    out = tmp_path / "sub" / "toy.xml"
    assert convert.main([str(urdf), "-o", str(out)]) == 0
    assert out.read_text() == convert.convert(urdf)


def test_malformed_urdf(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot>")
    with pytest.raises(convert.ConversionError, match="malformed URDF"):
        convert.convert(bad)
    bad.write_text("<sdf/>")
    with pytest.raises(convert.ConversionError, match="not a URDF"):
        convert.convert(bad)
    with pytest.raises(convert.ConversionError, match="does not exist"):
        convert.convert(tmp_path / "nothing.urdf")


def test_missing_mesh(tmp_path):
    urdf = make_toy(tmp_path, missing_mesh="femur_2")
    with pytest.raises(convert.ConversionError, match=r"mesh 'package://toy_description/meshes/femur_2.stl' not found"):
        convert.convert(urdf)


def test_leg_without_ankle(tmp_path):
    urdf = make_toy(tmp_path, drop_joint="leg2_ankle")
    with pytest.raises(convert.ConversionError, match=r"leg 'leg2' lacks joint\(s\) \['leg2_ankle'\]"):
        convert.convert(urdf)


def test_robot_without_leg_joints(tmp_path):
    urdf = make_toy(tmp_path, legs=0)
    with pytest.raises(convert.ConversionError, match="no leg joints found"):
        convert.convert(urdf)


def test_cli_reports_errors_without_traceback(tmp_path, capsys):
    urdf = make_toy(tmp_path, drop_joint="leg1_hip")
    assert convert.main([str(urdf), "-o", str(tmp_path / "x.xml")]) == 2
    assert "error: leg 'leg1' lacks joint(s) ['leg1_hip']" in capsys.readouterr().err
    assert not (tmp_path / "x.xml").exists()


QUAD = "{kind}_{i}x"  # joint names the default pattern does not match
QUAD_LEGS = " ".join(f"l{i}:hip_{i}x,knee_{i}x,ankle_{i}x" for i in range(1, 5))


def test_other_robot_with_a_leg_mapping_trains_on_both_engines(tmp_path):
    """A 4-legged robot with its own joint names: converted with --legs, then stepped in MJX and MuJoCo C."""
    import jax
    import jax.numpy as jp

    import hexa_mjx
    from hexa_mjx.mdp.config import EnvConfig
    from hexa_mjx.engines.native import NativeEnv

    urdf = make_toy(tmp_path, legs=4, joint_name=QUAD)
    with pytest.raises(convert.ConversionError, match="no leg joints found"):
        convert.convert(urdf)  # the default naming finds nothing
    out = tmp_path / "quad.xml"
    assert convert.main([str(urdf), "-o", str(out), "--legs", QUAD_LEGS]) == 0
    env = hexa_mjx.make_env(model_path=str(out))
    assert (env.action_size, env.observation_size) == (12, 3 + 4 + 3 + 3 + 12 + 12 + 3)
    assert [env.mj_model.geom(g).name for g in env.feet] == [f"l{i}_foot" for i in range(1, 5)]
    assert sorted(set(env.geom_leg[env.geom_leg >= 0])) == [0, 1, 2, 3]
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    native = NativeEnv(EnvConfig(model_path=str(out)))
    np.testing.assert_allclose(native.reset(seed=0), state.obs, atol=1e-5)  # the same settled start
    # The toy is too weak to stand (it rests on its torso): both engines count the same contacts.
    assert tuple(map(int, env.contact_counts(state.pipeline_state))) == tuple(map(int, native.contact_counts()))
    assert int(env.contact_counts(state.pipeline_state)[1]) > 0
    state = jax.jit(env.step)(state, jp.full(12, 0.1))
    assert np.isfinite(float(state.reward)) and np.isfinite(native.step(np.full(12, 0.1))[1])
    obs = NativeEnv(EnvConfig(task="navigate", model_path=str(out))).reset(seed=0)
    assert obs.shape == (2 + 1 + 1 + 3 + 3 + 3 + 12 * 3,)


def test_eight_legs_convert_with_a_mapping(tmp_path):
    urdf = make_toy(tmp_path, legs=8, joint_name=QUAD)
    legs = " ".join(f"l{i}:hip_{i}x,knee_{i}x,ankle_{i}x" for i in range(1, 9))
    model = mujoco.MjModel.from_xml_string(convert.convert(urdf, legs))
    assert model.nu == 24 and sum(model.geom(g).name.endswith("_foot") for g in range(model.ngeom)) == 8


@pytest.mark.parametrize("legs,message", [
    ("l1:hip_1x,knee_1x,ankle_1x l2:hip_2x,knee_9x", r"names joint\(s\) \['knee_9x'\] that are not revolute"),
    ("l1-hip_1x", "is not NAME:JOINT,JOINT"),
    ("l1:hip_1x l1:hip_2x", "names leg 'l1' twice"),
    ("l1:hip_1x l2:hip_1x", "to more than one leg"),
])
def test_leg_mapping_errors(tmp_path, legs, message):
    urdf = make_toy(tmp_path, legs=2, joint_name=QUAD)
    with pytest.raises(convert.ConversionError, match=message):
        convert.convert(urdf, legs)


def test_meshes_in_the_current_directory_are_ignored(toy, tmp_path, monkeypatch):
    """A stray meshes/ folder where the command runs must not change the robot."""
    urdf, expected = toy
    monkeypatch.chdir(tmp_path)
    (tmp_path / "meshes").mkdir()
    for mesh in (urdf.parent / "meshes").iterdir():  # same names, boxes ten times larger
        write_box_stl(tmp_path / "meshes" / mesh.name, (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
    got = mujoco.MjModel.from_xml_string(convert.convert(urdf))
    np.testing.assert_allclose(got.geom_size, expected.geom_size)


def test_cli_output_errors(toy, tmp_path, capsys):
    urdf, _ = toy
    assert convert.main([str(urdf), "-o", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err and not list(tmp_path.glob("*.tmp"))
    assert convert.main([str(urdf), "-o", "/proc/hexa_mjx_test.xml"]) == 2  # unwritable, even for root
    assert "cannot write /proc/hexa_mjx_test.xml" in capsys.readouterr().err
