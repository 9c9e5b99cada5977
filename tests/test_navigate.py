"""The navigation task: goal draws, heading-frame observation, goal chaining, waypoints, bad input."""

import jax
import jax.numpy as jp
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.evaluation import nav_metrics
from hexa_mjx.robot.kinematics import quat_mul, rotate, yaw
from hexa_mjx.engines.mjx_env import DRAWS
from hexa_mjx.engines.native import NativeEnv, NumpyDraws as NativeDraws
from hexa_mjx.mdp import events
from hexa_mjx.mdp.config import EnvConfig
from hexa_mjx import cli
from hexa_mjx.tasks import reward_variants


def _yaw_quat(angle):
    return jp.array([jp.cos(angle / 2), 0.0, 0.0, jp.sin(angle / 2)])


def test_sizes_and_reward_table(nav_env):
    assert (nav_env.observation_size, nav_env.action_size) == (67, 18)
    assert nav_env.config.reward == "navigate" and nav_env.scales["goal_reached"] > 0
    report = reward_variants()["goal_directed"]
    for term in ("stability", "height", "energy", "contact_quality", "termination"):
        assert nav_env.scales[term] == report[term]  # shaping shared with the report
    assert nav_env.scales["body_contact"] < report["body_contact"] < 0  # the same term, weighted more


def test_goals_and_headings_cover_every_direction(nav_env, nav_reset):
    states = nav_reset(jax.random.split(jax.random.PRNGKey(0), 512))
    qpos = np.asarray(states.pipeline_state.qpos)
    goal = np.asarray(jax.vmap(nav_env.goal)(states.pipeline_state))
    offset = goal - qpos[:, :2]
    dist = np.linalg.norm(offset, axis=1)
    assert dist.min() >= 0.5 - 1e-5 and dist.max() <= 3.0 + 1e-5 and dist.std() > 0.5
    bearing = nav_metrics.wrap_deg(np.degrees(np.arctan2(offset[:, 1], offset[:, 0]) - nav_metrics.heading(qpos)))
    counts = np.bincount(nav_metrics.sector_of(bearing), minlength=8)
    assert counts.min() > 35, counts  # 64 expected per sector
    headings = np.degrees(nav_metrics.heading(qpos))
    assert np.histogram(headings, bins=8, range=(-180, 180))[0].min() > 35  # start headings all round
    np.testing.assert_allclose(states.obs[:, 2], dist, atol=1e-5)  # observed distance, within range


def test_observation_does_not_depend_on_heading(nav_env, state_rotated):
    obs, turned = state_rotated
    np.testing.assert_allclose(obs, turned, atol=2e-5)


@pytest.fixture(scope="session")
def state_rotated(nav_env, nav_reset, nav_step):
    """The same moving state, and the whole world turned by 1.1 rad about z."""
    state = jax.tree.map(lambda x: x[0], nav_reset(jax.random.split(jax.random.PRNGKey(3), 1)))
    for _ in range(5):
        state = nav_step(state, jp.full(18, 0.3))
    data = state.pipeline_state
    turn = _yaw_quat(1.1)
    qpos = data.qpos.at[:3].set(rotate(data.qpos[:3], turn)).at[3:7].set(quat_mul(turn, data.qpos[3:7]))
    qvel = data.qvel.at[:3].set(rotate(data.qvel[:3], turn))  # angular velocity is body-frame: unchanged
    goal = rotate(jp.concatenate([nav_env.goal(data), jp.zeros(1)]), turn)[:2]
    turned = nav_env.set_goal(data.replace(qpos=qpos, qvel=qvel), goal)
    observe = jax.jit(nav_env.observe)
    assert abs(float(yaw(qpos[3:7]) - yaw(data.qpos[3:7])) % (2 * np.pi) - 1.1) < 1e-4
    return np.asarray(observe(data)), np.asarray(observe(turned))


def test_far_goals_read_as_the_range_end(nav_env, state0):
    data = nav_env.set_goal(state0.pipeline_state, state0.pipeline_state.qpos[:2] + jp.array([0.0, 7.0]))
    obs = nav_env.observe(data)
    assert float(obs[2]) == pytest.approx(3.0)  # clipped to goal_max_distance
    np.testing.assert_allclose(np.hypot(obs[0], obs[1]), 1.0, atol=1e-5)


@pytest.fixture(scope="session")
def arrival(nav_env, nav_reset, nav_step):
    """Two steps from a state whose goal sits 0.3 m ahead of the torso (inside the 0.5 m radius)."""
    state = jax.tree.map(lambda x: x[0], nav_reset(jax.random.split(jax.random.PRNGKey(5), 1)))
    data = state.pipeline_state
    old_goal = data.qpos[:2] + jp.array([0.3, 0.0])
    state = state.replace(pipeline_state=nav_env.set_goal(data, old_goal))
    first = nav_step(state, jp.zeros(18))
    second = nav_step(first, jp.zeros(18))
    return state, np.asarray(old_goal), first, second


def test_reaching_a_goal_draws_the_next(nav_env, arrival):
    start, old_goal, first, second = arrival
    new_goal = np.asarray(nav_env.goal(first.pipeline_state))
    xy = np.asarray(first.pipeline_state.qpos[:2])
    assert float(first.metrics["goals_reached"]) == 1.0 and int(first.info["goals"]) == 1
    assert float(first.metrics["reward/goal_reached"]) == nav_env.scales["goal_reached"]
    assert not np.allclose(new_goal, old_goal)
    assert 0.5 - 1e-5 <= np.linalg.norm(new_goal - xy) <= 3.0 + 1e-5  # drawn from where the torso is
    assert float(second.metrics["goals_reached"]) == 0.0 and int(second.info["goals"]) == 1


def test_no_spurious_approach_reward_when_the_goal_changes(nav_env, arrival):
    start, old_goal, first, second = arrival
    xy0, xy1, xy2 = (np.asarray(s.pipeline_state.qpos[:2], np.float64) for s in (start, first, second))
    new_goal = np.asarray(nav_env.goal(first.pipeline_state), np.float64)
    scale = nav_env.scales["goal_approach"]
    # The arrival step is scored against the old goal, the next one against the new goal, both ends.
    expected1 = scale * (np.linalg.norm(old_goal - xy0) - np.linalg.norm(old_goal - xy1))
    expected2 = scale * (np.linalg.norm(new_goal - xy1) - np.linalg.norm(new_goal - xy2))
    assert float(first.metrics["reward/goal_approach"]) == pytest.approx(expected1, abs=2e-3)
    assert float(second.metrics["reward/goal_approach"]) == pytest.approx(expected2, abs=2e-3)
    assert abs(expected2) < 10  # millimetres per step, not the metres between the goals


def test_restart_draws_a_new_heading_and_goal(nav_env, state0):
    a, b = (nav_env.restart(state0.pipeline_state, jax.random.PRNGKey(k)) for k in (1, 2))
    assert abs(float(yaw(a.qpos[3:7]) - yaw(b.qpos[3:7]))) > 1e-3
    assert not np.allclose(nav_env.goal(a), nav_env.goal(b))


def test_waypoints_are_followed_in_order_and_the_last_stays():
    env = hexa_mjx.make_env(task="navigate", waypoints=[(0.3, 0.0), (1.0, 0.0)])
    start = np.asarray(env.qpos0[:2])
    data = jax.jit(env.restart)(jax.jit(env.reset)(jax.random.PRNGKey(0)).pipeline_state, jax.random.PRNGKey(1))
    np.testing.assert_allclose(env.goal(data), start + [0.3, 0.0], atol=1e-6)
    for done in (1, 2):  # after the first waypoint, and once the path is done
        goal = env.task.next_goal(data.qpos, env.goal(data), jp.int32(done), DRAWS, jax.random.PRNGKey(2))
        np.testing.assert_allclose(goal, start + [1.0, 0.0])


def test_a_paths_last_waypoint_counts_once_and_stays_the_goal():
    env = NativeEnv(EnvConfig(task="navigate", waypoints=((0.3, 0.0),)))  # inside the radius at the start
    env.reset(seed=0)
    goal = env.goal
    reached = [env.step(np.zeros(env.action_size))[4]["goals_reached"] for _ in range(3)]
    assert reached == [1, 1, 1]
    np.testing.assert_array_equal(env.goal, goal)


@pytest.mark.parametrize("overrides, message", [
    ({"task": "fly"}, "unknown task 'fly'"),
    ({"task": "navigate", "reward": "goal_directed"}, "not one of the navigate task's"),
    ({"reward": "navigate"}, "not one of the goal task's"),
    ({"task": "navigate", "goal_min_distance": 2.0, "goal_max_distance": 1.0}, "0 <= min <= max"),
    ({"task": "navigate", "goal_min_distance": -0.5}, "0 <= min <= max"),
    ({"task": "navigate", "goal_max_distance": float("nan")}, "goal_max_distance must be a finite"),
    ({"goal_distance": float("nan")}, "goal_distance must be a finite"),
    ({"success_radius": -1.0}, "success_radius must be a finite"),
    ({"task": "navigate", "waypoints": [(1.0, float("inf"))]}, "finite"),
])
def test_bad_settings_are_rejected(overrides, message):
    with pytest.raises(ValueError, match=message):
        hexa_mjx.make_env(**overrides)


@pytest.mark.parametrize("text, message", [("", "no waypoints"), ("1,0 1", "is not x,y"), ("a,b", "is not x,y"),
                                           ("1,0,2", "is not x,y"), ("nan,0", "not finite")])
def test_bad_waypoints_are_rejected(text, message):
    with pytest.raises(ValueError, match=message):
        cli.parse_waypoints(text)


def test_waypoints_parse_from_text_and_file(tmp_path):
    assert cli.parse_waypoints("1,0 1,1; 0,1") == [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    path = tmp_path / "square.txt"
    path.write_text("1,0\n1,1\n0,1\n0,0\n")
    assert cli.parse_waypoints(str(path)) == [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.0, 0.0)]


def _straight_walk(goal_xy, heading_rad, steps, speed_per_step, radius=0.5):
    """One episode walking straight from the origin toward `goal_xy`; (qpos, goal, completed)."""
    qpos = np.zeros((steps, 1, 25))
    qpos[:, 0, 3] = np.cos(heading_rad / 2)
    qpos[:, 0, 6] = np.sin(heading_rad / 2)
    direction = np.asarray(goal_xy) / np.linalg.norm(goal_xy)
    qpos[:, 0, :2] = (np.arange(1, steps + 1)[:, None] * speed_per_step) * direction
    goal = np.broadcast_to(np.asarray(goal_xy, float), (steps, 1, 2)).copy()
    dist = np.linalg.norm(goal[:, 0] - qpos[:, 0, :2], axis=1)
    completed = np.zeros((steps, 1))
    completed[np.argmax(dist < radius), 0] = 1
    return qpos, goal, completed


def test_goal_records_from_a_hand_made_walk():
    # Heading 90 deg (facing +y), goal 2 m along +x: the goal is 90 deg to the right (-90).
    qpos, goal, completed = _straight_walk((2.0, 0.0), np.pi / 2, steps=200, speed_per_step=0.01)
    start = qpos[0].copy()
    start[:, :2] = 0.0
    alive = np.ones((200, 1))
    records = nav_metrics.goals_of_episodes(start, qpos, goal, completed, alive, np.array([False]), dt=0.1)
    first = records[0]
    assert first["bearing_deg"] == pytest.approx(-90.0) and first["distance"] == pytest.approx(2.0)
    assert first["reached"] and first["seconds"] == pytest.approx(15.1 * 1.0, abs=0.11)  # 1.5 m at 0.1 m/s
    assert first["heading_error_deg"] == pytest.approx(90.0, abs=1e-6)
    summary = nav_metrics.navigation_summary(records, 1, 0.5, 0.2, 0.5, 3.0)
    assert summary["sectors"]["-90 deg"] == {"goals": 1, "success": 1.0}
    assert summary["bands"]["2.0-2.5 m"] == {"goals": 1, "success": 1.0}
    assert list(nav_metrics.band_of([3.9999999, 4.0, 4.6], 4.0)) == [0, 0, 1]  # float32 draws at the range's start
    assert summary["speed_to_goal"] == pytest.approx(0.1, rel=0.01)
    assert summary["speed_to_goal_body_lengths"] == pytest.approx(0.5, rel=0.01)


def test_falls_walking_to_a_goal_are_told_from_falls_on_a_goal_that_stays():
    # Three walks 2 m toward +x at 0.01 m/s per step (0.1 s each). Episode 0 falls after 60 steps,
    # 1.4 m short; episode 1 arrives (within 0.5 m at step 150), is never credited (its goal
    # stays) and falls standing there at step 180; episode 2 arrives and does not fall.
    qpos, goal, completed = _straight_walk((2.0, 0.0), 0.0, steps=200, speed_per_step=0.01)
    qpos, goal = np.repeat(qpos, 3, axis=1), np.repeat(goal, 3, axis=1)
    completed = np.concatenate([np.zeros((200, 2)), completed], axis=1)
    alive = np.ones((200, 3))
    alive[60:, 0] = alive[180:, 1] = 0
    fell = np.array([True, True, False])
    start = np.zeros((3, qpos.shape[-1]))
    start[:, 3] = 1.0
    records = nav_metrics.goals_of_episodes(start, qpos, goal, completed, alive, fell, dt=0.1)
    assert [r["closest"] for r in records[:2]] == [pytest.approx(1.4), pytest.approx(0.2)]
    falls = nav_metrics.fall_phases(records, fell, alive, success_radius=0.5, dt=0.1)
    # Episode 0's goal was 2 m off; it closed 0.6 m of it (30%) and fell on its 60th step, 6.0 s
    # after the draw at the start (as a reached goal's `seconds` counts steps from the draw).
    assert falls == {"walking_to_a_goal": 1, "on_a_goal": 1, "seconds_median": pytest.approx(12.0),
                     "goal_distance_median": pytest.approx(2.0), "share_closed_median": pytest.approx(0.3),
                     "seconds_after_draw_median": pytest.approx(6.0)}
    none = nav_metrics.fall_phases(records[2:], fell[2:], alive[:, 2:], 0.5, 0.1)
    assert none["seconds_median"] is None and none["goal_distance_median"] is None
    rows = dict(nav_metrics.table_rows({"navigation": {**nav_metrics.navigation_summary(records, 3, 0.5, 0.2, 0.5, 3.0),
                                                       "falls": falls}}))
    assert rows["falls: walking to a goal, on a goal (median time)"] == "1, 1 (12.0 s)"
    assert rows["  walking: their goal's distance, share of it walked, time since it was drawn (medians)"] == \
        "2.00 m, 30.0%, 6.0 s"


def test_path_deviation_and_arrivals():
    # Corners at (1, 0) then (1, 1); the torso cuts 0.2 m inside the corner on the way.
    xy = np.array([[0.5, 0.0], [0.9, 0.0], [1.0, 0.1], [0.8, 0.2], [1.0, 0.6], [1.0, 1.0], [1.0, 1.0]])
    qpos = np.zeros((len(xy), 1, 25))
    qpos[:, 0, :2] = xy
    qpos[:, 0, 3] = 1.0
    completed = np.zeros((len(xy), 1))
    completed[[1, 5], 0] = 1
    alive = np.ones_like(completed)
    start = np.zeros((1, 25))
    out = nav_metrics.waypoint_summary(start, qpos, completed, alive, np.array([False]), [(1, 0), (1, 1)], dt=0.5)
    assert out["completed_rate"] == 1.0 and out["arrival_s_mean"] == [1.0, 3.0]
    assert out["max_deviation_mean"] == pytest.approx(0.2)  # (0.8, 0.2) is 0.2 m off the segment x = 1


# -- goals that stay put (--goal_stay_share) -----------------------------------------------------

@pytest.mark.parametrize("share", [0.0, 0.3, 1.0])
def test_stay_after_draws_follow_the_share(share):
    rng_draws = NativeDraws(np.random.default_rng(0))
    numpy_draws = np.array([events.draw_stay_after(share, rng_draws, None) for _ in range(4000)])
    jax_draws = np.asarray(jax.vmap(lambda k: events.draw_stay_after(share, DRAWS, k))(
        jax.random.split(jax.random.PRNGKey(0), 4000)))
    for drawn in (numpy_draws, jax_draws):
        stays = drawn[drawn != events.NEVER]
        assert abs(len(stays) / len(drawn) - share) < 0.03
        assert set(stays.tolist()) <= set(range(events.STAY_AFTER_MAX + 1))
        if share:  # every count from 0 to STAY_AFTER_MAX, about equally often
            counts = np.bincount(stays, minlength=events.STAY_AFTER_MAX + 1)
            assert counts.min() > 0.8 * len(stays) / (events.STAY_AFTER_MAX + 1)


def _arrive(env, stay_after):
    """Two native steps from a reset whose goal sits 0.3 m ahead (inside the 0.5 m radius), with
    this episode's goal staying after `stay_after` goals; (goal before, after step 1, after step 2,
    step infos)."""
    env.reset(seed=0)
    env.info["stay_after"] = np.int32(stay_after)
    env.set_goal(env.data.qpos[:2] + [0.3, 0.0])
    goals, infos = [env.goal], []
    for _ in range(2):
        infos.append(env.step(np.zeros(env.action_size))[4])
        goals.append(env.goal)
    return goals, infos


def test_a_goal_that_stays_is_not_replaced_and_pays_for_standing_on_it():
    env = NativeEnv(EnvConfig(task="navigate", goal_stay_share=1.0))
    assert "stay_after" in env.info
    goals, infos = _arrive(env, stay_after=0)
    np.testing.assert_array_equal(goals[0], goals[1])
    np.testing.assert_array_equal(goals[1], goals[2])
    assert [info["goals_reached"] for info in infos] == [0, 0]
    assert [info["terms"]["goal_bonus"] for info in infos] == [1.0, 1.0]  # paid on every step on the goal
    goals, infos = _arrive(env, stay_after=1)  # the first goal is replaced, as without the setting
    assert infos[0]["goals_reached"] == 1 and not np.allclose(goals[0], goals[1])


def test_stay_goals_leave_waypoints_and_other_tasks_alone():
    assert "stay_after" not in NativeEnv(EnvConfig(task="navigate")).info
    path = NativeEnv(EnvConfig(task="navigate", goal_stay_share=1.0, waypoints=((0.3, 0.0), (1.0, 0.0))))
    for seed in range(4):  # a path stays after its last waypoint, whatever the share would draw
        path.reset(seed=seed)
        assert path.info["stay_after"] == 2
    with pytest.raises(ValueError, match="the goal task has none"):
        hexa_mjx.make_env(goal_stay_share=0.5)
    with pytest.raises(ValueError, match=r"goal_stay_share is a share of the episodes in \[0, 1\]"):
        hexa_mjx.make_env(task="navigate", goal_stay_share=1.5)
