"""The MJX environment: shapes, batching, actions, contacts, termination, episode boundaries."""

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from brax.envs.wrappers import training as brax_training
from mujoco import mjx

import hexa_mjx
from hexa_mjx.mdp import rewards
from hexa_mjx.robot import constants as robot
from hexa_mjx.studies.benchmark import c_rollout, gait_actions
from hexa_mjx.engines.contacts import of as floor_contacts
from hexa_mjx.tasks import reward_variants
from hexa_mjx.engines.mjx_env import DRAWS

FLIPPED = jp.array([0.0, 1.0, 0.0, 0.0])  # 180 degrees about x: upside down


def test_sizes_and_dtypes(env, state0):
    assert (env.observation_size, env.action_size) == (52, 18)
    assert state0.obs.shape == (52,) and state0.obs.dtype == jp.float32
    assert state0.reward.shape == () and state0.done.shape == ()
    # The report's order: position, quaternion, lin vel, ang vel, joint pos, joint vel, goal vector, distance.
    qpos = np.asarray(state0.pipeline_state.qpos)
    np.testing.assert_allclose(state0.obs[:7], qpos[:7], atol=1e-6)
    np.testing.assert_allclose(state0.obs[13:31], qpos[7:], atol=1e-6)
    np.testing.assert_allclose(state0.obs[49:51], [1.5 - qpos[0], -qpos[1]], atol=1e-6)
    assert state0.obs[51] == pytest.approx(np.hypot(1.5 - qpos[0], qpos[1]), abs=1e-6)


def test_start_pose_rests_on_feet(env, state0):
    data = state0.pipeline_state
    bad, non_foot = env.contact_counts(data)
    assert int(bad) == 0 and int(non_foot) == 0
    geom1, geom2, dist = floor_contacts(data)
    feet = {env.mj_model.geom(robot.foot_geom(leg)).id for leg in robot.LEGS}
    touching = {int(g) for g, d in zip(np.asarray(geom2), np.asarray(dist)) if d < 0}
    assert touching == feet  # all six feet down, nothing else
    assert float(dist.min()) > -0.005  # resting, not sunk into the floor
    assert abs(float(data.qvel[2])) < 0.05  # settled


def test_jit_vmap_batch(env):
    batch = 3
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(1), batch))
    actions = jax.random.uniform(jax.random.PRNGKey(2), (batch, env.action_size), minval=-1, maxval=1)
    nxt = jax.jit(jax.vmap(env.step))(states, actions)
    assert nxt.obs.shape == (batch, 52) and nxt.reward.shape == (batch,)
    assert np.isfinite(np.asarray(nxt.obs)).all() and np.isfinite(np.asarray(nxt.reward)).all()
    assert not np.allclose(nxt.obs, states.obs)
    assert set(nxt.metrics) >= {"distance", "success", "fell", "nonfinite"} | {
        f"reward/{t}" for t, s in env.scales.items() if s}


@pytest.mark.parametrize("value", [-1.0, 0.0, 1.0, 7.0])
def test_action_maps_to_joint_limits(env, step, state0, value):
    lo, hi = env.mj_model.actuator_ctrlrange.T
    expected = {-1.0: lo, 0.0: (lo + hi) / 2, 1.0: hi, 7.0: hi}[value]  # out of range is clipped
    nxt = step(state0, jp.full(env.action_size, value))
    np.testing.assert_allclose(nxt.pipeline_state.ctrl, expected, atol=1e-6)
    joint_lo, joint_hi = env.mj_model.jnt_range[1:].T
    np.testing.assert_allclose(lo, joint_lo)
    np.testing.assert_allclose(hi, joint_hi)


def test_air_time_counts_while_the_feet_are_off_the_floor(env, step, state0):
    assert float(state0.info["air_time"].sum()) == 0.0  # all six feet down at the start
    data = state0.pipeline_state
    state = state0.replace(pipeline_state=data.replace(qpos=data.qpos.at[2].add(0.3)))  # 30 cm up: ~0.25 s of fall
    for _ in range(5):
        state = step(state, jp.zeros(env.action_size))
    np.testing.assert_allclose(state.info["air_time"], np.full(6, 5 * env.dt), rtol=1e-5)
    np.testing.assert_allclose(state.info["stance_avg"], np.full(6, (1 - env.dt / rewards.DUTY_WINDOW) ** 5), rtol=1e-5)
    assert not bool(env.foot_stance(state.pipeline_state).any())
    last = state.replace(info={**state.info, "t": jp.int32(env.config.episode_length - 1)})
    assert float(step(last, jp.zeros(env.action_size)).info["air_time"].sum()) == 0.0  # a new episode starts down


def test_wrong_action_shape_is_rejected(env, state0):
    with pytest.raises(ValueError, match=r"action must have shape \(18,\)"):
        env.step(state0, jp.zeros(17))


@pytest.fixture(scope="session")
def counts_at(env, state0):
    """Contact counts of the start state with qpos replaced (one compile for all poses)."""
    fn = jax.jit(lambda qpos: env.contact_counts(mjx.forward(env.mjx_model, state0.pipeline_state.replace(qpos=qpos))))
    return lambda qpos: tuple(int(x) for x in fn(jp.asarray(qpos, jp.float32)))


def _c_contacts(env, qpos):
    """Floor contacts MuJoCo C finds for a pose: list of (geom name, foot clearance of its leg or None)."""
    m, d = env.mj_model, mujoco.MjData(env.mj_model)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    out = []
    for c in d.contact[: d.ncon]:
        geom = int(c.geom[1])
        leg, body = None, m.geom_bodyid[geom]
        while leg is None and body > 0:  # the leg whose joint moves this body
            joints = [m.joint(j).name for j in range(m.njnt) if m.jnt_bodyid[j] == body]
            leg = next((j.split("_")[0] for j in joints if j.startswith("leg")), None)
            body = m.body_parentid[body]
        clear = None
        if leg is not None:
            foot = m.geom(robot.foot_geom(leg)).id
            clear = d.geom_xpos[foot, 2] - m.geom_size[foot, 0]
        out.append((m.geom(geom).name, clear))
    return out


def test_body_contact_when_torso_lies_on_floor(env, counts_at):
    qpos = np.array(env.mj_model.key_qpos[0])
    qpos[2], qpos[3:7] = 0.0, FLIPPED  # on its back, legs in the air
    c_names = [name for name, _ in _c_contacts(env, qpos)]
    assert robot.TORSO_GEOM in c_names and not any(n.endswith("_foot") for n in c_names)
    bad, non_foot = counts_at(qpos)
    assert non_foot == len(c_names) > 0
    standing = counts_at(env.mj_model.key_qpos[0])
    assert standing == (0, 0)


def test_contact_quality_when_leg_links_touch_with_feet_lifted(env, counts_at):
    # Kneeling: knees folded so every femur/shin rests on the floor and every foot is in the air.
    qpos = np.array(env.mj_model.key_qpos[0])
    qpos[2] = 0.1
    qpos[8::3], qpos[9::3] = -1.5, -1.0
    c = _c_contacts(env, qpos)
    assert c and all(clear is not None and clear > 0.02 for _, clear in c)  # leg links only, feet up
    bad, non_foot = counts_at(qpos)
    assert bad == non_foot == len(c)


def test_goal_bonus_is_paid_only_on_feet(env, state0):
    # At the goal (distance 0): standing earns the bonus, lying on the back does not.
    state0 = state0.replace(pipeline_state=env.set_goal(state0.pipeline_state, jp.zeros(2)))
    def bonus(qpos):
        data = mjx.forward(env.mjx_model, state0.pipeline_state.replace(qpos=qpos))
        info = env.episode.start_info(DRAWS, jax.random.PRNGKey(0))
        _, terms, _, _ = env.episode.transition(info, data.qpos, data.qpos, data.qvel, env.goal(data), env.heading(data),
                                                env.command(data), env.contacts(data), data.actuator_force,
                                                jp.array(True), DRAWS, jax.random.PRNGKey(1))
        return terms["goal_bonus"]
    bonus = jax.jit(bonus)
    lying = np.array(env.mj_model.key_qpos[0])
    lying[2], lying[3:7] = 0.0, FLIPPED
    assert float(bonus(jp.asarray(env.mj_model.key_qpos[0], jp.float32))) == 1.0
    assert float(bonus(jp.asarray(lying, jp.float32))) == 0.0


def test_mjx_matches_mujoco_c(env, step, state0):
    actions = gait_actions(15, env.dt)
    expected = c_rollout(env, env.mj_model, actions)
    state, got = state0, []
    for a in actions:
        state = step(state, jp.asarray(a, jp.float32))
        got.append(np.asarray(state.pipeline_state.qpos))
    got = np.array(got)
    assert np.abs(expected[-1, :3] - expected[0, :3]).max() > 0.005  # the gait really moves the torso
    np.testing.assert_allclose(got[:, :3], expected[:, :3], atol=0.01)  # m
    np.testing.assert_allclose(got[:, 7:], expected[:, 7:], atol=0.1)  # rad


CAP = 16  # contact points kept by the capped model below (the model has 40 slots)


@pytest.fixture(scope="module")
def capped():
    return hexa_mjx.make_env(max_contact_points=CAP)


def test_contact_cap_keeps_the_deepest_contacts(env, capped):
    # Torso lowered to 7 cm: the feet and 12 leg-link points press into the floor, more than CAP.
    qpos = np.array(env.mj_model.key_qpos[0])
    qpos[2] = 0.07
    def contacts(e):
        data = jax.jit(e.data_at)(jp.asarray(qpos, jp.float32))
        return np.sort(np.asarray(floor_contacts(data)[2])), [int(x) for x in e.contact_counts(data)]
    all_dist, all_counts = contacts(env)
    cap_dist, cap_counts = contacts(capped)
    assert (all_dist < 0).sum() > CAP and len(cap_dist) == capped.contact_slots == CAP and env.contact_slots == 40
    np.testing.assert_allclose(cap_dist, all_dist[:CAP], atol=1e-6)  # the CAP deepest, the rest dropped
    assert cap_counts[1] == all_counts[1] - ((all_dist < 0).sum() - CAP)  # the shallow ones are non-foot


def test_contact_cap_leaves_walking_physics_unchanged(env, step, state0, capped):
    # A gait touches the floor with a few feet at a time, far below CAP: the capped solve must match
    # the full one up to float rounding, and so must the contact reward terms.
    cap_step, cap_state = jax.jit(capped.step), jax.jit(capped.reset)(jax.random.PRNGKey(0))
    state, touching = state0, []
    for a in gait_actions(15, env.dt):
        a = jp.asarray(a, jp.float32)
        state, cap_state = step(state, a), cap_step(cap_state, a)
        np.testing.assert_allclose(cap_state.pipeline_state.qpos, state.pipeline_state.qpos, atol=1e-4)
        for term in ("reward/body_contact", "reward/contact_quality", "goal_bonus"):
            assert float(cap_state.metrics[term]) == float(state.metrics[term])
        touching.append(int(env.floor_contact_geoms(state.pipeline_state)[0].sum()))
        assert int(capped.floor_contact_geoms(cap_state.pipeline_state)[0].sum()) == touching[-1]
    assert 0 < max(touching) < CAP


def test_flipped_robot_terminates(env, step, state0):
    ps = state0.pipeline_state
    flipped = state0.replace(pipeline_state=ps.replace(qpos=ps.qpos.at[2].set(0.3).at[3:7].set(FLIPPED)))
    nxt = step(flipped, jp.zeros(env.action_size))
    assert float(nxt.done) == 1.0 and float(nxt.metrics["fell"]) == 1.0
    assert float(nxt.metrics["reward/termination"]) == -200.0
    upright = step(state0, jp.zeros(env.action_size))
    assert float(upright.done) == 0.0 and float(upright.metrics["reward/termination"]) == 0.0


def test_nan_state_terminates_with_finite_outputs(env, step, state0):
    ps = state0.pipeline_state
    broken = state0.replace(pipeline_state=ps.replace(qvel=ps.qvel.at[4].set(jp.nan)))
    nxt = step(broken, jp.zeros(env.action_size))
    assert float(nxt.done) == 1.0 and float(nxt.metrics["nonfinite"]) == 1.0
    assert np.isfinite(np.asarray(nxt.obs)).all() and np.isfinite(float(nxt.reward))
    assert all(np.isfinite(np.asarray(v)).all() for v in nxt.metrics.values())


def test_episode_boundary_under_brax_autoreset(env):
    """brax's AutoResetWrapper keeps `info`: the env must not leak episode state across it."""
    wrapped = brax_training.wrap(env, episode_length=env.config.episode_length)
    reset, step = jax.jit(wrapped.reset), jax.jit(wrapped.step)
    state = reset(jax.random.split(jax.random.PRNGKey(0), 2))
    last = env.config.episode_length - 2
    ps = state.pipeline_state
    near_goal = ps.replace(qpos=ps.qpos.at[:, 0].set(1.2))  # 0.3 m from the goal
    state = state.replace(pipeline_state=near_goal, info={**state.info, "steps": state.info["steps"] + last,
                                                          "t": state.info["t"] + last})
    zeros = jp.zeros((2, env.action_size))
    state = step(state, zeros)  # second-to-last step: inside the goal radius
    assert np.all(np.asarray(state.metrics["success"]) == 1.0) and np.all(np.asarray(state.done) == 0)
    state = step(state, zeros)  # last step: truncated and reset
    assert np.all(np.asarray(state.done) == 1) and np.all(np.asarray(state.info["truncation"]) == 1)
    np.testing.assert_allclose(state.pipeline_state.qpos[:, 0], env.qpos0[0], atol=1e-6)
    assert np.all(np.asarray(state.info["t"]) == 0) and np.all(np.asarray(state.info["success"]) == 0)
    state = step(state, zeros)  # first step of the new episode
    # A stale previous distance would give 1000 * (0.3 - 1.5) = -1200 here.
    assert np.all(np.abs(np.asarray(state.metrics["reward/goal_approach"])) < 20)
    assert np.all(np.asarray(state.metrics["success"]) == 0)


def test_start_noise_is_drawn_per_reset(env, state0):
    noisy = hexa_mjx.make_env(start_joint_noise=0.1, start_yaw_noise=0.3)
    states = jax.jit(jax.vmap(noisy.reset))(jax.random.split(jax.random.PRNGKey(1), 64))
    qpos = np.asarray(states.pipeline_state.qpos)
    offsets = qpos[:, 7:] - env.qpos0[7:]
    assert np.abs(offsets).max() <= 0.1 + 1e-6 and np.abs(offsets).max() > 0.09  # fills the range
    assert len(np.unique(offsets[:, 0])) == 64  # a different start for every key
    low, high = env.mj_model.jnt_range[1:].T
    assert np.all(qpos[:, 7:] >= low - 1e-6) and np.all(qpos[:, 7:] <= high + 1e-6)
    w, z = qpos[:, 3], qpos[:, 6]  # the settled start is level, so the noise is a pure yaw
    yaw = 2 * np.arctan2(z, w) - 2 * np.arctan2(env.qpos0[6], env.qpos0[3])
    assert np.abs(yaw).max() <= 0.3 + 1e-4 and np.abs(yaw).max() > 0.25
    np.testing.assert_allclose(np.linalg.norm(qpos[:, 3:7], axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(states.obs, jax.vmap(noisy.observe)(states.pipeline_state), rtol=1e-6, atol=1e-9)
    # Without noise, every key gives the settled start exactly.
    other = jax.jit(env.reset)(jax.random.PRNGKey(7))
    np.testing.assert_array_equal(other.pipeline_state.qpos, state0.pipeline_state.qpos)
    np.testing.assert_array_equal(state0.pipeline_state.qpos, np.float32(env.qpos0))


def test_every_variant_and_ablation_builds():
    variants = [(task, reward) for task, cls in hexa_mjx.TASKS.items() for reward in cls.rewards]
    assert sorted(r for _, r in variants) == sorted(reward_variants())  # every variant belongs to a task
    for task, reward in variants:
        for ablation in [None, *rewards.ABLATIONS]:
            env = hexa_mjx.make_env(reward, task, ablate=() if ablation is None else ablation)
            active = {t for t, s in env.scales.items() if s}
            dropped = set(rewards.ABLATIONS.get(ablation, ()))
            assert not active & dropped
            if reward == "forward_motion":
                assert not active & {"goal_approach", "velocity_alignment", "goal_bonus"}


def test_forward_motion_logs_its_own_terms():
    env = hexa_mjx.make_env("forward_motion", ablate=["velocity"])
    state = jax.jit(env.step)(jax.jit(env.reset)(jax.random.PRNGKey(0)), jp.zeros(env.action_size))
    assert "reward/forward_progress" in state.metrics
    assert not {"reward/goal_approach", "reward/goal_bonus", "reward/forward_velocity"} & set(state.metrics)
    total = sum(float(v) for k, v in state.metrics.items() if k.startswith("reward/"))
    assert float(state.reward) == pytest.approx(total, rel=1e-5, abs=1e-6)


def test_bad_settings_give_clear_errors():
    with pytest.raises(ValueError, match="unknown reward 'fast'; the goal task's are"):
        hexa_mjx.make_env("fast")
    with pytest.raises(TypeError, match=r"unknown environment setting\(s\) \['ctrl_rate'\]"):
        hexa_mjx.make_env(ctrl_rate=50)
    with pytest.raises(ValueError, match="ctrl_hz=50 is not the 240 Hz physics rate divided by a whole number"):
        hexa_mjx.make_env(ctrl_hz=50)
    with pytest.raises(ValueError, match="start_yaw_noise is a range in radians from 0 to pi, got -0.1"):
        hexa_mjx.make_env(start_yaw_noise=-0.1)
    with pytest.raises(ValueError, match="max_contact_points must be 0 .every contact slot. or positive, got -2"):
        hexa_mjx.make_env(max_contact_points=-2)
    with pytest.raises(ValueError, match="unknown ablation"):
        hexa_mjx.make_env(ablate="legs")
    assert hexa_mjx.make_env(ctrl_hz=30).n_substeps == 8


def test_contact_cap_replaces_the_files_own(tmp_path):
    from hexa_mjx.robot.model import load_model as _load_model

    path = tmp_path / "capped.xml"  # the model references no mesh files, so a copy loads anywhere
    path.write_text(robot.MODEL_XML.read_text().replace(
        "</mujoco>", '<custom><numeric name="max_contact_points" data="7"/></custom></mujoco>'))
    assert _load_model(path, 0).nnumeric == 0  # 0 means every slot, whatever the file says
    capped = _load_model(path, 12)
    assert capped.nnumeric == 1 and capped.numeric("max_contact_points").data.tolist() == [12.0]


def test_a_failed_leg_gives_no_torque_and_the_policy_is_not_told(env):
    from hexa_mjx.engines.native import NativeEnv

    limp = hexa_mjx.make_env(disabled_legs=(3,))
    state = jax.jit(limp.reset)(jax.random.PRNGKey(0))
    np.testing.assert_array_equal(state.info["failed_legs"], [0, 0, 1, 0, 0, 0])
    step = jax.jit(limp.step)
    action = jp.full(18, 0.8)
    for _ in range(20):
        state = step(state, action)
    force = np.asarray(state.pipeline_state.actuator_force).reshape(6, 3)
    assert np.abs(force[2]).max() < 1e-5 and np.abs(force[[0, 1, 3, 4, 5]]).max() > 0.1  # N*m
    # ctrl holds the policy's command, failed leg included (the navigation observation reads it)
    lo, hi = env.mj_model.actuator_ctrlrange.T
    np.testing.assert_allclose(state.pipeline_state.ctrl, lo + 0.9 * (hi - lo), atol=1e-5)
    # The native engine fails the same servos; "locked" holds them at the start pose's angles.
    native = NativeEnv(limp.config)
    native.reset(seed=0)
    for _ in range(20):
        native.step(np.asarray(action))
    assert np.abs(native.data.actuator_force[6:9]).max() < 1e-9
    locked = NativeEnv(dataclasses.replace(limp.config, failure_mode="locked"))
    locked.reset(seed=0)
    for _ in range(20):
        locked.step(np.asarray(action))
    # Its servos pull toward the start angles (within their 5 N*m), not toward the command.
    q, hold = locked.data.qpos[7 + 6:7 + 9], locked.robot.hold_ctrl[6:9]
    # (the force is from the last physics step's start, q from its end: 0.05 N*m of slack)
    np.testing.assert_allclose(locked.data.actuator_force[6:9], np.clip(robot.KP * (hold - q), -5, 5), atol=0.05)


def test_random_leg_failure_is_drawn_per_episode():
    env = hexa_mjx.make_env(leg_failure="random", leg_failure_rate=0.5)
    failed = np.asarray(jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 2000)).info["failed_legs"])
    assert set(failed.sum(1).tolist()) == {0.0, 1.0}  # one leg or none
    assert abs(failed.sum(1).mean() - 0.5) < 0.05 and failed.sum(0).min() > 100  # every leg fails sometimes


def test_two_non_adjacent_legs_and_mixed_failures_in_both_engines():
    from hexa_mjx.engines.native import NativeEnv
    env = hexa_mjx.make_env(leg_failure="random", leg_failure_rate=1.0, leg_failure_pairs=0.5, failure_mode="mixed")
    # The hips sit on a hexagon around the torso: adjacent legs are its 6 sides, the shortest hip
    # to hip distances; the 9 non-adjacent pairs are its diagonals, every one longer.
    data = mujoco.MjData(env.mj_model)
    data.qpos[:] = env.robot.qpos0
    mujoco.mj_forward(env.mj_model, data)
    hips = data.xanchor[env.robot.hips, :2]
    diagonals = {tuple(p) for p in env.robot.non_adjacent_pairs}
    sides = {(i, j) for i in range(6) for j in range(i + 1, 6)} - diagonals
    assert len(diagonals) == 9 and len(sides) == 6
    length = lambda pair: np.linalg.norm(hips[pair[0]] - hips[pair[1]])  # noqa: E731
    assert max(map(length, sides)) < min(map(length, diagonals))
    info = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 2000)).info
    failed, locked = np.asarray(info["failed_legs"]), np.asarray(info["failure_locked"])
    counts = failed.sum(1)
    assert set(counts.tolist()) == {1.0, 2.0} and abs((counts == 2).mean() - 0.5) < 0.05
    pairs = {tuple(np.flatnonzero(row)) for row in failed[counts == 2]}
    assert pairs == diagonals  # every non-adjacent pair, no other
    assert set(locked.tolist()) == {0.0, 1.0} and abs(locked.mean() - 0.5) < 0.05
    first_locked = jax.tree.map(lambda x: x[int(np.flatnonzero(locked == 1)[0])], info)
    np.testing.assert_array_equal(np.unique(env.episode.failed_servos(first_locked)), [0, 2])  # 2: locked
    native = NativeEnv(env.config)
    seen = set()
    for seed in range(60):
        native.reset(seed=seed)
        legs = tuple(np.flatnonzero(native.info["failed_legs"]))
        assert len(legs) == 1 or legs in pairs
        seen.add((len(legs), float(native.info["failure_locked"])))
    assert seen == {(1, 0.0), (1, 1.0), (2, 0.0), (2, 1.0)}
    # Mixed: a failed servo is limp (follows its joint) or locked (holds the start pose) by episode.
    from hexa_mjx.robot.model import failed_ctrl
    target, joints, hold = np.full(3, 0.5), np.full(3, 0.1), np.full(3, -0.2)
    np.testing.assert_array_equal(failed_ctrl(target, joints, np.array([0, 1, 2]), "mixed", hold), [0.5, 0.1, -0.2])


def test_leg_failure_weights_pick_the_failed_leg_in_both_engines():
    from hexa_mjx.engines.native import NativeEnv
    weights = (0, 0, 3, 1, 0, 0)  # legs 3 and 4 only, 3 three times as often
    env = hexa_mjx.make_env(leg_failure="random", leg_failure_rate=1.0, leg_failure_weights=weights)
    mjx_counts = np.asarray(jax.jit(jax.vmap(env.draw_failure))(jax.random.split(jax.random.PRNGKey(0), 2000))).sum(0)
    native = NativeEnv(env.config)
    native_counts = np.zeros(6)
    for seed in range(400):
        native.reset(seed=seed)
        native_counts += native.info["failed_legs"]
    for counts in (mjx_counts, native_counts):
        assert counts[[0, 1, 4, 5]].sum() == 0 and counts.sum() > 0
        assert 2.4 < counts[2] / counts[3] < 3.8, counts


@pytest.mark.parametrize("settings,message", [
    (dict(leg_failure="random", leg_failure_weights=(1, 1)), "one weight per leg"),
    (dict(leg_failure="random", leg_failure_weights=(0,) * 6), "not all 0"),
    (dict(leg_failure="random", leg_failure_weights=(1, 1, -1, 1, 1, 1)), "each 0 or more"),
    (dict(disabled_legs=(7,)), "leg 7 does not exist"),
    (dict(disabled_legs=(1, 2, 3, 4, 5, 6)), "disables all 6 legs"),
    (dict(disabled_legs=(0,)), "leg numbers from 1"),
    (dict(disabled_legs=(2, 2)), "names a leg twice"),
    (dict(leg_failure="sometimes"), "leg_failure is 'none' or 'random'"),
    (dict(failure_mode="broken"), "failure_mode is 'limp', 'locked' or 'mixed'"),
    (dict(leg_failure="random", leg_failure_pairs=1.5), "leg_failure_pairs is a share"),
    (dict(leg_failure="random", leg_failure_rate=1.5), "leg_failure_rate is a probability"),
])
def test_leg_failure_settings_are_checked(settings, message):
    with pytest.raises(ValueError, match=message):
        hexa_mjx.make_env(**settings)


def test_energy_reward_pays_for_servo_power():
    env = hexa_mjx.make_env(reward="energy")
    state = jax.jit(env.step)(jax.jit(env.reset)(jax.random.PRNGKey(0)), jp.full(18, 0.5))
    data = state.pipeline_state
    power = np.abs(np.asarray(data.actuator_force) * np.asarray(data.qvel)[6:]).sum()  # W, 18 hinges after the free joint
    assert power > 1.0
    assert float(state.metrics["reward/mechanical_power"]) == pytest.approx(-0.01 * power, rel=1e-5)
    # none of the report's gait shaping
    assert not {"reward/stability", "reward/height", "reward/contact_quality", "reward/body_contact"} & set(state.metrics)
