"""train.py and eval.py end to end (tiny budgets, in subprocesses), checkpoints, and bad input."""

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import imageio.v2 as imageio
import jax
import numpy as np
import pytest

from hexa_mjx.training import checkpoints, config, networks, loop as training
from hexa_mjx.evaluation import evaluate as evaluation, video
from hexa_mjx.evaluation import table
from hexa_mjx.tasks import TASKS

from conftest import NOISE, ROOT, TINY, run  # noqa: E402  (the shared tiny run: tests/conftest.py)


def rows(run_dir):
    return [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]


def test_train_writes_run_directory(trained):
    run_dir, proc = trained
    assert [r["step"] for r in rows(run_dir)] == [0, 64]
    assert {"episode_return", "final_distance", "success_rate", "goal_bonus", "fall_rate"} <= set(rows(run_dir)[-1])
    assert [step for step, _ in checkpoints.list_checkpoints(run_dir)] == [64]
    assert list((run_dir / "tb").glob("events.out.tfevents.*"))
    assert "success" in proc.stdout and "steps/s" in proc.stdout and "done:" in proc.stdout
    # Compiling is announced, and its end (the first training update) reported.
    assert "compiling the environment and evaluation programs" in proc.stdout
    assert re.search(r"training compiled and its first update ran in \d+ s", proc.stdout)
    # The untrained params (step 0) and the trained ones (64) are evaluated by one program.
    assert proc.stderr.count("Compiling episodes (") == 1, proc.stderr[-3000:]
    # One CPU device per core, as many as divide the 8 envs and the batch of 8.
    devices = max(d for d in range(1, len(os.sched_getaffinity(0)) + 1) if 8 % d == 0)
    assert f"on 8 envs ({devices} cpu device" in proc.stdout


def test_training_program_is_compiled_once_and_kept_in_the_cache(trained, cache_env):
    """hexa_mjx.training.ppo's update has no host callback, so it can be kept (brax's training epoch,
    with the progress line's and Adam's callbacks, was compiled afresh by every run): the run keeps
    its compiled reset, update and evaluation in the cache folder's programs/ (program_store)."""
    _, proc = trained
    assert proc.stderr.count("Compiling update (") == 1, proc.stderr[-3000:]
    kept = Path(cache_env["JAX_COMPILATION_CACHE_DIR"]) / "programs"
    assert all(list(kept.glob(f"{name}-*.bin")) for name in ("reset", "update", "evaluation"))


def test_saved_config_round_trips(trained):
    run_dir, _ = trained
    saved = config.load_config(run_dir)
    flags = config.parse_args([*TINY, *NOISE, "--num_timesteps", "64", "--seed", "3", "--run_dir", str(run_dir)])
    assert saved == flags and saved.start_yaw_noise == 0.1
    assert saved.seed == 3 and saved.hidden == [256, 256] and saved.discount == 0.99


def test_init_from_fine_tunes_from_another_runs_params(trained, tmp_path, cache_env):
    source = tmp_path / "source"  # a copy, deleted below
    shutil.copytree(trained[0], source)
    with pytest.raises(config.ConfigError, match="hidden \\[256, 256\\] there, \\[32, 32\\] here"):
        config.validate(config.TrainConfig(init_from=str(source), hidden=[32, 32], run_dir=str(tmp_path / "bad")))
    run_dir = tmp_path / "tuned"
    proc = run("train.py", *TINY, *NOISE, "--num_timesteps", "64", "--seed", "4", "--run_dir", str(run_dir),
               "--init_from", str(source), "--no_eval_at_start", env=cache_env)
    assert f"starting from the params of {source} (its step 64)" in proc.stdout
    # No evaluation before training: training compiles first, and the first row is after it.
    assert [r["step"] for r in rows(run_dir)] == [64]
    announced = [proc.stdout.index(line) for line in ("compiling the environment and training programs",
                                                      "training compiled and its first update",
                                                      "evaluation compiled and run in")]
    assert announced == sorted(announced), proc.stdout
    cfg = config.load_config(run_dir)
    env = config.make_env_for(cfg)
    template = networks.init_params(cfg, env)
    _, before, _, _ = checkpoints.load_latest(source, template)
    _, after, _, _ = checkpoints.load_latest(run_dir, template)
    # The observation normalizer's sample count (brax's UInt64: hi and lo words) carries on from the
    # source's: a fresh start would count only this run's own samples, as many as the source's.
    count_before, count_after = ((int(p[0].count.hi) << 32) + int(p[0].count.lo) for p in (before, after))
    assert count_after == 2 * count_before > 0
    # Resuming it needs only its own checkpoints, not the source's.
    shutil.rmtree(source)
    config.validate(dataclasses.replace(cfg, resume=True))


# Resuming after crashes at chosen moments (before the first checkpoint among them): tests/test_crashes.py.


def test_runs_from_before_a_new_setting_resume(tmp_path):
    """A config.json written before a setting existed reads as that setting's default."""
    cfg = config.validate(config.TrainConfig(run_dir=str(tmp_path / "old")))
    old = dataclasses.asdict(cfg)
    del old["start_joint_noise"], old["start_yaw_noise"]
    (tmp_path / "old").mkdir(exist_ok=True)  # validate made the run's folder
    (tmp_path / "old" / "config.json").write_text(json.dumps(old))
    config.validate(dataclasses.replace(cfg, resume=True))
    with pytest.raises(config.ConfigError, match="holds a different run: start_yaw_noise=0.0"):
        config.validate(dataclasses.replace(cfg, resume=True, start_yaw_noise=0.2))


def test_resumed_run_keeps_its_evaluation_spacing():
    cfg = config.TrainConfig(num_timesteps=2_000_000, num_evals=10)
    assert training.evals_for(cfg, 2_000_000) == 10  # a fresh run: as asked
    assert training.evals_for(cfg, 1_000_000) == 6  # half the run left: about half the evaluations
    assert training.evals_for(cfg, 10_000) == 2  # the initial one and one at the end


def test_checkpoint_restores_same_actions(tmp_path):
    cfg = config.TrainConfig(hidden=[32, 32])
    env = config.make_env_for(cfg)
    normalizer, policy, value = networks.init_params(cfg, env)
    key = jax.random.PRNGKey(7)
    # Non-trivial normalizer statistics, so a normalizer lost in saving would change the actions.
    normalizer = normalizer.replace(mean=jax.random.normal(key, normalizer.mean.shape),
                                    std=1 + jax.random.uniform(key, normalizer.std.shape))
    params = (normalizer, policy, value)
    obs = jax.random.normal(jax.random.PRNGKey(1), (5, env.observation_size))
    before = networks.make_inference(cfg, env, params)(obs, key)
    path = checkpoints.save_checkpoint(tmp_path, 1234, params)
    step, restored = checkpoints.load_checkpoint(path, networks.init_params(cfg, env))
    after = networks.make_inference(cfg, env, restored)(obs, key)
    assert step == 1234
    np.testing.assert_array_equal(np.asarray(before), np.asarray(after))
    fresh = networks.make_inference(cfg, env, networks.init_params(dataclasses.replace(cfg, seed=1), env))(obs, key)
    assert not np.allclose(before, fresh)  # the comparison can tell different params apart


@pytest.mark.parametrize("noise_std", [1.0, 0.4])
def test_init_noise_std_sets_the_untrained_policys_action_noise(noise_std):
    cfg = config.TrainConfig(hidden=[8, 8], init_noise_std=noise_std)
    env = config.make_env_for(cfg)
    params = networks.init_params(cfg, env)
    obs = jax.numpy.zeros((4096, env.observation_size))
    mean = networks.make_inference(cfg, env, params)(obs, jax.random.PRNGKey(0))
    sampled = networks.make_inference(cfg, env, params, deterministic=False)(obs, jax.random.PRNGKey(1))
    np.testing.assert_allclose(np.std(np.asarray(sampled - mean)), noise_std, rtol=0.03)


def test_reselection_evaluates_the_last_checkpoints_again_and_best_follows(trained, tmp_path, cache_env):
    from hexa_mjx.tasks import task_class
    from hexa_mjx.training import checks, reselection, selection

    run_dir = tmp_path / "run"
    shutil.copytree(trained[0], run_dir)
    run("train.py", "--run_dir", str(run_dir), "--resume", "--num_timesteps", "192", "--num_evals", "3", env=cache_env)
    assert [s for s, _ in checkpoints.list_checkpoints(run_dir)] == [64, 128, 192]
    reselect = [sys.executable, "-m", "hexa_mjx.training.reselection", str(run_dir), "--last", "2", "--episodes", "4"]
    proc = subprocess.run(reselect, capture_output=True, text=True, cwd=ROOT, env=cache_env, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = reselection.read_selection(run_dir)
    assert [(r["step"], r["episodes"], r["seed"]) for r in rows] == [(128, 4, 4), (192, 4, 4)]  # seed 3's run: 4
    cfg = config.load_config(run_dir)
    scores = [task_class(cfg.task).selection_score(r, checks.run_scales(cfg)) for r in rows]
    chosen = rows[1]["step"] if scores[1] >= scores[0] else rows[0]["step"]
    assert selection.best_step(run_dir)[0] == chosen
    assert f"is now step {chosen:,}" in proc.stdout
    # the same episodes again: the same figures
    again = subprocess.run(reselect, capture_output=True, text=True, cwd=ROOT, env=cache_env, timeout=900)
    assert again.returncode == 0, again.stderr
    assert reselection.read_selection(run_dir) == rows


def test_eval_writes_video_and_metrics(trained, cache_env, tmp_path):
    run_dir, _ = trained
    out = tmp_path / "eval"
    proc = run("eval.py", "--ckpt", str(run_dir), "--episodes", "3", "--out", str(out), "--start_yaw_noise", "0.2",
               env=cache_env)
    assert "success rate" in proc.stdout and "fall rate" in proc.stdout
    assert "RuntimeWarning" not in proc.stderr  # the video encoder's os.fork() warning stays off the console
    result = json.loads((out / "metrics.json").read_text())
    # The run's joint noise, the command line's yaw noise.
    assert (result["config"]["start_joint_noise"], result["config"]["start_yaw_noise"]) == (0.05, 0.2)
    assert result["step"] == 64 and result["summary"]["episodes"] == 3
    assert {"success_rate", "final_distance_mean", "final_distance_median", "min_distance_mean", "goal_bonus_mean",
            "return_mean", "fall_rate", "mean_speed"} <= set(result["summary"])
    assert result["summary"]["min_distance_mean"] <= result["summary"]["final_distance_mean"]
    terms = result["summary"]["reward_terms"]
    assert {"goal_approach", "body_contact", "contact_quality", "height"} <= set(terms)
    assert terms["body_contact"] <= 0 and terms["height"] < 0
    before = result["summary"]["contacts_before_goal"]
    assert list(before) == list(evaluation.CONTACT_GROUPS) and before["feet"] > 0  # it starts on its feet
    # 20 steps never reach the goal: no episode has an "after the goal" phase.
    assert result["summary"]["contacts_after_goal"] is None and result["summary"]["steps_to_goal_mean"] is None
    assert "floor contacts per step, before goal" in proc.stdout
    assert result["config"]["max_contact_points"] == 0 and "floor contact points at once, most" in proc.stdout
    assert 0 < result["summary"]["contact_points_max"] <= 40
    # 20 steps are too few to see a stride: the gait analysis says so instead of inventing one.
    assert result["summary"]["gait"]["class"] == "irregular" and "gait class" in proc.stdout
    assert (out / "gait.png").stat().st_size > 1000 and len(result["per_episode"]["gait_class"]) == 3
    video = out / "episode_0.mp4"
    assert video.stat().st_size > 1000
    frames = np.array([f for f in imageio.get_reader(video)])
    assert len(frames) == 11  # start frame + every 2nd of 20 control steps: 30 frames/s at 60 Hz control
    assert np.abs(frames[0].astype(float) - frames[-1].astype(float)).mean() > 1.0  # the picture changes


def test_episode_table_phases_average_over_episodes_that_have_them():
    """Two 4-step episodes: the first reaches the goal at its second step, the second never does."""
    env_config = SimpleNamespace(success_radius=0.5, max_contact_points=3)
    env = SimpleNamespace(config=env_config, dt=0.1, task=TASKS["goal"](env_config, None))
    T, N = 4, 2
    contacts = np.zeros((T, N, len(evaluation.CONTACT_GROUPS)))
    contacts[:, 0, 3] = [1, 2, 2, 2]  # feet of episode 0: 1 before the goal, 2 after
    contacts[:, 1, 2] = [3, 3, 3, 3]  # shins of episode 1, which never gets there
    traj = {"alive": np.ones((T, N)), "distance": np.array([[1.0, 1.0], [0.4, 0.9], [0.3, 0.8], [0.6, 0.7]]),
            "qpos": np.zeros((T, N, 7)), "goal_bonus": np.zeros((T, N)), "reward": np.ones((T, N)),
            "fell": np.zeros((T, N)), "nonfinite": np.zeros((T, N)), "contacts": contacts,
            "success": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 0.0]]),  # within 0.5 m, so far
            "reward/body_contact": -contacts[..., 2]}
    summary = evaluation.episode_table(env, np.zeros((N, 7)), traj)["summary"]
    assert summary["success_rate"] == 0.5 and summary["steps_to_goal_mean"] == 1.0
    assert summary["contacts_after_goal"] == {"torso": 0.0, "hip and knee links": 0.0, "shins": 0.0, "feet": 2.0}
    assert summary["contacts_before_goal"] == {"torso": 0.0, "hip and knee links": 0.0, "shins": 1.5, "feet": 0.5}
    assert summary["body_contact_before_goal_mean"] == -6.0  # (0 + -12) / 2
    # Episode 1 has 3 points on the floor at every step: as many as this physics keeps.
    assert summary["contact_points_max"] == 3 and summary["steps_at_contact_cap"] == 4 and summary["steps"] == 8
    assert re.search(r"floor contact points at once, most +3 \(physics keeps 3; at that cap in 4 of 8 steps\)",
                     table.format_table(summary))
    assert re.search(r"steps to the goal, mean of successes +1\n", table.format_table(summary))


def test_contact_groups(env):
    from hexa_mjx.robot import constants as robot

    m, groups = env.mj_model, evaluation.contact_groups(env)
    assert groups[m.geom(robot.TORSO_GEOM).id] == 0 and groups[m.geom(robot.FLOOR_GEOM).id] == 0
    for leg in robot.LEGS:
        foot = m.geom(robot.foot_geom(leg)).id
        assert groups[foot] == 3
        shin = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.geom_bodyid[foot] and g != foot]
        assert shin and all(groups[g] == 2 for g in shin)
    assert sum(groups == 1) == 12  # a hip and a knee servo per leg
    assert sum(groups == 2) == sum(groups == 3) == 6


# train.py's and eval.py's bad input (run dirs, navigation flags among it): tests/test_bad_input.py.


@pytest.mark.parametrize("script", [["train.py"], ["eval.py", "--ckpt", "policies/goal"],
                                    ["play.py", "--policy", "policies/goal.onnx"]])
def test_an_unusable_mujoco_gl_is_one_line(script):
    proc = run(*script, env={**os.environ, "MUJOCO_GL": "bogus"}, check=False)
    assert proc.returncode == 2 and proc.stderr.startswith("error: MUJOCO_GL=bogus is not one of egl, osmesa, glfw")
    assert "Traceback" not in proc.stderr


def test_eval_rejects_corrupted_checkpoint(trained, tmp_path):
    run_dir, _ = trained
    broken = tmp_path / "broken"
    subprocess.run(["cp", "-r", str(run_dir), str(broken)], check=True)
    (ckpt,) = [p for _, p in checkpoints.list_checkpoints(broken)]
    for f in (ckpt / "params").rglob("*"):
        if f.is_file():
            f.write_bytes(b"garbage")
    proc = run("eval.py", "--ckpt", str(broken), "--no-video", check=False)
    assert proc.returncode == 2 and "is unreadable" in proc.stderr and "use an earlier checkpoint" in proc.stderr
    proc = run("eval.py", "--ckpt", str(tmp_path / "nowhere"), check=False)
    assert proc.returncode == 2 and "neither a run directory" in proc.stderr


def test_missing_opengl_names_the_package(env, monkeypatch, tmp_path):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    with pytest.raises(RuntimeError, match="apt-get install libegl1 libegl-mesa0 libosmesa6"):
        video.render_video(env, np.zeros((2, env.mj_model.nq)), tmp_path / "x.mp4", np.zeros((2, 2)))


def test_a_render_worker_draws_the_frames_this_process_would(env):
    """render_video splits a long video over worker processes: their frames are this process's."""
    qpos = np.tile(np.asarray(env.qpos0), (3, 1))
    qpos[:, 0] += [0.0, 0.3, 0.6]
    frames = [(q, np.array([1.0, 0.5]), (0.5, 0.0, 0.3)) for q in qpos]
    draw = dict(corners=None, width=64, height=48, shadows=False)
    here = video.render_frames(env.mj_model, frames, **draw)
    there = video.finish_render_worker(video.start_render_worker(env.mj_model, frames, draw), len(frames), 48, 64)
    assert here.shape == (3, 48, 64, 3) and here.std() > 0 and not np.array_equal(here[0], here[2])
    np.testing.assert_array_equal(there, here)


def test_a_policy_runs_on_another_tasks_goals_with_its_own_observation():
    goal_run = config.TrainConfig()
    baseline = config.make_env_for(goal_run, task="navigate")  # the report's policy on navigation goals
    assert baseline.name == "navigate" and baseline.observation_size == 52
    nav_run = config.TrainConfig(task="navigate", reward="navigate", goal_max_distance=2.0)
    on_report_goals = config.make_env_for(nav_run, task="goal")  # its own observation, on the report's goal
    assert on_report_goals.name == "goal" and on_report_goals.observation_size == 67
    far = config.make_env_for(nav_run, goal_min_distance=4.0, goal_max_distance=4.0)
    assert far.config.goal_distance_cap == 2.0  # the policy keeps the distance cap it trained with


def test_waypoint_rollout_records_arrivals():
    """A path whose first two waypoints lie inside the start's radius: both are completed at once."""
    env = config.make_env_for(config.TrainConfig(task="navigate", reward="navigate", episode_length=12),
                              waypoints=((0.0, 0.0), (0.2, 0.0), (5.0, 0.0)))
    start, traj = evaluation.rollout(env, lambda obs, key: jax.numpy.zeros((obs.shape[0], 18)), 2)
    np.testing.assert_array_equal(traj["goals_reached"][:3, 0], [1, 1, 0])
    np.testing.assert_allclose(traj["goal"][1, 0], env.qpos0[:2] + [0.2, 0.0], atol=1e-6)
    summary = evaluation.episode_table(env, start, traj)["summary"]["waypoints"]
    assert summary["completed_rate"] == 0.0 and summary["arrival_s_mean"][:2] == pytest.approx([env.dt, 2 * env.dt])
    assert summary["arrival_s_mean"][2] is None
