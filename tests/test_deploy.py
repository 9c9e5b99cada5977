"""Outside the trainer: ONNX export, the native-MuJoCo engine and player, Gymnasium, shipped policies."""

import json
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest

from hexa_mjx.training import checkpoints, config, networks
from hexa_mjx.deploy import export, player
from hexa_mjx.robot import constants as robot
from hexa_mjx.studies.benchmark import gait_actions
from hexa_mjx.engines.native import NativeEnv
from hexa_mjx.tasks import TASKS

POLICIES = robot.REPO_ROOT / "policies"
# policies/<name>: a run directory and its ONNX
SHIPPED = ("goal", "navigate", "velocity", "generalist", "leg_failure", "drive")
# m/s: about three times the largest single-episode RMS error of the shipped velocity policy in
# native MuJoCo at the model's solver over 32 episodes (0.069; over all 32, 0.050).
VELOCITY_RMS_BOUND = 0.2
# Conditions the shipped generalist policy completes in all 8 of the battery's episodes
# (docs/RESULTS.md, "The shipped generalist policy"); the test walks two of each.
GENERALIST_CONDITIONS = ({"terrain": "stairs", "terrain_seed": 1, "terrain_difficulty": 1.0},
                         {"disabled_legs": (6,), "failure_mode": "locked"})
# Conditions the shipped drive policy walks in its goal mode in all 8 of the battery's episodes
# (docs/RESULTS.md, "The shipped drive policy"); the test walks two of each.
DRIVE_CONDITIONS = ({"terrain": "stairs", "terrain_seed": 1, "terrain_difficulty": 1.0},
                    {"disabled_legs": (1,), "failure_mode": "limp"})


@pytest.fixture(scope="module")
def shipped():
    """(config, params, ONNX policy) of each shipped policy, by name."""
    out = {}
    for name in SHIPPED:
        run_dir, ckpt = checkpoints.resolve_checkpoint(POLICIES / name)
        cfg = config.load_config(run_dir)
        _, params = checkpoints.load_checkpoint(ckpt, networks.init_params(cfg, config.make_env_for(cfg)))
        out[name] = (cfg, params, player.OnnxPolicy(POLICIES / f"{name}.onnx"))
    return out


def copy_state(native, data) -> None:
    """Put an MJX state (and its goal) into a native environment."""
    d = native.data
    for name in ("qpos", "qvel", "ctrl", "mocap_pos", "qacc_warmstart"):
        getattr(d, name)[:] = np.asarray(getattr(data, name))
    mujoco.mj_forward(native.mj_model, d)


def test_native_foot_stance_and_power():
    env = NativeEnv(config.EnvConfig())
    env.reset(seed=0)
    assert env.foot_stance().tolist() == [True] * 6 and env.servo_power() < 0.1  # W: standing, settled
    env.data.qpos[2] += 0.1  # m: the feet lifted off the floor
    env.data.qvel[env.robot.actuator_dof] = 1.0  # rad/s
    mujoco.mj_forward(env.mj_model, env.data)
    assert env.foot_stance().tolist() == [False] * 6 and env.servo_power() > 0.0


@pytest.mark.parametrize("name", SHIPPED)
def test_onnx_matches_the_jax_policy(shipped, name):
    cfg, params, policy = shipped[name]
    env = config.make_env_for(cfg)
    act = jax.jit(jax.vmap(networks.make_inference(cfg, env, params), in_axes=(0, None)))
    # 1,000 observations spread like the ones training saw (the normalizer's statistics).
    rng = np.random.default_rng(0)
    normalizer = params[0]
    obs = (np.asarray(normalizer.mean) + 2 * np.asarray(normalizer.std) * rng.normal(size=(1000, env.observation_size)))
    obs = obs.astype(np.float32)
    expected = np.clip(np.asarray(act(obs, jax.random.PRNGKey(0))), -1, 1)
    assert 0.05 < np.mean(np.abs(expected) == 1) < 0.95  # saturated and unsaturated actions both occur
    np.testing.assert_allclose(policy(obs), expected, atol=1e-5, rtol=0)


def test_export_writes_metadata_a_deployer_needs(tmp_path):
    out = export.export(POLICIES / "goal", tmp_path / "p.onnx")
    meta = export.read_metadata(out)
    assert meta == json.loads(out.with_suffix(".json").read_text())
    assert meta["task"] == "goal" and meta["control_hz"] == 60.0 and meta["observation_size"] == 52
    assert meta["observation_layout"][-1]["end"] == 52 and meta["observation_layout"][0]["units"] == "m"
    assert meta["joint_order"] == list(robot.JOINT_NAMES)
    lo, hi = np.array(meta["action_mapping"]["ctrl_lo"]), np.array(meta["action_mapping"]["ctrl_hi"])
    model = mujoco.MjModel.from_xml_path(str(robot.MODEL_XML))
    np.testing.assert_allclose(np.stack([lo, hi], 1), model.actuator_ctrlrange, atol=1e-6)
    # The same policy as the shipped file: exporting is deterministic.
    obs = np.random.default_rng(1).normal(size=(8, 52)).astype(np.float32)
    np.testing.assert_array_equal(player.OnnxPolicy(out)(obs), player.OnnxPolicy(POLICIES / "goal.onnx")(obs))


def test_tanh_policy_and_deeper_networks_export(env):
    cfg = config.TrainConfig(hidden=[32, 16, 8], policy_dist="tanh_normal", mean_init_scale=1.0, seed=3)
    params = networks.init_params(cfg, env)
    model = export.onnx_model(export.policy_arrays(cfg.policy_dist, params), {"format": export.FORMAT})
    import onnxruntime as ort

    obs = np.random.default_rng(2).normal(size=(100, 52)).astype(np.float32)
    got = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"obs": obs})[0]
    expected = np.asarray(jax.vmap(networks.make_inference(cfg, env, params), in_axes=(0, None))(obs, jax.random.PRNGKey(0)))
    np.testing.assert_allclose(got, expected, atol=1e-5, rtol=0)


def test_native_rewards_match_mjx_from_the_same_state(env, step, state0):
    """For the same action from the same state, the native engine's reward and terms equal MJX's:
    on most steps to float precision; on steps with a foot impact the engines' contact solutions
    differ slightly, so the reward is within 2% + 0.05."""
    native = NativeEnv(env.config)
    native.reset(seed=0)
    state, gaps = state0, []
    for t, action in enumerate(gait_actions(90, env.dt)):
        sample = t % 6 == 0  # from this MJX state, one step in each engine
        if sample:
            copy_state(native, state.pipeline_state)
            _, reward, terminated, _, info = native.step(action)
        state = step(state, jp.asarray(action, jp.float32))
        if sample:
            assert reward == pytest.approx(float(state.reward), rel=0.02, abs=0.05), t
            gaps.append(abs(reward - float(state.reward)))
            for name in ("contact_quality", "body_contact", "termination", "goal_bonus"):
                assert info["terms"][name] == float(state.metrics[f"reward/{name}"]) / env.scales[name], (t, name)
            assert terminated == bool(state.done)
    assert len(gaps) == 15 and np.median(gaps) < 1e-3


def test_native_air_time_matches_mjx(env, step, state0):
    """Both engines count each foot's time off the floor and its share of time down the same way
    (the inputs of the idle_feet and low_duty terms)."""
    data = state0.pipeline_state
    lifted = state0.replace(pipeline_state=data.replace(qpos=data.qpos.at[2].add(0.3)))
    native = NativeEnv(env.config)
    native.reset(seed=0)
    copy_state(native, lifted.pipeline_state)
    state = lifted
    for _ in range(4):
        state = step(state, jp.zeros(env.action_size))
        native.step(np.zeros(env.action_size))
    np.testing.assert_allclose(native.info["air_time"], np.asarray(state.info["air_time"]), rtol=1e-5)
    np.testing.assert_allclose(native.info["stance_avg"], np.asarray(state.info["stance_avg"]), rtol=1e-5)
    assert native.info["air_time"].min() > 0


def test_player_follows_the_mjx_rollout(env, step, state0, shipped):
    """Same start, same policy: the native trajectory matches MJX's closely for the first 0.25 s,
    and both reach the goal within 10 s; after that, contact events diverge (docs/RESULTS.md)."""
    cfg, params, policy = shipped["goal"]
    act = jax.jit(networks.make_inference(cfg, env, params))
    native = player.env_for(policy)
    obs = native.reset(seed=0)
    np.testing.assert_allclose(obs, np.asarray(state0.obs), atol=1e-6)
    state, gaps, reached = state0, [], np.zeros(2, bool)
    for t in range(600):  # 10 s
        state = step(state, act(state.obs, jax.random.PRNGKey(0)))
        obs, _, _, _, info = native.step(policy(obs))
        gaps.append(np.abs(native.data.qpos[:2] - np.asarray(state.pipeline_state.qpos[:2])).max())
        reached |= [bool(info["success"]), bool(state.info["success"])]
    assert max(gaps[:15]) < 0.002  # m, first 0.25 s
    # Both arrive. What follows an arrival is chaotic: on an AMD EPYC host the MJX rollout, stepping
    # about near the goal, had fallen by 10 s, so where each engine ends at 10 s is not compared.
    assert reached.all()


@pytest.mark.parametrize("task,episodes", [("goal", 2), ("navigate", 6)])
def test_shipped_policies_succeed_on_the_current_model(shipped, task, episodes):
    policy = shipped[task][2]
    env = player.env_for(policy)
    results = [player.run_episode(policy, env, seed) for seed in range(episodes)]
    summary = player.summarize(results)
    assert summary["success_rate"] >= 0.9 and summary["fall_rate"] == 0.0, summary
    if task == "navigate":
        assert summary["goals_per_episode"] >= 5


def assert_tracks_commands(policy, **overrides):
    """Three native episodes of the task's random commands: no fall, planar RMS error in bound."""
    env = player.env_for(policy, **overrides)
    results = [player.run_episode(policy, env, seed) for seed in range(3)]
    summary, tracked = player.summarize(results), player.tracking(env, results)
    assert summary["fall_rate"] == 0.0 and tracked["velocity_rms"] < VELOCITY_RMS_BOUND, (summary, tracked)


def assert_walks_the_square(name, conditions, **settings):
    """policies/<name>.onnx completes the battery's 2 m square in 2 of 2 episodes without a fall in
    each condition (EnvConfig overrides over the battery's base, MJX's heightfield contacts)."""
    from hexa_mjx.studies import generalist, robustness

    base = {**generalist.base_settings(terrain_contacts="mjx"), **settings}
    rows = robustness.run_conditions(str(POLICIES / f"{name}.onnx"), [({**base, **c}, None) for c in conditions],
                                     episodes=2, path=generalist.SQUARE)
    for overrides, row in zip(conditions, rows):
        assert row["path_completed_rate"] == 1.0 and row["fall_rate"] == 0.0, (overrides, row)


def test_shipped_velocity_policy_follows_its_commands_on_the_current_model(shipped):
    # Native MuJoCo, three episodes of random commands (docs/RESULTS.md, "Velocity commands").
    assert_tracks_commands(shipped["velocity"][2])


def test_shipped_generalist_walks_the_square_on_stairs_and_on_a_failed_leg():
    """Native MuJoCo through the path follower, as the battery walks it (hexa_mjx.studies.generalist,
    MJX's heightfield contacts): the 2 m square up and down 5 cm stairs on a terrain the training
    never drew, and on flat ground with a leg the policy does not observe failed."""
    assert_walks_the_square("generalist", GENERALIST_CONDITIONS)


def test_shipped_drive_policy_follows_commands_and_walks_goals_on_a_limp_leg(shipped):
    """Native MuJoCo: in command mode, random commands on intact legs, tracked as the velocity
    policy's test bounds them; in goal mode, the 2 m square given as waypoints up and down 5 cm
    stairs the training never saw, and on flat ground with a leg limp that it does not observe."""
    assert_tracks_commands(shipped["drive"][2], goal_mode_share=0.0, leg_failure="none")
    assert_walks_the_square("drive", DRIVE_CONDITIONS, goal_mode_share=1.0)


def test_shipped_leg_failure_policy_walks_on_any_one_limp_leg():
    """Native MuJoCo, the leg-failure sweep's conditions at 2 seeded episodes each: intact, and each
    of the six legs limp, which the policy does not observe (docs/RESULTS.md, "The shipped
    leg-failure policy": 94 to 100% success with any one leg limp over 64 episodes)."""
    from hexa_mjx.studies import leg_failure_sweep

    rows = leg_failure_sweep.sweep(str(POLICIES / "leg_failure.onnx"), episodes=2, start_joint_noise=0.1)
    single = [r for r in rows if len(r["failed_legs"]) == 1]
    assert rows[0]["failed_legs"] == [] and rows[0]["success_rate"] == 1.0, rows[0]
    assert len(single) == 6 and sum(2 * r["success_rate"] for r in single) >= 10, single  # of 12 episodes


def run_play(*args, env=None):
    return subprocess.run([sys.executable, str(robot.REPO_ROOT / "play.py"), *args], capture_output=True, text=True,
                          env=env, cwd=robot.REPO_ROOT)


def test_play_writes_results_and_imports_no_jax(tmp_path):
    out = tmp_path / "r.json"
    code = ("import runpy, sys; sys.argv = ['play.py'] + sys.argv[1:]\n"
            "try:\n    runpy.run_path('play.py', run_name='__main__')\nexcept SystemExit as e:\n    assert not e.code\n"
            "heavy = sorted({m.split('.')[0] for m in sys.modules} & {'jax', 'jaxlib', 'brax', 'flax', 'optax', 'orbax'})\n"
            "print('heavy modules:', heavy)")
    proc = subprocess.run([sys.executable, "-c", code, "--policy", "policies/navigate.onnx", "--episodes", "2",
                           "--json", str(out), "--video", str(tmp_path / "v.mp4"), "--episode_length", "300"],
                          capture_output=True, text=True, cwd=robot.REPO_ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "heavy modules: []" in proc.stdout
    doc = json.loads(out.read_text())
    assert len(doc["episodes"]) == 2 and doc["model_matches_training"]
    assert {"success", "final_distance", "fell", "goals_reached"} <= set(doc["episodes"][0])
    assert (tmp_path / "v.mp4").stat().st_size > 10_000


def test_play_walks_a_drive_policy_in_goal_mode_given_waypoints_and_by_commands_with_follow(tmp_path):
    """--waypoints alone: the drive policy's goal mode takes them as goals; with --follow the path
    follower's commands drive it in command mode, which reaches the waypoints without goals."""
    runs = {}
    for mode, extra in (("goal", []), ("command", ["--follow"])):
        out = tmp_path / f"{mode}.json"
        proc = run_play("--policy", "policies/drive.onnx", "--waypoints", "1,0", "--leg_failure", "none", "--episodes",
                        "1", "--episode_length", "600", "--no-video", "--json", str(out), *extra)
        assert proc.returncode == 0, proc.stderr
        runs[mode] = (proc.stdout, json.loads(out.read_text())["episodes"][0])
    assert runs["goal"][1]["goals_reached"] >= 1 and "tracking" not in runs["goal"][0], runs["goal"]
    assert runs["command"][1]["goals_reached"] == 0 and "every waypoint reached in 1 of 1" in runs["command"][0]


def test_play_bad_input_is_one_line(tmp_path):
    wrong = tmp_path / "wrong.onnx"  # a 10-input graph whose metadata claims the goal task's 52
    arrays = {"mean": np.zeros(10, np.float32), "std": np.ones(10, np.float32), "squash": False,
              "layers": [(np.ones((10, 18), np.float32), np.zeros(18, np.float32))]}
    meta = export.read_metadata(POLICIES / "goal.onnx")
    wrong.write_bytes(export.onnx_model(arrays, meta).SerializeToString())
    mislabelled = tmp_path / "mislabelled.onnx"  # the goal policy labelled as a navigation policy
    arrays["mean"], arrays["std"] = np.zeros(52, np.float32), np.ones(52, np.float32)
    arrays["layers"] = [(np.ones((52, 18), np.float32), np.zeros(18, np.float32))]
    mislabelled.write_bytes(export.onnx_model(arrays, {**meta, "task": "navigate",
                                                       "env_config": {**meta["env_config"], "task": "navigate"}})
                            .SerializeToString())
    (tmp_path / "junk.onnx").write_text("not a model")
    cases = {
        (str(wrong),): "graph maps 10 -> 18",
        (str(mislabelled),): "observes 67 values",
        (str(tmp_path / "junk.onnx"),): "not a readable ONNX model",
        (str(tmp_path / "missing.onnx"),): "neither an ONNX file",
        ("policies/goal.onnx", "--waypoints", "1,0"): "need a task that follows a path",
        ("policies/navigate.onnx", "--waypoints", "1,x"): "is not x,y",
        ("policies/goal.onnx", "--episodes", "0"): "--episodes must be at least 1",
        ("policies/goal.onnx", "--goal_distance", "-1"): "goal_distance must be",
        ("policies/goal.onnx", "--terrain", "bumps", "--terrain_difficulty", "2"): "terrain_difficulty is a fraction",
        ("policies/goal.onnx", "--terrain", "lava"): "invalid choice: 'lava'",
    }
    for args, message in cases.items():
        proc = run_play("--policy", *args, "--no_video")
        assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr, (args, proc.stderr)
    no_display = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = run_play("--policy", "policies/goal.onnx", "--viewer", env=no_display)
    assert proc.returncode == 2 and "needs a display" in proc.stderr


def test_gymnasium_environments_pass_the_checker():
    import gymnasium
    from gymnasium.utils.env_checker import check_env

    from hexa_mjx.engines import gym_envs

    for task, env_id in gym_envs.IDS.items():
        env = gymnasium.make(env_id, render_mode="rgb_array", width=64, height=48)
        check_env(env.unwrapped)
        obs, _ = env.reset(seed=5)
        again, _ = env.reset(seed=5)
        np.testing.assert_array_equal(obs, again)  # a seed fixes the episode's start and goal
        assert obs.shape == (TASKS[task].layout(18)[-1][1],) and env.render().shape == (48, 64, 3)
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert np.isfinite(reward) and not terminated and not truncated
        assert set(info["terms"]) == {k for k, v in env.unwrapped.env.scales.items() if v}
        env.close()


def test_mjx_vector_env_resets_finished_episodes_in_the_same_step():
    from hexa_mjx.engines import gym_envs

    envs = gym_envs.MJXVectorEnv(num_envs=2, task="navigate", episode_length=3)
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (2, 67) and obs.dtype == np.float32
    for t in range(3):
        prev = obs
        obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 18), np.float32))
        assert reward.shape == (2,) and not terminated.any()
    assert truncated.all() and info["_final_obs"].all()
    # The returned observation is the next episode's first: a new goal, the robot back at its start.
    assert not np.allclose(obs, info["final_obs"]) and not np.allclose(obs[:, :2], prev[:, :2])
    with pytest.raises(ValueError, match="num_envs"):
        gym_envs.MJXVectorEnv(num_envs=0)


def test_leg_failure_sweep_covers_every_leg_and_opposite_pairs(tmp_path):
    from hexa_mjx.studies import leg_failure_sweep as leg_failure

    out = tmp_path / "sweep.json"
    assert leg_failure.main(["policies/goal.onnx", "--episodes", "1", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert [r["failed_legs"] for r in rows] == [[], [1], [2], [3], [4], [5], [6], [1, 6], [2, 5], [3, 4]]
    assert rows[0]["speed_share_of_intact"] == 1.0 and rows[0]["success_rate"] == 1.0


def test_robustness_sweep_changes_one_quantity(tmp_path):
    from hexa_mjx.studies import robustness as sweeps

    rows = sweeps.sweep("policies/goal.onnx", "payload", [0.0, 3.0], episodes=1, episode_length=120)
    assert [r["value"] for r in rows] == [0.0, 3.0] and all(r["episodes"] == 1 for r in rows)
    assert sweeps.plot(rows, "payload", tmp_path / "p.png").stat().st_size > 1000
    with pytest.raises(ValueError, match="unknown sweep"):
        sweeps.sweep("policies/goal.onnx", "gravity", [1.0], episodes=1)
    assert sweeps.main(["policies/goal.onnx", "--sweep", "friction", "--values", "-1", "--episodes", "1"]) == 2
    assert sweeps.main(["policies/goal.onnx", "--grid", "gravity=1,2", "--episodes", "1"]) == 2
    assert sweeps.main(["policies/goal.onnx", "--grid", "mass=heavy", "--episodes", "1"]) == 2
    with pytest.raises(SystemExit):  # a sweep and a grid at once
        sweeps.main(["policies/goal.onnx", "--grid", "mass=1", "--sweep", "push", "--values", "1"])


def test_grid_points_set_each_quantity_and_workers_change_nothing():
    from hexa_mjx.deploy import player
    from hexa_mjx.studies import robustness as sweeps
    from hexa_mjx.mdp import terrain

    overrides, ranges = sweeps.settings({"friction": 0.4, "payload": 1.5, "slopes": 5.0, "push": 0.5})
    env = player.env_for(player.OnnxPolicy("policies/goal.onnx"), **overrides)
    env.ranges = ranges
    nominal_mass = env.mj_model.body_subtreemass[env.robot.torso]
    env.reset(seed=0)
    torso = env.robot.torso
    assert env.mj_model.body_subtreemass[torso] == pytest.approx(nominal_mass + 1.5)
    assert np.all(env.mj_model.geom_friction[:, 0] == pytest.approx(0.4)) and env.config.push_speed == 0.5
    heights = env.robot.terrain.heights  # half the full slope: 5 degrees off the ridges
    assert np.degrees(np.arctan(np.abs(np.diff(heights, axis=1)).max() / terrain.CELL)) == pytest.approx(5.0, abs=0.5)
    for bad, match in [({"bumps": 0.05}, "from 0 to 0.04 m"), ({"bumps": 0.01, "steps": 0.01}, "one terrain"),
                       ({"mass": -1.0}, "low <= high")]:
        with pytest.raises(ValueError, match=match):
            sweeps.settings(bad)
    points = [{"mass": 0.8}, {"mass": 1.2}]
    alone = sweeps.evaluate_points("policies/goal.onnx", points, episodes=2, episode_length=60)
    pooled = sweeps.evaluate_points("policies/goal.onnx", points, episodes=2, workers=2, episode_length=60)
    assert alone == pooled and [r["mass"] for r in alone] == [0.8, 1.2] and alone[0]["episodes"] == 2


def test_a_policy_file_never_names_a_file_to_open(tmp_path):
    arrays = {"mean": np.zeros(52, np.float32), "std": np.ones(52, np.float32), "squash": False,
              "layers": [(np.ones((52, 18), np.float32), np.zeros(18, np.float32))]}
    meta = export.read_metadata(POLICIES / "goal.onnx")
    crafted = tmp_path / "crafted.onnx"
    crafted.write_bytes(export.onnx_model(arrays, {**meta, "env_config": {**meta["env_config"],
                                                                           "model_path": "../../../../etc/passwd"}})
                        .SerializeToString())
    env = player.env_for(player.OnnxPolicy(crafted))
    assert Path(env.config.model_path) == robot.MODEL_XML
