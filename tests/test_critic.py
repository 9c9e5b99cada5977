"""The privileged critic (hexa_mjx.training.critic): the value network reads the observation without
its noise and the failed legs, the policy its own observation alone; PPO with it is brax's PPO with
a dict observation; a critic-less start carries over; the exported policy is the trained one."""

import dataclasses

import jax
import jax.numpy as jp
import numpy as np
import pytest

from conftest import TINY, run
from hexa_mjx.deploy import export, player
from hexa_mjx.engines import wrappers
from hexa_mjx.training import checkpoints, config, critic, networks, ppo, loop as training

# Leg 2 locked in every episode, observation noise on: the critic's observation must differ from
# the policy's by the noise alone, and name the leg.
FIXED = config.TrainConfig(num_envs=4, episode_length=20, leg_failure="random", leg_failure_rate=1.0,
                           leg_failure_weights=[0, 1, 0, 0, 0, 0], failure_mode="locked", obs_noise=1.0,
                           start_joint_noise=0.05, hidden=[16, 16], privileged_critic=True)


def test_critic_sees_the_clean_observation_and_the_failed_leg():
    env = config.make_env_for(FIXED)
    plain = wrappers.wrap_for_training(env, episode_length=20)
    split = wrappers.wrap_for_training(env, episode_length=20, critic_observation=True)
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    action = 0.3 * jp.ones((4, env.action_size))
    ref = jax.jit(plain.reset)(keys)
    ours = jax.jit(split.reset)(keys)
    for _ in range(2):
        ref, ours = jax.jit(plain.step)(ref, action), jax.jit(split.step)(ours, action)
        np.testing.assert_array_equal(ours.obs["state"], ref.obs)  # the policy sees what it saw before
        n = env.observation_size
        seen = np.asarray(ours.obs["privileged_state"])
        assert seen.shape == (4, n + 12)
        np.testing.assert_allclose(seen[:, :n], jax.vmap(env.observe)(ref.pipeline_state), atol=1e-6)
        assert np.abs(seen[:, :n] - np.asarray(ref.obs)).max() > 0.01  # the noise is the policy's alone
        np.testing.assert_array_equal(seen[:, n:n + 6], 0.0)  # limp: none
        np.testing.assert_array_equal(seen[:, n + 6:], np.tile([0, 1, 0, 0, 0, 0], (4, 1)))  # locked: leg 2


# brax's own PPO on the same dict observation: our loop holds two normalizers and feeds each
# network its key exactly as brax does (bit for bit, as tests/test_ppo.py for one observation).
PPO_CFG = config.TrainConfig(num_envs=8, batch_size=8, num_minibatches=2, unroll_length=4, episode_length=20,
                             update_epochs=2, hidden=[32, 32], start_joint_noise=0.05, leg_failure="random",
                             leg_failure_rate=0.5, failure_mode="mixed", privileged_critic=True)


def test_same_params_as_brax_ppo_train_with_a_privileged_critic():
    from brax.training.agents.ppo import train as brax_ppo

    env = config.make_env_for(PPO_CFG)
    settings = training.ppo_settings(PPO_CFG, num_timesteps=128, num_evals=2, seed=2, devices=1)
    kwargs = dict(network_factory=networks.network_factory(PPO_CFG),
                  wrap_env_fn=training.wrap_env_fn(env, critic_observation=True))
    params = ppo.train(env, settings, **kwargs)
    _, reference, _ = brax_ppo.train(environment=env, run_evals=False, num_eval_envs=2,
                                     **dataclasses.asdict(settings), **kwargs)
    normalizer = params[0]
    assert set(normalizer.mean) == {"state", "privileged_state"} and int(normalizer.count.lo) > 0
    assert params[2]["params"]["hidden_0"]["kernel"].shape[0] == env.observation_size + 12
    jax.tree.map(np.testing.assert_array_equal, params, jax.tree.map(np.asarray, reference))


def test_a_start_without_the_critic_keeps_its_policy_and_its_values(env):
    flat_cfg = dataclasses.replace(FIXED, privileged_critic=False, obs_noise=0.0)
    rng = np.random.default_rng(0)
    n = env.observation_size
    normalizer, policy, value = jax.tree.map(np.asarray, networks.init_params(flat_cfg, env))
    # Statistics as a trained run has them, not the fresh (0, 1).
    count = type(normalizer.count)(hi=np.uint32(0), lo=np.uint32(500))
    normalizer = normalizer.replace(count=count, mean=rng.normal(size=n).astype(np.float32),
                                    std=rng.uniform(0.5, 2.0, n).astype(np.float32),
                                    summed_variance=np.zeros(n, np.float32))
    normalizer = normalizer.replace(summed_variance=(500.0 * normalizer.std ** 2).astype(np.float32))
    value = jax.tree.map(lambda x: rng.normal(size=x.shape).astype(np.float32), value)
    template, _ = networks.templates(FIXED, env)
    lifted = critic.with_critic((normalizer, policy, value), template)
    assert jax.tree.structure(lifted) == jax.tree.structure(template)
    obs = (normalizer.mean + normalizer.std * rng.normal(size=(16, n))).astype(np.float32)
    failures = rng.integers(0, 2, (16, 12)).astype(np.float32)
    flat_nets, nets = networks.make_networks(flat_cfg, env), networks.make_networks(FIXED, env)
    before = flat_nets.value_network.apply(normalizer, value, obs)
    after = nets.value_network.apply(lifted[0], lifted[2], {"state": obs, "privileged_state": np.concatenate(
        [obs, failures], axis=1)})
    np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-5)
    key = jax.random.PRNGKey(0)
    np.testing.assert_array_equal(networks.make_inference(FIXED, env, lifted)(obs, key),
                                  networks.make_inference(flat_cfg, env, (normalizer, policy, value))(obs, key))


def test_a_run_with_a_privileged_critic_trains_from_a_plain_run_and_exports(trained, tmp_path, cache_env):
    source, _ = trained
    run_dir = tmp_path / "critic"
    run("train.py", *TINY, "--privileged_critic", "--leg_failure", "random", "--leg_failure_rate", "0.5",
        "--failure_mode", "mixed", "--num_timesteps", "64", "--seed", "1", "--init_from", str(source),
        "--run_dir", str(run_dir), env=cache_env)
    cfg = config.load_config(run_dir)
    env = config.make_env_for(cfg)
    step, params = checkpoints.load_checkpoint(checkpoints.list_checkpoints(run_dir)[-1][1],
                                               networks.init_params(cfg, env))
    assert step == 64 and set(params[0].mean) == {"state", "privileged_state"}
    out = export.export(run_dir, tmp_path / "p.onnx")
    assert export.read_metadata(out)["observation_size"] == env.observation_size
    obs = np.random.default_rng(2).normal(size=(8, env.observation_size)).astype(np.float32)
    expected = np.clip(np.asarray(jax.vmap(networks.make_inference(cfg, env, params), in_axes=(0, None))(
        obs, jax.random.PRNGKey(0))), -1, 1)
    np.testing.assert_allclose(player.OnnxPolicy(out)(obs), expected, atol=1e-5, rtol=0)
    # It goes on from its own checkpoint, critic and training environments included.
    resumed = run("train.py", "--run_dir", str(run_dir), "--resume", "--num_timesteps", "128", env=cache_env)
    assert "its environments carry on" in resumed.stdout
    assert checkpoints.list_checkpoints(run_dir)[-1][0] == 128
    # A plain run cannot start from it: its critic has nowhere to go.
    with pytest.raises(config.ConfigError, match="privileged_critic True there"):
        config.validate(dataclasses.replace(cfg, privileged_critic=False, init_from=str(run_dir),
                                            run_dir=str(tmp_path / "plain")), writes=False)
