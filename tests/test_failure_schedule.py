"""The training schedule of leg failures: a start step, and legs drawn by what losing them costs."""

import json

import jax
import jax.numpy as jp
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.mdp import failure_schedule as fs
from hexa_mjx.robot import kinematics
from hexa_mjx.training import loop as training
from hexa_mjx.engines import wrappers
from hexa_mjx.training.config import ConfigError, parse_args, validate

BATCH, EPISODE = 6, 4


def test_a_leg_is_drawn_by_the_square_of_its_deficit_beside_a_uniform_share(monkeypatch):
    intact, legs = [10.0, 1.0], [[9.0, 1.0]] * 6  # goals per episode 10 intact, 9 with each leg failed
    np.testing.assert_allclose(fs.leg_probabilities(jp.asarray([intact, *legs])), np.full(6, 1 / 6), rtol=1e-6)
    legs[2] = [8.0, 2.0]  # leg 3: 4 goals per episode, a deficit of 0.6 against 0.1 for the others
    share = fs.UNIFORM_SHARE
    p = np.asarray(fs.leg_probabilities(jp.asarray([intact, *legs])))
    np.testing.assert_allclose(p[2], share / 6 + (1 - share) * 0.36 / (0.36 + 5 * 0.01), rtol=1e-5)
    legs[0] = [12.0, 1.0]  # better than intact: weighed by the floor
    p = np.asarray(fs.leg_probabilities(jp.asarray([intact, *legs])))
    np.testing.assert_allclose(p[0], share / 6 + (1 - share) * fs.FLOOR ** 2 / (fs.FLOOR ** 2 + 0.36 + 4 * 0.01),
                               rtol=1e-5)
    assert p.min() >= share / 6 - 1e-7  # every leg keeps its uniform share
    monkeypatch.setattr(fs, "UNIFORM_SHARE", 0.0)  # by deficit alone
    p = np.asarray(fs.leg_probabilities(jp.asarray([intact, *legs])))
    np.testing.assert_allclose(p[2], 0.36 / (fs.FLOOR ** 2 + 0.36 + 4 * 0.01), rtol=1e-5)


def test_finished_episodes_are_summed_by_condition():
    failed = jp.asarray([[0, 0, 1], [0, 0, 0], [0, 0, 1], [1, 0, 0]], jp.float32)
    goals = jp.asarray([2.0, 5.0, 4.0, 7.0])
    ended = jp.asarray([True, True, True, False])  # the last is still running: not counted
    np.testing.assert_allclose(fs.episode_stats(failed, goals, ended), [[5, 1], [0, 0], [0, 0], [6, 2]])


@pytest.fixture(scope="module")
def scheduled():
    env = hexa_mjx.make_env(task="navigate", leg_failure="random", leg_failure_rate=1.0, episode_length=EPISODE)
    wrapped = wrappers.wrap_for_training(env, episode_length=EPISODE, failure_schedule=dict(
        start_after=EPISODE + 2, adaptive=True))
    return wrapped, jax.jit(wrapped.step)


def summary(state):
    """The schedule's row figures, as training reads them: one device holding the whole batch."""
    return fs.schedule_summary(jax.tree.map(lambda x: np.asarray(x)[None], state.info))


def test_no_leg_fails_before_the_start_then_every_episode_has_one(scheduled):
    env, step = scheduled
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(0), BATCH))
    assert float(state.info["failed_legs"].sum()) == 0  # the rate is 1, but not yet
    counts = []
    for t in range(1, 2 * EPISODE + 1):
        before = np.asarray(state.info["leg_failure_stats"][0])
        state = step(state, jp.zeros((BATCH, 18)))
        counts.append(np.asarray(state.info["leg_failure_stats"][0])[:, 1] - fs.DECAY * before[:, 1])
        if t == EPISODE:  # the first episodes end before the start: the next ones are intact too
            assert float(state.info["failed_legs"].sum()) == 0
            assert summary(state)["leg_failure/rate"] == 0.0
    np.testing.assert_array_equal(state.info["failed_legs"].sum(-1), np.ones(BATCH))  # one leg each
    counts = np.asarray(counts)
    # Both batches of episodes that ended were intact, and nothing else ended.
    ends = [EPISODE - 1, 2 * EPISODE - 1]
    np.testing.assert_allclose(counts[ends], [[BATCH, 0, 0, 0, 0, 0, 0]] * 2, atol=1e-4)
    np.testing.assert_allclose(np.delete(counts, ends, axis=0), 0, atol=1e-4)
    row = summary(state)
    assert row["leg_failure/rate"] == 1.0
    assert abs(sum(row[f"leg_failure/p_leg{k}"] for k in range(1, 7)) - 1) < 1e-5
    assert 0.0 <= row["leg_failure/progress_intact"] < 1.0  # the prior (1 goal), pulled down by goalless episodes


def test_a_command_task_weighs_each_leg_by_the_metres_walked_along_its_commands():
    """Velocity commands have no goals: an episode's progress is the metres it walked along the
    commanded direction, summed here from each step's state, by condition, at the episode's end."""
    env = hexa_mjx.make_env(task="velocity", leg_failure="random", leg_failure_rate=1.0, episode_length=EPISODE)
    wrapped = wrappers.wrap_for_training(env, episode_length=EPISODE, failure_schedule=dict(start_after=0,
                                                                                            adaptive=True))
    step = jax.jit(wrapped.step)
    state = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(1), BATCH))
    failed = np.asarray(state.info["failed_legs"])
    assert (failed.sum(-1) == 1).all()  # one leg each, from the first episode
    walked = np.zeros(BATCH)
    actions = 0.8 * jp.sin(jp.arange(BATCH * 18, dtype=jp.float32).reshape(BATCH, 18))
    for _ in range(EPISODE):
        for i in range(BATCH):  # metres along the command, at the velocity each step starts from
            data = jax.tree.map(lambda x: x[i], state.pipeline_state)
            wanted = env.task.commanded(np.asarray(data.userdata), np.asarray(data.qpos), float(env.heading(data)))[:2]
            heading = kinematics.yaw(np.asarray(data.qpos[3:7]))
            c, s = np.cos(heading), np.sin(heading)  # the torso's velocity turned into the heading frame
            velocity = np.array([[c, s], [-s, c]]) @ np.asarray(data.qvel[:2])
            speed = np.linalg.norm(wanted)
            walked[i] += env.dt * (wanted @ velocity) / max(speed, 1e-6)
        before = np.asarray(state.info["leg_failure_stats"][0])
        state = step(state, actions)
    assert (np.asarray(state.info["t"]) == 0).all()  # every episode ended on the last step
    np.testing.assert_allclose(state.info["leg_failure_walked_m"], 0.0)  # and its count started afresh
    added = np.asarray(state.info["leg_failure_stats"][0]) - fs.DECAY * before
    expected = np.zeros((7, 2))
    for i in range(BATCH):
        expected[1 + failed[i].argmax()] += [walked[i], 1.0]
    np.testing.assert_allclose(added, expected, atol=1e-5)
    assert np.abs(walked).max() > 1e-3  # the sums compared above are not all zero


def test_a_task_without_goals_or_commands_has_nothing_to_weigh_legs_by(tmp_path, monkeypatch):
    from hexa_mjx.tasks.stand import StandTask

    monkeypatch.setattr(StandTask, "has_goal", False)  # every task has one or the other: one without either
    with pytest.raises(ConfigError, match="neither goals nor commands"):
        validate(parse_args(["--task", "stand", "--leg_failure", "random", "--leg_failure_adaptive",
                             "--run_dir", str(tmp_path / "run")]), writes=False)


def test_evaluation_environments_are_not_scheduled():
    env = hexa_mjx.make_env(task="navigate", leg_failure="random")
    wrap = training.wrap_env_fn(env, failure_schedule=dict(start_after=10, adaptive=True))
    assert isinstance(wrap(env), fs.LegFailureSchedule)  # the training environments
    # RunEvaluator wraps with the run's wrappers, without a schedule: failures as configured.
    assert not isinstance(training.wrap_env_fn(env)(env), fs.LegFailureSchedule)


@pytest.mark.parametrize("flags, message", [
    (["--leg_failure_adaptive"], "add it or drop them"),
    (["--leg_failure_after", "1000"], "add it or drop them"),
    (["--leg_failure", "random", "--leg_failure_adaptive", "--leg_failure_weights", "1", "1", "3", "3", "1", "1"],
     "keep one of the two"),
    (["--leg_failure", "random", "--leg_failure_after", "-5"], "0 or more"),
])
def test_bad_schedules_are_refused_before_compiling(flags, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        validate(parse_args([*flags, "--run_dir", str(tmp_path / "run")]), writes=False)


def test_the_schedule_is_logged_in_the_runs_rows(tmp_path):
    from hexa_mjx.training.progress import Logger

    cfg = parse_args(["--leg_failure", "random", "--leg_failure_adaptive", "--run_dir", str(tmp_path)])
    logger = Logger(tmp_path, cfg, 0)
    logger(16384, {"leg_failure/p_leg3": 0.4, "leg_failure/progress_intact": 9.5, "other/thing": 1.0})
    logger.close()
    row = json.loads((tmp_path / "metrics.jsonl").read_text().splitlines()[-1])
    assert row["leg_failure/p_leg3"] == 0.4 and row["leg_failure/progress_intact"] == 9.5 and "other/thing" not in row


def test_the_start_is_counted_per_environment_from_the_checkpoint():
    cfg = parse_args(["--leg_failure", "random", "--leg_failure_after", "1000", "--num_envs", "256"])
    assert training.failure_schedule_for(cfg, 0) == dict(start_after=4, adaptive=False)  # 1000 / 256, rounded up
    assert training.failure_schedule_for(cfg, 600)["start_after"] == 2  # 400 steps left on resume
    assert training.failure_schedule_for(cfg, 5000)["start_after"] == 0
    assert training.failure_schedule_for(parse_args(["--leg_failure", "random"]), 0) is None
