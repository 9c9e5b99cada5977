"""Rough terrain: generated heightfields, the ground height the contact and height terms read,
and the terrain in both engines. MuJoCo's own ray casts are the reference for the ground height."""

import mujoco
import numpy as np
import pytest

from hexa_mjx.mdp import terrain
from hexa_mjx.mdp.config import make_config
from hexa_mjx.robot.model import RobotModel


@pytest.fixture(scope="module", params=["bumps", "slopes", "steps", "mixed"])
def robot_on(request):
    return RobotModel(make_config(terrain=request.param, terrain_seed=3))


def ray_height(model, data, xy):
    """Height of the first surface below (x, y, 1 m), by MuJoCo's ray cast (robot geoms excluded)."""
    hit = np.zeros(1, np.int32)
    dist = mujoco.mj_ray(model, data, np.array([xy[0], xy[1], 1.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, hit)
    assert hit[0] == model.geom("floor").id
    return 1.0 - dist


def test_ground_height_matches_mujocos_heightfield(robot_on):
    model = robot_on.mj_model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    points = np.random.default_rng(1).uniform(-9, 9, size=(200, 2))
    points = points[np.hypot(*points.T) > 1.0]  # away from the robot standing at the origin
    ours = terrain.ground_height(robot_on.terrain, points)
    theirs = np.array([ray_height(model, data, p) for p in points])
    # MuJoCo triangulates each 0.1 m cell where we interpolate bilinearly: they differ only where a
    # cell is curved or holds a step's edge, by at most a quarter of the cell's twist
    # |h00 + h11 - h01 - h10| (at its centre), so by half the largest jump between neighbours.
    h = robot_on.terrain.heights
    jump = max(np.abs(np.diff(h, axis=0)).max(), np.abs(np.diff(h, axis=1)).max())
    assert np.median(np.abs(ours - theirs)) < 1e-3 and np.abs(ours - theirs).max() <= jump / 2 + 1e-4
    assert ours.max() > 0.02  # the terrain is not flat


def test_terrain_sizes_follow_the_kind_and_difficulty():
    x, y = np.meshgrid(*(np.linspace(-9, 9, 91),) * 2)
    bumps = terrain.generate("bumps", seed=0)
    assert bumps.max_height == pytest.approx(terrain.BUMP_HEIGHT, rel=1e-5)
    assert terrain.generate("bumps", seed=0, difficulty=0.5).max_height == pytest.approx(terrain.BUMP_HEIGHT / 2, rel=1e-5)
    slopes = terrain.generate("slopes")
    gy, gx = np.gradient(slopes.heights, terrain.CELL)
    # Off the ridges, valleys and the flat spawn disc, the slope is SLOPE_DEG.
    angle = np.degrees(np.arctan(np.hypot(gx, gy)))
    assert np.median(angle[angle > 1]) == pytest.approx(terrain.SLOPE_DEG, abs=0.2)
    assert angle.max() < terrain.SLOPE_DEG + 0.1 and slopes.heights[::20, ::20].max() == pytest.approx(0.0)  # edges at 0
    steps = terrain.generate("steps", seed=2).heights
    grid = np.linspace(-terrain.HALF_SIZE, terrain.HALF_SIZE, steps.shape[0])
    beyond_ramp = np.hypot(*np.meshgrid(grid, grid)) > 1.0  # 2 steps = 6 cm, 0.34 m of ramp past the disc
    assert set(np.round(np.unique(steps[beyond_ramp]) / terrain.STEP_HEIGHT, 6)) == {0.0, 1.0, 2.0}
    assert not np.array_equal(terrain.generate("bumps", seed=1).heights, bumps.heights)  # the seed matters
    steep = terrain.generate("steep").heights
    gy, gx = np.gradient(steep, terrain.CELL)
    angle = np.degrees(np.arctan(np.hypot(gx, gy)))
    assert np.median(angle[angle > 1]) == pytest.approx(terrain.STEEP_DEG, abs=0.3)
    stairs = terrain.generate("stairs").heights
    far = np.hypot(*np.meshgrid(grid, grid)) > 2.0  # past the spawn disc's ramp
    risers = np.round(np.unique(stairs[far]) / terrain.STAIR_RISER, 6)
    # Whole risers from the squares' edges (0) to their centres: up one flight and down the next.
    assert set(risers) == set(range(int(terrain.SLOPE_PERIOD / 2 / terrain.STAIR_TREAD) + 1))
    hard = terrain.generate("hard", seed=4).heights
    assert np.isin(np.round(hard[far].max(), 6), np.round([steep.max(), stairs.max()], 6)).any()
    for kind in terrain.KINDS:  # the start stays flat, so the settled pose is the same everywhere,
        t = terrain.generate(kind, seed=5)  # and the terrain rises from it by no more than SLOPE_DEG
        assert terrain.ground_height(t, np.array([[0.0, 0.0], [0.3, -0.3]])) == pytest.approx(0.0)
        off_disc = np.hypot(*np.meshgrid(grid, grid)) - terrain.SPAWN_RADIUS
        assert np.all(t.heights <= np.tan(np.radians(terrain.SLOPE_DEG)) * np.maximum(off_disc, 0) + 1e-6)
    with pytest.raises(ValueError, match="unknown terrain 'lava'"):
        terrain.generate("lava")


def test_settled_start_is_the_flat_floors(robot_on):
    """The spawn disc is flat; the heightfield's contacts settle the pose within 1 mm and 0.005 rad
    of the plane's (its collision routine is not the plane's, so not to the last digit)."""
    flat = RobotModel(make_config())
    np.testing.assert_allclose(robot_on.qpos0[:3], flat.qpos0[:3], atol=1e-3)
    np.testing.assert_allclose(robot_on.qpos0[7:], flat.qpos0[7:], atol=5e-3)


def test_lifted_foot_is_measured_from_the_ground_under_it(robot_on):
    """A leg contact counts as dragging only when its foot is more than 2 cm above the ground under
    it: on a bump, a foot 3 cm above z = 0 can be on the ground."""
    r = robot_on
    geom_leg1_shin = next(g for g in range(r.mj_model.ngeom) if r.geom_leg[g] == 0 and g not in r.feet)
    feet = np.zeros((len(r.feet), 3))
    feet[:, :2] = np.random.default_rng(0).uniform(-8, 8, size=(len(r.feet), 2))
    ground = terrain.ground_height(r.terrain, feet[:, :2])
    geom1, geom2, dist = np.array([r.floor]), np.array([geom_leg1_shin]), np.array([-0.001])
    feet[:, 2] = ground + r.foot_radius + 0.01  # 1 cm above the ground under each foot
    assert r.contact_counts(geom1, geom2, dist, feet, 0.02)[0] == 0
    feet[:, 2] = ground + r.foot_radius + 0.03
    assert r.contact_counts(geom1, geom2, dist, feet, 0.02)[0] == 1


def test_height_term_reads_the_ground_under_the_torso():
    from hexa_mjx.mdp import rewards

    config = make_config(terrain="slopes")
    qpos = np.zeros(25)
    qpos[2], qpos[3] = config.target_height + 0.1, 1.0  # 10 cm above z = 0, upright
    args = (config, qpos, qpos, np.zeros(24), np.zeros(2), 0, 0, False, False, 0.0)
    assert rewards.terms(["height"], *args, ground=0.1)["height"] == pytest.approx(0.0)
    assert rewards.terms(["height"], *args)["height"] > 0  # on the flat floor the torso is 10 cm too high


def test_curriculum_terrain_grades_its_columns_and_keeps_every_spawn_flat():
    levels = 3
    graded = terrain.generate("bumps", seed=0, levels=levels)
    x = np.linspace(-terrain.HALF_SIZE, terrain.HALF_SIZE, graded.heights.shape[1])
    column = np.clip(np.floor((x + terrain.HALF_SIZE) / terrain.LEVEL_TILE), 0, levels - 1)
    tallest = [graded.heights[:, column == c].max() for c in range(levels)]
    np.testing.assert_allclose(tallest, [terrain.BUMP_HEIGHT * (c + 1) / levels for c in range(levels)], rtol=0.05)
    centres = terrain.spawn_points()
    spawns = np.array([(cx + dx, cy) for cx in centres for cy in centres for dx in (-0.3, 0.0, 0.3)])
    assert np.abs(terrain.ground_height(graded, spawns)).max() < 1e-6


def test_curriculum_level_picks_the_start_column():
    import jax
    from mujoco import mjx

    import hexa_mjx

    env = hexa_mjx.make_env(task="navigate", terrain="slopes", curriculum_levels=3)
    restart = jax.jit(env.restart)
    data = mjx.make_data(env.mjx_model, impl="jax")  # a template for restart
    centres = terrain.spawn_points()
    for level in range(3):
        starts = np.array([np.asarray(restart(data, jax.random.PRNGKey(k), level).qpos[:2]) for k in range(6)])
        np.testing.assert_allclose(starts[:, 0], centres[level] + env.qpos0[0], atol=1e-5)
        assert set(np.round(starts[:, 1] - env.qpos0[1], 4)) <= set(np.round(centres, 4))
    flat = hexa_mjx.make_env(task="navigate", curriculum_levels=3)  # no terrain: every level starts at the origin
    np.testing.assert_allclose(np.asarray(jax.jit(flat.restart)(data, jax.random.PRNGKey(0), 2).qpos[:2]),
                               flat.qpos0[:2], atol=1e-6)
    with pytest.raises(ValueError, match="at most 5 levels"):
        hexa_mjx.make_env(task="navigate", terrain="bumps", curriculum_levels=6)


def test_heightfield_collides_with_feet_and_torso_spheres_only(robot_on):
    model, flat = robot_on.mj_model, RobotModel(make_config()).mj_model
    floor = model.geom("floor").id
    names = [model.geom(g).name for g in range(model.ngeom)]
    colliding = {n for g, n in enumerate(names)
                 if g != floor and (model.geom_contype[g] & model.geom_conaffinity[floor])}
    feet = {n for n in names if n.endswith("_foot")}
    assert len(feet) == 6 and colliding - feet == {f"torso_terrain_{i}" for i in range(4)}
    # The spheres add no mass: the robot weighs and swings as on the flat floor.
    np.testing.assert_allclose(model.body_subtreemass, flat.body_subtreemass)
    np.testing.assert_allclose(model.body_inertia, flat.body_inertia)
    # Upside down on the flat spawn disc, the torso 1 cm into the ground: its spheres touch it
    # (a body contact) and no foot does (the legs point up).
    data = mujoco.MjData(model)
    data.qpos[:] = robot_on.qpos0
    data.qpos[2] = -0.01
    data.qpos[3:7] = [0.0, 1.0, 0.0, 0.0]  # rolled by 180 degrees about x
    mujoco.mj_forward(model, data)
    touching = {names[g] for c in data.contact[: data.ncon] for g in (c.geom1, c.geom2) if g != floor and c.dist < 0}
    assert touching and all(n.startswith("torso_terrain_") for n in touching)


def test_native_heightfield_gives_a_sphere_near_a_cell_edge_a_side_contact():
    """The mechanism behind native MuJoCo's falls on a flat heightfield (docs/RESULTS.md): a foot
    sphere 5 mm deep and 8 mm from a cell's edge also touches the neighbouring prism's side."""
    import mujoco

    from hexa_mjx.evaluation.contact_check import main, native_tilts

    radius, depth = 0.012, 0.005  # m: the robot's foot sphere, a typical penetration
    m = mujoco.MjModel.from_xml_string(f"""<mujoco><asset><hfield name="h" nrow="3" ncol="3" size="0.1 0.1 0.05 0.1"/>
        </asset><worldbody><geom type="hfield" hfield="h"/>
        <body><freejoint/><geom type="sphere" size="{radius}"/></body></worldbody></mujoco>""")

    def tilts(x, y):
        return native_tilts(m, np.array([[x, y, radius - depth, 1, 0, 0, 0]]))

    assert list(tilts(-0.05, -0.085)) == [0.0]  # 15 mm or more from every edge and diagonal: one upright contact
    seam = tilts(-0.008, -0.05)  # the cells' edge is at x = 0
    assert len(seam) == 2 and min(seam) == 0.0 and max(seam) > 45
    assert main(["no-such-policy.onnx"]) == 2 and main(["policies/navigate.onnx", "--terrain", "lava"]) == 2


def test_terrain_contacts_as_mjx_makes_them():
    """hexa_mjx.engines.terrain_contacts: MuJoCo C's step with MJX's rules for heightfield contacts.
    The step is mj_step's own pipeline: with nothing changed it matches mj_step bit for bit; a
    side wall's horizontal normal is turned up to the face's, and shallow side contacts go."""
    from hexa_mjx.engines import terrain_contacts
    from hexa_mjx.engines.native import NativeEnv
    from hexa_mjx.robot.model import action_to_ctrl
    from hexa_mjx.studies.benchmark import gait_actions

    robot = RobotModel(make_config(terrain="bumps", terrain_seed=3))
    model = robot.mj_model
    plain, ours = mujoco.MjData(model), mujoco.MjData(model)
    plain.qpos[:] = robot.qpos0
    mujoco.mj_forward(model, plain)
    same = changed = 0
    for action in gait_actions(20, 1 / 60):
        plain.ctrl[:] = action_to_ctrl(np.asarray(action), robot.ctrl_lo, robot.ctrl_hi)
        for _ in range(robot.n_substeps):  # from each state one step of each; on with mj_step's
            mujoco.mj_copyData(ours, model, plain)
            count = terrain_contacts.step(model, ours, robot.floor)
            mujoco.mj_step(model, plain)
            if count == 0:
                assert np.array_equal(plain.qpos, ours.qpos) and np.array_equal(plain.qvel, ours.qvel)
            same, changed = same + (count == 0), changed + (count > 0)
    assert same > 10 and changed > 10  # both kinds of step occur on bumps
    assert np.abs(plain.qpos[:2] - robot.qpos0[:2]).max() > 0.005  # the gait moved the robot over the field

    # Two cells along x: flat, then rising 5 cm over 10 cm (normal (-0.447, 0, 0.894)).
    radius = 0.012  # m, the robot's foot sphere
    m = mujoco.MjModel.from_xml_string(f"""<mujoco><asset><hfield name="h" nrow="2" ncol="3" size="0.1 0.05 0.05 0.1"
        elevation="0 0 1 0 0 1"/></asset><worldbody><geom type="hfield" hfield="h"/>
        <body><freejoint/><geom type="sphere" size="{radius}"/></body></worldbody></mujoco>""")
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(terrain_contacts.face_normal(m, d, 0, np.array([0.05, 0.0, 0.0])),
                               np.array([-0.5, 0.0, 1.0]) / np.sqrt(1.25))
    np.testing.assert_allclose(terrain_contacts.face_normal(m, d, 0, np.array([-0.05, 0.0, 0.0])), [0.0, 0.0, 1.0])
    # Sunk 12 mm, 11 mm short of the rising cell: MuJoCo C pushes it back through that cell's side wall.
    d.qpos[:] = [-0.011, 0.0, 0.0, 1, 0, 0, 0]
    mujoco.mj_forward(m, d)
    assert d.ncon == 2 and d.contact.frame[1, :3].round(6).tolist() == [-1.0, 0.0, 0.0]
    assert terrain_contacts.step(m, d, 0) == 2  # turned up, then dropped: 11 mm shallower than the deepest
    kept = d.contact.exclude[:d.ncon] == 0
    assert kept.tolist() == [True, False] and (d.contact.frame[:d.ncon, 2] > 0.5).all()

    # A foot sphere 5 mm deep on flat cells: 8 mm from an edge its side contact (1.4 mm deep) goes,
    # 3 mm from it (4.4 mm deep, within 1 mm of the 5 mm top contact) it stays, as in MJX.
    depth = 0.005
    m = mujoco.MjModel.from_xml_string(f"""<mujoco><asset><hfield name="h" nrow="3" ncol="3" size="0.1 0.1 0.05 0.1"/>
        </asset><worldbody><geom type="hfield" hfield="h"/>
        <body><freejoint/><geom type="sphere" size="{radius}"/></body></worldbody></mujoco>""")
    d = mujoco.MjData(m)
    for x, dropped in ((-0.008, [False, True]), (-0.003, [False, False])):
        d.qpos[:] = [x, -0.05, radius - depth, 1, 0, 0, 0]
        mujoco.mj_forward(m, d)
        c, n = d.contact, d.ncon
        assert terrain_contacts.shallow(c.geom1[:n], c.geom2[:n], c.dist[:n], 0, m.ngeom).tolist() == dropped
    flat = RobotModel(make_config())  # a plane floor: mj_step itself
    assert terrain_contacts.step(flat.mj_model, mujoco.MjData(flat.mj_model), flat.floor) == 0
    with pytest.raises(ValueError, match="terrain_contacts is one of"):
        NativeEnv(make_config(), terrain_contacts="some")
