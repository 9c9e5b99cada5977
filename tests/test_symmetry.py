"""The robot's rotational symmetry (hexa_mjx.training.symmetry): the relabelling maps agree with the
physics of a turned robot, the mirror loss is zero only for a policy that respects them, and a run
with it trains."""

import types

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest

from conftest import TINY, run
from hexa_mjx.robot.kinematics import quat_mul
from hexa_mjx.studies.symmetry_gap import symmetry_gap
from hexa_mjx.training import config, networks, symmetry
from hexa_mjx.training.checks import validate
from hexa_mjx.training.config import ConfigError


def quat_z(angle):
    return np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


@pytest.fixture(scope="module")
def velocity_env():
    return config.make_env_for(config.TrainConfig(task="velocity"))


@pytest.fixture(scope="module")
def small_policy(velocity_env):
    """(networks, normalizer, policy params) of a small velocity policy with a full-scale mean layer."""
    cfg = config.TrainConfig(task="velocity", hidden=[16, 16], mean_init_scale=1.0)
    normalizer, policy, _ = networks.init_params(cfg, velocity_env)
    return networks.make_networks(cfg, velocity_env), normalizer, policy


def test_relabelled_state_is_the_same_robot(velocity_env):
    """A robot turned about its own vertical axis by a multiple of 60 degrees, its joints relabelled
    by the action map, has every foot where the original's relabelled foot is, before and after
    20 physics steps under the relabelled controls, and observes the relabelled observation. The
    half turn is exact; the converted legs repeat under the others to within a millimetre (0.5 mm
    at this pose; the URDF's rounded offsets), and their 20 steps stay within 5% of how far the
    feet moved."""
    env, rng = velocity_env, np.random.default_rng(0)
    robot, task = env.robot, env.task
    model = robot.mj_model
    obs_maps, act_maps = symmetry.maps_for(env, 6)
    qpos = robot.qpos0.copy()
    qpos[3:7] = quat_z(0.7)
    qpos[7:] += rng.uniform(-0.3, 0.3, qpos.size - 7)
    qvel = rng.normal(0.0, 0.3, model.nv)
    ctrl = np.clip(robot.ctrl0 + rng.uniform(-0.4, 0.4, model.nu), robot.ctrl_lo, robot.ctrl_hi)
    command = np.array([0.3, -0.2, 0.5, 0.0], np.float32)
    original = mujoco.MjData(model)
    original.qpos, original.qvel, original.ctrl = qpos, qvel, ctrl
    mujoco.mj_forward(model, original)
    obs = task.observe(original.qpos, original.qvel, original.ctrl, qpos[:2], 0.0, command)
    for k, (angle, source) in enumerate(symmetry.leg_turns(robot.hip_bearings, 6)):
        act, c, s = act_maps[k], np.cos(angle), np.sin(angle)
        turn = np.array([[c, s], [-s, c]])
        turned = mujoco.MjData(model)
        turned.qpos[:3], turned.qpos[3:7], turned.qpos[7:] = qpos[:3], quat_mul(qpos[3:7], quat_z(angle)), act @ qpos[7:]
        turned.qvel[:3], turned.qvel[6:] = qvel[:3], act @ qvel[6:]
        turned.qvel[3:5], turned.qvel[5] = turn @ qvel[3:5], qvel[5]  # the free joint's angular velocity is body-frame
        turned.ctrl = act @ ctrl
        mujoco.mj_forward(model, turned)
        exact = np.isclose(angle, np.pi)
        np.testing.assert_allclose(turned.geom_xpos[robot.feet], original.geom_xpos[robot.feet[source]],
                                   atol=1e-9 if exact else 1e-3)
        command_turned = np.concatenate([turn @ command[:2], command[2:]]).astype(np.float32)
        seen = task.observe(turned.qpos, turned.qvel, turned.ctrl, qpos[:2], 0.0, command_turned)
        np.testing.assert_allclose(seen, obs_maps[k] @ obs, atol=1e-5)
        a, b = mujoco.MjData(model), turned
        a.qpos, a.qvel, a.ctrl = original.qpos, original.qvel, original.ctrl
        for _ in range(20):
            mujoco.mj_step(model, a)
            mujoco.mj_step(model, b)
        moved = np.abs(a.geom_xpos[robot.feet] - original.geom_xpos[robot.feet]).max()
        assert moved > 0.02  # m: the test moves the feet
        gap = np.abs(b.geom_xpos[robot.feet] - a.geom_xpos[robot.feet[source]]).max()
        assert gap < (1e-9 if exact else 0.05 * moved), (np.degrees(angle), gap, moved)


def test_maps_are_a_group(velocity_env):
    """Each turn's maps are orthogonal, and turning by k then by one more 60 degrees is turning by k + 1."""
    obs_maps, act_maps = symmetry.maps_for(velocity_env, 6)
    for maps in (obs_maps, act_maps):
        for m in maps:
            np.testing.assert_allclose(m @ m.T, np.eye(len(m)), atol=1e-6)
        for k in range(4):
            np.testing.assert_allclose(maps[0] @ maps[k], maps[k + 1], atol=1e-6)
        np.testing.assert_allclose(maps[0] @ maps[4], np.eye(len(maps[0])), atol=1e-6)


def test_mirror_loss_is_zero_for_a_symmetric_policy_only(velocity_env, small_policy):
    """A policy made equivariant by averaging over the turns has no mirror loss; a random one has."""
    net, normalizer, policy = small_policy
    obs_maps, act_maps = symmetry.maps_for(velocity_env, 6)
    loss = symmetry.mirror_loss(net, 2.0, obs_maps, act_maps)
    obs = jax.random.normal(jax.random.PRNGKey(1), (3, 5, velocity_env.observation_size))
    params = types.SimpleNamespace(policy=policy)
    assert float(loss(params, normalizer, obs)) > 1e-4

    class Averaged:  # g^-1 f(g s), averaged over the group: equivariant by construction
        @staticmethod
        def apply(norm, pol, o):
            total = net.policy_network.apply(norm, pol, o)[0]  # the Gaussian policy's (mean, std)
            for om, am in zip(obs_maps, act_maps):
                total = total + jp.einsum("ji,...j->...i", am, net.policy_network.apply(norm, pol, o @ om.T)[0])
            return total / (len(obs_maps) + 1), None

    averaged = types.SimpleNamespace(policy_network=Averaged)
    assert float(symmetry.mirror_loss(averaged, 2.0, obs_maps, act_maps)(params, normalizer, obs)) < 1e-10


def test_descending_the_mirror_loss_makes_the_policy_symmetric(velocity_env, small_policy):
    """Gradient steps on the loss alone shrink it: its gradient reaches the policy."""
    import optax

    net, normalizer, policy = small_policy
    loss = symmetry.mirror_loss(net, 1.0, *symmetry.maps_for(velocity_env, 6))
    obs = jax.random.normal(jax.random.PRNGKey(2), (64, velocity_env.observation_size))

    def of(policy):
        return loss(types.SimpleNamespace(policy=policy), normalizer, obs)

    opt = optax.adam(1e-2)

    @jax.jit
    def step(policy, state):
        updates, state = opt.update(jax.grad(of)(policy), state)
        return optax.apply_updates(policy, updates), state

    state, first = opt.init(policy), float(of(policy))
    for _ in range(100):
        policy, state = step(policy, state)
    assert float(of(policy)) < first / 10


def test_bad_symmetry_settings_fail_before_compiling():
    with pytest.raises(ConfigError, match="symmetry_turns"):
        validate(config.TrainConfig(task="velocity", symmetry_loss=1.0, symmetry_turns=1), writes=False)
    with pytest.raises(ConfigError, match="do not repeat every 72 degrees"):
        validate(config.TrainConfig(task="velocity", symmetry_loss=1.0, symmetry_turns=5), writes=False)
    with pytest.raises(ConfigError, match="torso position, world"):  # the report's task observes the world frame
        validate(config.TrainConfig(task="goal", symmetry_loss=1.0), writes=False)


def test_a_run_with_the_mirror_loss_trains(tmp_path):
    out = run("train.py", *["--task", "velocity", *TINY, "--hidden", "16", "16", "--symmetry_loss", "1.0",
               "--num_timesteps", "128", "--run_dir", str(tmp_path / "run")])
    assert "done: 128 steps" in out.stdout
    assert config.load_config(tmp_path / "run").symmetry_loss == 1.0
    gap = symmetry_gap(tmp_path / "run", episodes=2, steps=3, every=1)
    assert 0.0 < gap < 1.0  # a barely trained policy's mean actions are near 0 under every labelling
