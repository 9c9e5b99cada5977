"""The stand task, the example of a task added as one module: it runs in MJX, native MuJoCo,
Gymnasium, eval.py, export and the player with no code of its own outside hexa_mjx/tasks/stand.py."""

import dataclasses
import json
import subprocess
import sys

import jax
import jax.numpy as jp
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.deploy import export, player
from hexa_mjx.engines.native import NativeEnv
from hexa_mjx.evaluation import evaluate
from hexa_mjx.robot import constants as robot
from hexa_mjx.robot.kinematics import yaw
from hexa_mjx.tasks import stand
from hexa_mjx.training import checkpoints, config, networks


@pytest.fixture(scope="module")
def stand_env():
    return hexa_mjx.make_env(task="stand", episode_length=20)


@pytest.fixture(scope="module")
def stand_states(stand_env):
    return jax.jit(jax.vmap(stand_env.reset))(jax.random.split(jax.random.PRNGKey(0), 64))


def test_each_episode_asks_for_a_heading_on_the_start_spot(stand_env, stand_states):
    data = stand_states.pipeline_state
    goals, headings = np.asarray(jax.vmap(stand_env.goal)(data)), np.asarray(jax.vmap(stand_env.heading)(data))
    np.testing.assert_allclose(goals, np.asarray(data.qpos[:, :2]), atol=1e-6)  # the spot is the start
    assert headings.min() < -2.0 and headings.max() > 2.0  # drawn over 360 degrees
    errors = np.asarray(jax.vmap(lambda q, h: stand.heading_error(q, h))(data.qpos, headings))
    obs = np.asarray(stand_states.obs)
    assert obs.shape == (64, stand.StandTask.layout(18)[-1][1])
    np.testing.assert_allclose(obs[:, 2:4], np.stack([np.cos(errors), np.sin(errors)], 1), atol=1e-5)
    turned = np.asarray(jax.vmap(lambda q: yaw(q[3:7]))(data.qpos))
    np.testing.assert_allclose(np.cos(turned - headings), np.cos(errors), atol=1e-5)


def test_rewards_are_logged_per_term_and_pay_for_facing_the_heading(stand_env, stand_states):
    state = jax.tree.map(lambda x: x[0], stand_states)
    nxt = jax.jit(stand_env.step)(state, jp.zeros(stand_env.action_size))
    assert {"reward/spot_tracking", "reward/heading_tracking"} <= set(nxt.metrics)
    qpos = state.pipeline_state.qpos
    facing = stand.heading_tracking(None, qpos, None, None, yaw(qpos[3:7]), None)
    away = stand.heading_tracking(None, qpos, None, None, yaw(qpos[3:7]) + np.pi, None)
    assert float(facing) == pytest.approx(1.0) and float(away) < 1e-6
    reached = stand_env.task.reached(jp.float32(0.0), qpos, yaw(qpos[3:7]) + 2 * stand.HEADING_TOLERANCE, None)
    assert not bool(reached) and bool(stand_env.task.reached(jp.float32(0.0), qpos, yaw(qpos[3:7]), None))


def test_native_engine_observes_what_mjx_does(stand_env, stand_states):
    state = jax.tree.map(lambda x: x[3], stand_states)
    native = NativeEnv(stand_env.config)
    native.reset(seed=0)
    d = native.data
    for name in ("qpos", "qvel", "ctrl", "mocap_pos", "mocap_quat"):
        getattr(d, name)[:] = np.asarray(getattr(state.pipeline_state, name))
    import mujoco

    mujoco.mj_forward(native.mj_model, d)
    np.testing.assert_allclose(native.observe(), np.asarray(state.obs), atol=1e-5)
    obs, reward, terminated, truncated, info = native.step(np.zeros(18))
    assert np.isfinite(reward) and set(info["terms"]) >= {"spot_tracking", "heading_tracking"}


def test_gymnasium_id_needs_no_import_of_ours():
    code = ("import gymnasium\nenv = gymnasium.make('hexa_mjx.engines.gym_envs:hexa_mjx/HexapodStand-v0')\n"
            "obs, _ = env.reset(seed=0)\nprint(obs.shape)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=robot.REPO_ROOT)
    size = stand.StandTask.layout(18)[-1][1]
    assert proc.returncode == 0 and f"({size},)" in proc.stdout, proc.stderr


@pytest.fixture(scope="module")
def stand_run(tmp_path_factory):
    """A stand-task run directory with an untrained checkpoint: enough to evaluate, export and play."""
    run_dir = tmp_path_factory.mktemp("stand") / "run"
    cfg = config.validate(config.parse_args(["--task", "stand", "--hidden", "8", "8", "--episode_length", "20",
                                             "--num_envs", "8", "--batch_size", "8", "--num_minibatches", "1",
                                             "--cpu_devices", "1", "--run_dir", str(run_dir)]))
    (run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    checkpoints.save_checkpoint(run_dir, 0, networks.init_params(cfg, config.make_env_for(cfg)))
    return run_dir


def test_eval_export_and_player_run_the_task(stand_run, tmp_path):
    result = evaluate.evaluate(stand_run, episodes=2, video=False, out=tmp_path / "eval")
    assert result["config"]["task"] == "stand" and result["summary"]["episodes"] == 2
    assert "spot_tracking" in result["summary"]["reward_terms"]
    onnx = export.export(stand_run, tmp_path / "stand.onnx")
    policy = player.OnnxPolicy(onnx)
    assert policy.metadata["task"] == "stand" and policy.metadata["observation_size"] == stand.StandTask.layout(18)[-1][1]
    episode = player.run_episode(policy, player.env_for(policy), seed=0)
    assert episode["steps"] == 20 and np.isfinite(episode["return"])
