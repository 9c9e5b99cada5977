"""The curriculum: the level rules (navigation's goals, the velocity task's terrain or commands), goal ranges
per level, levels kept across episodes and reported to the host."""

import jax
import jax.numpy as jp
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.training import config
from hexa_mjx.mdp import curriculum
from hexa_mjx.evaluation import nav_metrics
from hexa_mjx.engines import wrappers
from hexa_mjx.engines.mjx_env import DRAWS
from hexa_mjx.mdp.config import EnvConfig
from hexa_mjx.tasks.velocity import VelocityTask

LEVELS = 4


def _next_level(task, level, completed=False, over=False, fell=False, goals=0, asked=0.0, walked=0.0):
    walking = {"asked_m": jp.float32(asked), "walked_m": jp.float32(walked)}
    up, down = task.level_moves(jp.bool_(completed), jp.bool_(over), jp.bool_(fell), jp.int32(goals), walking,
                                 jp.zeros(4))
    return int(curriculum.next_level(jp.int32(level), LEVELS, up, down))


def test_level_rule(cur_env):
    task = cur_env.task
    assert _next_level(task, 1, completed=True, goals=1) == 2  # a goal reached: up
    assert _next_level(task, LEVELS - 1, completed=True, goals=1) == LEVELS - 1  # no level above the top
    assert _next_level(task, 2, over=True, fell=True, goals=1) == 1  # a fall: down
    assert _next_level(task, 0, over=True, fell=True) == 0  # no level below the bottom
    assert _next_level(task, 2, over=True, goals=1) == 2  # the time ran out after a goal: kept
    assert _next_level(task, 2, over=True) == 1  # ... without a goal: down
    assert _next_level(task, 2, goals=0) == 2  # mid-episode: kept


def test_velocity_levels_move_by_the_commanded_path_walked():
    task = VelocityTask(EnvConfig(task="velocity"), robot=None)
    assert _next_level(task, 2, over=True, asked=5.0, walked=4.0) == 3  # walked 80% of it to the end: up
    assert _next_level(task, 2, over=True, asked=5.0, walked=2.0) == 2  # walked 40%: kept
    assert _next_level(task, 2, over=True, asked=5.0, walked=0.1) == 1  # stood still: down
    assert _next_level(task, 2, over=True, fell=True, asked=5.0, walked=4.5) == 1  # a fall: down
    assert _next_level(task, 2, asked=5.0, walked=4.5) == 2  # mid-episode: kept


@pytest.mark.parametrize("terrain, shares", [("flat", [0.25, 0.5, 0.75, 1.0]), ("bumps", [1.0] * LEVELS)])
def test_velocity_command_ranges_open_with_the_level_on_flat_ground_only(terrain, shares):
    """On flat ground the levels grade the commands (legged_gym's command curriculum): level l
    draws from (l + 1) / N of each range; on a terrain they grade the ground and every command is
    drawn from the full ranges; without a curriculum, the draw is the task's as before."""
    cfg = EnvConfig(task="velocity", terrain=terrain, curriculum_levels=LEVELS, command_zero_share=0.0)
    task, plain = VelocityTask(cfg, robot=None), VelocityTask(EnvConfig(task="velocity", command_zero_share=0.0), None)
    keys = jax.random.split(jax.random.PRNGKey(1), 400)
    draw = jax.jit(jax.vmap(lambda key, lvl: task.draw_command(DRAWS, key, lvl)[0], in_axes=(0, None)))
    full = np.asarray(jax.vmap(lambda key: plain.draw_command(DRAWS, key)[0])(keys))
    for level, share in enumerate(shares):
        np.testing.assert_allclose(np.asarray(draw(keys, jp.int32(level)))[:, :3], full[:, :3] * share, rtol=1e-5, atol=1e-6)
    assert np.abs(full[:, 0]).max() > 0.5  # the full draw reaches past a quarter of the ranges


def test_velocity_episodes_sum_the_path_asked_for_and_walked():
    env = hexa_mjx.make_env(task="velocity", terrain="bumps", curriculum_levels=LEVELS, episode_length=4,
                            command_zero_share=0.0)
    state, step = jax.jit(env.reset)(jax.random.PRNGKey(0)), jax.jit(env.step)
    asked, data = 0.0, state.pipeline_state
    for _ in range(3):  # standing still: every metre asked for, none walked but the torso's sway
        wanted = env.task.commanded(data.userdata, data.qpos, env.heading(data))
        state = step(state, jp.zeros(18))
        data = state.pipeline_state
        asked += float(jp.linalg.norm(wanted[:2])) * env.dt
    assert float(state.info["asked_m"]) == pytest.approx(asked, rel=1e-4) and asked > 0
    assert abs(float(state.info["walked_m"])) < 0.1 * asked


@pytest.fixture(scope="module")
def cur_env():
    return hexa_mjx.make_env(task="navigate", curriculum_levels=LEVELS, episode_length=10)


def _bearings_and_distances(env, qpos, level, n=2000):
    draw = jax.jit(jax.vmap(lambda q, key, lvl: env.task.first_goal(q, DRAWS, key, lvl), in_axes=(None, 0, None)))
    goals = np.asarray(draw(qpos, jax.random.split(jax.random.PRNGKey(0), n), jp.int32(level)))
    offset = goals - np.asarray(qpos[:2])
    heading = float(np.degrees(nav_metrics.heading(np.asarray(qpos)[None]))[0])
    bearing = nav_metrics.wrap_deg(np.degrees(np.arctan2(offset[:, 1], offset[:, 0])) - heading)
    return bearing, np.linalg.norm(offset, axis=1)


def test_goal_ranges_open_with_the_level(cur_env):
    turn = 2.0  # rad: the bearings are measured from the torso's heading, not from +x
    qpos = jp.asarray(cur_env.qpos0).at[3:7].set(jp.array([np.cos(turn / 2), 0.0, 0.0, np.sin(turn / 2)]))
    bearing, dist = _bearings_and_distances(cur_env, qpos, 0)
    assert np.abs(bearing).max() <= 45 + 1e-3 and np.abs(bearing).max() > 40  # +-180 x 1/4
    assert dist.min() >= 0.5 - 1e-5 and 1.1 < dist.max() <= 0.5 + 2.5 / 4 + 1e-5
    bearing, dist = _bearings_and_distances(cur_env, qpos, LEVELS - 1)  # the top level: the whole task
    assert np.histogram(bearing, bins=8, range=(-180, 180))[0].min() > 150  # 250 expected per sector
    assert dist.max() > 2.9


def test_training_environments_keep_their_level_and_report_it(cur_env):
    env = wrappers.wrap_for_training(cur_env, episode_length=10)
    step = jax.jit(env.step)
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(1), 3))
    on_torso = jax.vmap(lambda d: cur_env.set_goal(d, d.qpos[:2]))(state.pipeline_state)
    state = step(state.replace(pipeline_state=on_torso), jp.zeros((3, 18)))  # every goal reached: level 1
    np.testing.assert_array_equal(state.info["level"], [1, 1, 1])
    for _ in range(4):
        state = step(state, jp.zeros((3, 18)))
    assert curriculum.level_summary(state.info["level"], LEVELS)["curriculum/level_1"] == 1.0
    for _ in range(5):  # the first episode ends with its goal reached: the level stays
        state = step(state, jp.zeros((3, 18)))
    np.testing.assert_array_equal(state.info["level"], [1, 1, 1])
    offset = jax.vmap(cur_env.goal)(state.pipeline_state) - state.pipeline_state.qpos[:, :2]
    assert np.linalg.norm(offset, axis=1).max() <= 0.5 + 2.5 * 2 / LEVELS + 1e-5  # restarted at level 1
    for _ in range(10):  # standing still, the second episode reaches no goal: down a level
        state = step(state, jp.zeros((3, 18)))
    np.testing.assert_array_equal(state.info["level"], [0, 0, 0])
    summary = curriculum.level_summary(state.info["level"], LEVELS)
    assert summary["curriculum/level_0"] == 1.0 and summary["curriculum/level_mean"] == 0.0
    summary = curriculum.level_summary(np.array([[0, 1], [1, LEVELS - 1]]), LEVELS)  # (devices, environments)
    assert summary["curriculum/level_1"] == 0.5 and summary["curriculum/top_level_share"] == 0.25
    assert summary["curriculum/level_mean"] == (0 + 1 + 1 + LEVELS - 1) / 4


def test_only_random_navigation_goals_and_velocity_terrain_have_a_curriculum():
    with pytest.raises(ValueError, match="the goal task has none"):
        hexa_mjx.make_env(task="goal", curriculum_levels=LEVELS)
    with pytest.raises(ValueError, match="navigate task's random goals only"):
        hexa_mjx.make_env(task="navigate", curriculum_levels=LEVELS, waypoints=[(1, 0)])


def test_evaluation_sees_the_full_task():
    cfg = config.parse_args(["--task", "navigate", "--curriculum_levels", str(LEVELS)])
    assert cfg.curriculum_levels == LEVELS
    assert config.make_env_for(cfg).config.curriculum_levels == 0  # eval.py's and training's evaluations
