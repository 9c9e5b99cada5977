"""Domain randomization (per-environment physics models) and pushes."""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.mdp import randomization
from hexa_mjx.engines import wrappers
from hexa_mjx.studies.benchmark import gait_actions
from hexa_mjx.mdp import events
from hexa_mjx.engines.mjx_env import DRAWS

N = 64


@pytest.fixture(scope="module")
def models(env):
    return randomization.randomization_fn(env)(env.mjx_model, jax.random.split(jax.random.PRNGKey(0), N))


def test_every_quantity_is_drawn_in_its_range(env, models):
    batch, in_axes = models
    r, m, robot = randomization.Ranges(), env.mj_model, env.robot
    friction = np.asarray(batch.geom_friction[:, :, 0])
    assert np.all(friction == friction[:, :1]) and r.friction[0] <= friction.min() and friction.max() <= r.friction[1]
    assert friction[:, 0].std() > 0.1  # environments differ
    legs = [b for b in range(m.nbody) if b not in (0, robot.torso) and m.body_mass[b] > 0 and b != m.body("goal").id]
    scale = np.asarray(batch.body_mass[:, legs]) / m.body_mass[legs]
    assert r.mass_scale[0] <= scale.min() and scale.max() <= r.mass_scale[1] and scale.std() > 0.05
    np.testing.assert_allclose(np.asarray(batch.body_inertia[:, legs]) / m.body_inertia[legs],
                               np.repeat(scale[..., None], 3, -1), rtol=1e-5)
    assert np.asarray(batch.body_mass[:, m.body("goal").id] == m.body_mass[m.body("goal").id]).all()  # not the robot
    # payload: the torso's mass beyond its own randomized share lies in [0, 1.5] kg
    total = np.asarray(batch.body_subtreemass[:, robot.torso])
    assert 0.8 * robot.mass <= total.min() and total.max() <= 1.2 * robot.mass + 1.5
    # subtree masses recomputed: each body's subtree = itself + its children's subtrees
    sub, mass = np.asarray(batch.body_subtreemass), np.asarray(batch.body_mass)
    children = sub[:, 1:].copy()
    expected = mass.copy()
    np.add.at(expected.T, m.body_parentid[1:], children.T)
    np.testing.assert_allclose(sub, expected, rtol=1e-5)
    kp = np.asarray(batch.actuator_gainprm[:, :, 0]) / m.actuator_gainprm[:, 0]
    np.testing.assert_allclose(np.asarray(batch.actuator_biasprm[:, :, 1]), -kp * m.actuator_gainprm[:, 0], rtol=1e-5)
    for name, span in (("actuator_forcerange", r.force_scale), ("dof_damping", r.damping_scale),
                       ("dof_armature", r.armature_scale)):
        ratio = np.asarray(getattr(batch, name))[:, 6:] / getattr(m, name)[6:]
        assert span[0] - 1e-6 <= ratio.min() and ratio.max() <= span[1] + 1e-6, name
    assert in_axes.body_mass == 0 and in_axes.geom_pos is None  # only the randomized fields are batched
    # the constraint weights were recomputed for the new masses, not left at the nominal model's
    assert not np.allclose(np.asarray(batch.body_invweight0[0]), m.body_invweight0)


def test_each_environment_steps_its_own_model(env, step, state0):
    """Environment 0 gets the nominal model, environment 1 a randomized one: 0 must step exactly
    as the plain environment does, 1 differently."""
    def nominal_and_randomized(model):
        models, in_axes = randomization.randomization_fn(env)(model, jax.random.split(jax.random.PRNGKey(0), 2))
        return models.tree_replace({name: getattr(models, name).at[0].set(getattr(model, name))
                                    for name in randomization.RANDOMIZED_FIELDS}), in_axes

    wrapped = wrappers.RandomizedVmap(env, nominal_and_randomized)
    action = jp.asarray(gait_actions(1, env.dt)[0], jp.float32)
    stepped = jax.jit(wrapped.step)(jax.tree.map(lambda x: jp.stack([x, x]), state0), jp.stack([action, action]))
    alone = step(state0, action)
    np.testing.assert_allclose(stepped.pipeline_state.qpos[0], alone.pipeline_state.qpos, atol=1e-6)
    assert not np.allclose(stepped.pipeline_state.qpos[1], alone.pipeline_state.qpos, atol=1e-5)


def one_steps(model, states, actions, n_substeps):
    """qpos after one control step from each (qpos, qvel, warm start) state, MuJoCo C."""
    data, out = mujoco.MjData(model), []
    for (qpos, qvel, warm), action in zip(states, actions):
        data.qpos[:], data.qvel[:], data.qacc_warmstart[:] = qpos, qvel, warm
        lo, hi = model.actuator_ctrlrange.T
        data.ctrl[:] = lo + (np.clip(action, -1, 1) + 1) / 2 * (hi - lo)
        for _ in range(n_substeps):
            mujoco.mj_step(model, data)
        out.append(data.qpos.copy())
    return np.array(out)


def test_derived_constants_must_be_recomputed(env):
    """Why randomization calls mj_setConst: with masses x1.2, a control step with the derived
    constants (constraint inverse weights) left as they were lands as far from the recomputed
    one as the mass change itself moves it (measured: 0.25 mm against 0.31 mm)."""
    def heavier(recompute):
        model = mujoco.MjModel.from_xml_path(env.config.model_path)
        model.body_mass[1:] *= 1.2
        model.body_inertia[1:] *= 1.2
        if recompute:
            mujoco.mj_setConst(model, mujoco.MjData(model))
        return model

    stale, fresh, nominal = heavier(False), heavier(True), mujoco.MjModel.from_xml_path(env.config.model_path)
    assert not np.allclose(fresh.dof_invweight0, stale.dof_invweight0)  # the constants did change
    actions = gait_actions(120, env.dt)
    data, states = mujoco.MjData(fresh), []  # states along a walk of the heavier robot
    data.qpos[:], data.qvel[:] = env.qpos0, env.qvel0
    for action in actions:
        states.append((data.qpos.copy(), data.qvel.copy(), data.qacc_warmstart.copy()))
        lo, hi = fresh.actuator_ctrlrange.T
        data.ctrl[:] = lo + (np.clip(action, -1, 1) + 1) / 2 * (hi - lo)
        for _ in range(env.n_substeps):
            mujoco.mj_step(fresh, data)
    a, b, c = (one_steps(m, states, actions, env.n_substeps) for m in (stale, fresh, nominal))
    gap, effect = np.abs(a[:, :3] - b[:, :3]).max(), np.abs(c[:, :3] - b[:, :3]).max()
    assert gap > 0.3 * effect > 0, (gap, effect)  # m


def test_pushes_kick_the_torso_at_the_interval():
    env = hexa_mjx.make_env(push_speed=1.0, push_interval=0.1)  # every 6 control steps
    kick = jax.jit(lambda t, key: events.push_kick(t, env.episode.push_every, env.config.push_speed, DRAWS, key))
    keys = jax.random.split(jax.random.PRNGKey(0), 200)
    assert all(float(jp.linalg.norm(kick(t, keys[0]))) == 0 for t in (0, 1, 5, 7))
    speeds = np.array([float(jp.linalg.norm(kick(jp.int32(6), k))) for k in keys])
    assert speeds.max() <= 1.0 and speeds.min() >= 0 and 0.4 < speeds.mean() < 0.6
    with pytest.raises(ValueError, match="push_speed"):
        hexa_mjx.make_env(push_speed=-1)


def test_native_engine_draws_a_variant_every_episode():
    from hexa_mjx.mdp.config import EnvConfig
    from hexa_mjx.engines.native import NativeEnv

    native = NativeEnv(EnvConfig(), ranges=randomization.Ranges())
    nominal = native.nominal
    seen = []
    for seed in range(3):
        native.reset(seed=seed)
        m = native.mj_model
        seen.append((m.geom_friction[0, 0], m.body_subtreemass[native.robot.torso]))
        assert 0.4 <= m.geom_friction[0, 0] <= 1.25
        assert not np.allclose(m.dof_invweight0, nominal.dof_invweight0)  # recomputed for this variant
        assert np.isfinite(native.step(np.zeros(18))[1])
    assert len({round(f, 6) for f, _ in seen}) == 3 and len({round(s, 6) for _, s in seen}) == 3


def test_a_late_command_leaves_the_previous_one_acting(env, step, state0):
    """With a whole control step of latency the physics runs the previous command, and the env
    still records the new one (the observation's last action)."""
    late = hexa_mjx.make_env(action_latency=1.0)
    lo, hi = env.mj_model.actuator_ctrlrange.T
    previous = 2 * (np.asarray(state0.pipeline_state.ctrl) - lo) / (hi - lo) - 1  # the start's command
    state = state0.replace(info={**state0.info, "latency": jp.float32(1.0)})
    delayed = jax.jit(late.step)(state, jp.full(18, 0.7))
    on_time = step(state0, jp.asarray(previous, jp.float32))
    np.testing.assert_allclose(delayed.pipeline_state.qpos, on_time.pipeline_state.qpos, atol=1e-5)
    np.testing.assert_allclose(delayed.pipeline_state.ctrl, lo + 0.85 * (hi - lo), atol=1e-5)
    draw = jax.vmap(lambda key: events.draw_latency(late.config.action_latency, DRAWS, key))
    latencies = draw(jax.random.split(jax.random.PRNGKey(0), 500))
    assert 0 <= float(latencies.min()) and float(latencies.max()) <= 1 and float(latencies.std()) > 0.2


def test_observation_noise_touches_only_sensor_values():
    from hexa_mjx.mdp.observations import noise_scale
    from hexa_mjx.tasks import TASKS

    noisy = hexa_mjx.make_env(obs_noise=1.0)
    state = jax.jit(noisy.reset)(jax.random.PRNGKey(0))
    diff = np.asarray(state.obs - noisy.observe(state.pipeline_state))
    scale = noise_scale(TASKS["goal"].layout(18))
    assert np.all(np.abs(diff) <= scale + 1e-6) and np.all(diff[scale == 0] == 0)
    assert np.abs(diff[31:49]).max() > 0.3  # joint velocities: +-1.5 rad/s


def test_eval_rollout_runs_each_episode_on_its_own_model():
    """eval.py --randomize: episodes from the same start (the report task's), with the same (zero)
    commands, part ways only because each has its own physics (here only its payload differs)."""
    from hexa_mjx.evaluation import evaluate as evaluation

    env = hexa_mjx.make_env(episode_length=30)
    hold = lambda obs, key: jp.zeros((obs.shape[0], env.action_size))  # noqa: E731
    only_payload = randomization.Ranges(friction=(1.0, 1.0), mass_scale=(1.0, 1.0), kp_scale=(1.0, 1.0),
                                        force_scale=(1.0, 1.0), damping_scale=(1.0, 1.0), armature_scale=(1.0, 1.0))
    start, varied = evaluation.rollout(env, hold, 4, seed=0, ranges=only_payload)
    assert np.ptp(start, axis=0).max() == 0  # the same start state
    assert np.ptp(varied["qpos"][-1, :, 2]) > 1e-4  # payloads of 0 to 1.5 kg: four different torso heights
