"""The drive task: velocity commands or goals per episode, one observation for both, each mode
paid and scored by its own terms and figures; a navigation policy starts a drive run unchanged."""

import dataclasses

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.engines.native import NativeEnv
from hexa_mjx.evaluation import evaluate, table
from hexa_mjx.mdp.config import make_config
from hexa_mjx.robot import constants as robot
from hexa_mjx.tasks import TASKS, drive
from hexa_mjx.training import config, networks, warm_start

EPISODES = 32


def drive_env_config():
    return make_config("drive", episode_length=30, command_interval=10 / 60.0, goal_min_distance=0.2,
                       goal_max_distance=0.3, goal_mode_share=0.0, reward_scales={"tracking_ang_vel": 10.0})


@pytest.fixture(scope="module")
def drive_env():
    return hexa_mjx.make_env(task="drive", episode_length=30, command_interval=10 / 60.0, goal_min_distance=0.2,
                             goal_max_distance=0.3)


@pytest.fixture(scope="module")
def drive_run(drive_env):
    """(states after reset, states after 12 random steps, summed |scaled term| per episode)."""
    states = jax.jit(jax.vmap(drive_env.reset))(jax.random.split(jax.random.PRNGKey(0), EPISODES))
    step = jax.jit(jax.vmap(drive_env.step))
    s, total = states, {}
    for i in range(12):
        s = step(s, jax.random.uniform(jax.random.PRNGKey(i), (EPISODES, drive_env.action_size), minval=-1, maxval=1))
        for k, v in s.metrics.items():
            if k.startswith("reward/"):
                total[k[7:]] = total.get(k[7:], 0.0) + np.abs(np.asarray(v))
    return states, s, total


def test_each_episode_is_in_one_mode_and_observes_only_its_own_inputs(drive_env, drive_run):
    states, later, _ = drive_run
    goal_mode = np.asarray(drive.in_goal_mode(states.pipeline_state.userdata))
    assert 0 < goal_mode.sum() < EPISODES  # goal_mode_share 0.5: both modes drawn
    np.testing.assert_array_equal(np.asarray(drive.in_goal_mode(later.pipeline_state.userdata)), goal_mode)
    obs = np.asarray(states.obs)
    assert obs.shape == (EPISODES, TASKS["drive"].layout(18)[-1][1]) and obs.shape[1] == drive_env.observation_size
    np.testing.assert_array_equal(obs[:, -1], goal_mode)  # the mode, last
    np.testing.assert_allclose(np.linalg.norm(obs[goal_mode, :2], axis=1), 1.0, atol=1e-5)  # the goal's direction
    moving = np.abs(obs[~goal_mode, :drive.LEAD]).sum(1) > 0
    assert moving.sum() >= 0.6 * (~goal_mode).sum()  # most commands ask to move (10% are zero)
    # Goal mode observes what the navigate task does; command mode what the velocity task does.
    for mode, task in ((True, "navigate"), (False, "velocity")):
        own = TASKS[task](drive_env.config, drive_env.robot)
        i = np.flatnonzero(goal_mode == mode)[0]
        d = jax.tree.map(lambda x: x[i], states.pipeline_state)
        np.testing.assert_allclose(obs[i, :-1], own.observe(d.qpos, d.qvel, d.ctrl, drive_env.goal(d),
                                                            drive_env.heading(d), d.userdata), atol=1e-6)


def test_each_mode_is_paid_by_its_own_terms_and_reaches_goals_only_in_goal_mode(drive_env, drive_run):
    states, later, total = drive_run
    goal_mode = np.asarray(drive.in_goal_mode(states.pipeline_state.userdata))
    for name in ("goal_approach", "velocity_alignment"):
        assert total[name][~goal_mode].max() == 0.0 and total[name][goal_mode].max() > 0.0, name
    for name in ("tracking_lin_vel", "tracking_ang_vel"):
        assert total[name][goal_mode].max() == 0.0 and total[name][~goal_mode].max() > 0.0, name
    for name in ("stability", "height"):  # the shared shaping in both
        assert total[name][goal_mode].max() > 0.0 and total[name][~goal_mode].max() > 0.0, name
    assert drive_env.scales["body_contact"] == TASKS["navigate"].rewards["navigate"]["body_contact"]
    # Every goal is 0.2 to 0.3 m away, inside the 0.5 m radius: goal mode counts one at once, command mode none.
    goals = np.asarray(later.info["goals"])
    assert goals[goal_mode].min() >= 1 and goals[~goal_mode].max() == 0


def test_command_mode_gain_weighs_every_term_of_a_command_step_and_leaves_goal_steps(drive_env):
    terms = {name: np.full(2, 3.0, np.float32) for name in ("goal_approach", "tracking_lin_vel", "stability")}
    command = np.array([[0.2, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, drive.GOAL_MODE]], np.float32)  # command, goal
    plain = TASKS["drive"](drive_env.config, drive_env.robot).mask_terms(terms, command)
    gained = TASKS["drive"](dataclasses.replace(drive_env.config, command_mode_gain=2.5),
                            drive_env.robot).mask_terms(terms, command)
    assert {k: v.tolist() for k, v in plain.items()} == {"goal_approach": [0.0, 3.0], "tracking_lin_vel": [3.0, 0.0],
                                                         "stability": [3.0, 3.0]}
    assert {k: v.tolist() for k, v in gained.items()} == {"goal_approach": [0.0, 3.0], "tracking_lin_vel": [7.5, 0.0],
                                                          "stability": [7.5, 3.0]}
    with pytest.raises(ValueError, match="command_mode_gain is a factor above 0"):
        NativeEnv(dataclasses.replace(drive_env.config, command_mode_gain=0.0))


def test_a_gained_run_reads_its_tracking_as_an_ungained_one_does():
    """The progress line and the checkpoint choice read a run's tracking at the weight it was paid at."""
    from hexa_mjx.training import checks
    from hexa_mjx.tasks.velocity import VelocityTask

    figures = []
    for gain in (1.0, 2.5):
        env = NativeEnv(dataclasses.replace(drive_env_config(), command_mode_gain=gain))
        env.reset(seed=3)
        paid = {"tracking_lin_vel": 0.0, "tracking_ang_vel": 0.0}
        for i in range(20):
            terms = env.step(np.random.default_rng(i).uniform(-1, 1, 18))[4]["terms"]
            paid = {k: v + terms[k] * env.scales[k] for k, v in paid.items()}
        row = {"episode_length": 20, **{f"eval/episode_reward/{k}": v for k, v in paid.items()}}
        cfg = config.TrainConfig(task="drive", command_mode_gain=gain, reward_scale=["tracking_ang_vel=10"])
        figures.append(VelocityTask.tracking(row, checks.run_scales(cfg)))
    assert 0 < figures[0][0] < 1 and 0 < figures[0][1] < 1
    np.testing.assert_allclose(figures[1], figures[0], rtol=1e-6)


def test_native_engine_observes_and_scores_what_mjx_does(drive_env, drive_run):
    states, _, _ = drive_run
    native = NativeEnv(drive_env.config)
    native.reset(seed=0)
    for i in (0, 1, 2, 3):
        d = native.data
        for name in ("qpos", "qvel", "ctrl", "mocap_pos", "mocap_quat", "userdata"):
            getattr(d, name)[:] = np.asarray(getattr(states.pipeline_state, name))[i]
        mujoco.mj_forward(native.mj_model, d)
        np.testing.assert_allclose(native.observe(), np.asarray(states.obs)[i], atol=1e-5)
        _, _, _, _, info = native.step(np.zeros(18))
        goal_mode = bool(drive.in_goal_mode(native.command))
        assert (info["terms"]["tracking_lin_vel"] == 0.0) == goal_mode
        assert (info["terms"]["goal_approach"] == 0.0) != goal_mode or info["terms"]["goal_approach"] == 0.0


def test_waypoints_are_walked_in_goal_mode_and_a_keyboard_command_in_command_mode():
    env = NativeEnv(dataclasses.replace(hexa_mjx.make_env(task="drive").config, waypoints=((1.0, 0.0), (1.0, 1.0))))
    for seed in range(4):
        env.reset(seed=seed)
        assert drive.in_goal_mode(env.command)
    env.set_command([0.3, 0.0, 0.0, 0.0])  # what play.py's keyboard and the path follower write
    assert not drive.in_goal_mode(env.command)
    np.testing.assert_allclose(env.observe()[:drive.LEAD], [0.3, 0.0, 0.0], atol=1e-6)
    assert env.observe()[-1] == 0.0


def test_eval_figures_come_from_each_mode_own_episodes(drive_env):
    zero = lambda obs, key: jp.zeros(obs.shape[:-1] + (drive_env.action_size,))  # noqa: E731
    start, traj = evaluate.rollout(drive_env, zero, 8, seed=3)
    result = evaluate.episode_table(drive_env, start, traj)
    summary, per_episode = result["summary"], result["per_episode"]
    goal_mode = np.asarray(per_episode["goal_mode"])
    assert summary["modes"] == {"goal": int(goal_mode.sum()), "command": int((~goal_mode).sum())}
    assert 0 < goal_mode.sum() < 8
    assert {record["episode"] for record in per_episode["goals"]} <= set(np.flatnonzero(goal_mode).tolist())
    assert set(per_episode["tracking"]["velocity_rms"]) == set(np.flatnonzero(~goal_mode).tolist())
    assert summary["navigation"]["first_goal_success"] == pytest.approx(1.0)  # every goal starts within reach
    text = table.format_table(summary, TASKS["drive"])
    assert "episodes in goal mode, command mode" in text and "velocity and yaw-rate RMS errors" in text


def test_a_navigation_policy_starts_a_drive_run_acting_as_before(capsys, tmp_path):
    for source in ("navigate", "velocity"):  # both tasks' shipped policies start a drive run
        path = str(robot.REPO_ROOT / "policies" / source)
        cfg = config.parse_args(["--task", "drive", "--init_from", path, "--run_dir", str(tmp_path / source)])
        assert config.validate(cfg).init_from == path
        assert "observes 1 more value(s)" in capsys.readouterr().out
    with pytest.raises(config.ConfigError, match="only without privileged_critic"):
        config.validate(dataclasses.replace(cfg, privileged_critic=True))
    layout = TASKS["drive"].layout(18)
    # A drive policy's params do not start a navigate run: it reads more values.
    assert not warm_start.extends(layout, TASKS["navigate"].layout(18))
    # Past the lead of task inputs every slice must match: proprioception out of place does not fit.
    moved = [*layout[:5], (*layout[5][:3], "other units"), *layout[6:]]
    assert warm_start.extends(TASKS["navigate"].layout(18), layout)
    assert not warm_start.extends(TASKS["navigate"].layout(18), moved)

    small = config.TrainConfig(task="navigate", hidden=[16, 16])
    nav_env, env = config.make_env_for(small), config.make_env_for(dataclasses.replace(small, task="drive"))
    rng = np.random.default_rng(0)
    params = jax.tree.map(lambda x: np.asarray(x) + rng.normal(size=np.shape(x)).astype(np.asarray(x).dtype)
                          if np.issubdtype(np.asarray(x).dtype, np.floating) else x,
                          networks.init_params(small, nav_env))
    params = (params[0].replace(std=np.abs(params[0].std) + 0.5), *params[1:])
    template, _ = networks.templates(dataclasses.replace(small, task="drive"), env)
    wide = warm_start.widened(params, template)
    assert jax.tree.structure(wide) == jax.tree.structure(template)
    obs = rng.normal(size=(8, nav_env.observation_size)).astype(np.float32)
    mode = rng.normal(size=(8, 1)).astype(np.float32)  # the mode input, at any value
    key = jax.random.PRNGKey(0)
    before = networks.make_inference(small, nav_env, params)(obs, key)
    after = networks.make_inference(dataclasses.replace(small, task="drive"), env, wide)(
        np.concatenate([obs, mode], axis=1), key)
    np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-6)
    drive_nets, nav_nets = networks.make_networks(small, env), networks.make_networks(small, nav_env)
    np.testing.assert_allclose(drive_nets.value_network.apply(wide[0], wide[2], np.concatenate([obs, mode], 1)),
                               nav_nets.value_network.apply(params[0], params[2], obs), rtol=1e-5, atol=1e-5)


@pytest.fixture(scope="module")
def drive_onnx(tmp_path_factory):
    """A drive run whose only checkpoint is the shipped navigation policy widened as --init_from
    widens it (training.loop.load_start), exported."""
    import json

    from hexa_mjx.deploy import export
    from hexa_mjx.training import checkpoints, loop

    run_dir = tmp_path_factory.mktemp("drive") / "run"
    navigate = str(robot.REPO_ROOT / "policies" / "navigate")
    cfg = config.validate(config.parse_args(["--task", "drive", "--init_from", navigate, "--cpu_devices", "1",
                                             "--run_dir", str(run_dir)]))
    env = config.make_env_for(cfg)
    step, params = loop.load_start(cfg, env, networks.templates(cfg, env)[0])
    (run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    checkpoints.save_checkpoint(run_dir, 0, params)
    return run_dir, export.export(run_dir, run_dir.parent / "drive.onnx")


def test_export_names_the_command_where_the_drive_observation_holds_it(drive_onnx):
    from hexa_mjx.deploy import export

    meta = export.read_metadata(drive_onnx[1])
    assert meta["task"] == "drive" and meta["observation_size"] == 68
    assert [f["observation_index"] for f in meta["command"]] == [0, 1, 2]
    assert meta["observation_layout"][-1]["what"].startswith("mode")


def test_the_battery_walks_a_drive_policy_by_commands_or_in_its_goal_mode(drive_onnx):
    from hexa_mjx.deploy import player
    from hexa_mjx.studies import generalist, robustness

    onnx = str(drive_onnx[1])
    policy = player.OnnxPolicy(onnx)
    # Goal mode: the widened navigation policy is the navigation policy, so it walks the square as
    # that policy does (its battery row: 100% in about 8 s).
    row, = generalist.battery(onnx, 1, groups=["flat"], goal_mode=True)
    assert row["path_completed_rate"] == 1.0 and 4 < row["path_time_s_median"] < 20, row
    env = robustness.path_env(policy, generalist.SQUARE, **generalist.base_settings(), goal_mode_share=1.0)
    assert env.config.waypoints and env.reset(seed=0) is not None and drive.in_goal_mode(env.command)
    # Command mode: the follower drives it from the first step; its command weights start at zero,
    # so this policy has not learnt them.
    env = robustness.path_env(policy, generalist.SQUARE, **generalist.base_settings())
    assert not env.config.waypoints and env.config.goal_mode_share == 0.0
    env.reset(seed=0)
    assert not drive.in_goal_mode(env.command)
    with pytest.raises(ValueError, match="goal mode is a drive policy's"):
        generalist.battery(str(robot.REPO_ROOT / "policies" / "velocity.onnx"), 1, groups=["flat"], goal_mode=True)


def test_the_mode_advantage_study_refuses_a_policy_without_modes():
    from hexa_mjx.studies import mode_advantages

    with pytest.raises(SystemExit, match="navigate policy; this study splits a drive policy"):
        mode_advantages.spreads(robot.REPO_ROOT / "policies" / "navigate")
