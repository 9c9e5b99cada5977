"""The velocity task: commands drawn, held and resampled as configured, tracked in the field's
reward form, observed alike by both engines; eval.py's tracking figures; schedules, keyboard and the
path follower that drive a velocity policy outside the trainer."""

import json

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest

import hexa_mjx
from hexa_mjx.deploy import commands
from hexa_mjx.engines.mjx_env import DRAWS
from hexa_mjx.engines.native import NativeEnv
from hexa_mjx.evaluation import tracking
from hexa_mjx.evaluation.nav_metrics import segment_distance
from hexa_mjx.mdp.config import make_config
from hexa_mjx.robot.kinematics import yaw
from hexa_mjx.tasks import TASKS, velocity

INTERVAL_STEPS = 3


@pytest.fixture(scope="module")
def vel_env():
    return hexa_mjx.make_env(task="velocity", episode_length=20, command_interval=INTERVAL_STEPS / 60.0,
                             command_heading_share=0.2)


@pytest.fixture(scope="module")
def vel_states(vel_env):
    return jax.jit(jax.vmap(vel_env.reset))(jax.random.split(jax.random.PRNGKey(0), 64))


def test_commands_fall_in_their_classes_and_ranges(vel_env):
    keys = jax.random.split(jax.random.PRNGKey(1), 4000)
    cmd = np.asarray(jax.jit(jax.vmap(lambda k: vel_env.task.draw_command(DRAWS, k)[0]))(keys))
    cfg = vel_env.config
    for i, bounds in enumerate((cfg.command_vx, cfg.command_vy, cfg.command_yaw_rate)):
        assert bounds[0] <= cmd[:, i].min() and cmd[:, i].max() <= bounds[1]
    names = [*velocity.CLASSES, "heading"]
    classes = tracking.command_class(cmd, velocity.CLASSES)
    shares = {name: float(np.mean(classes == i)) for i, name in enumerate(names)}
    assert shares["zero"] == pytest.approx(cfg.command_zero_share, abs=0.02)
    assert shares["heading"] == pytest.approx(0.2 * (1 - cfg.command_zero_share), abs=0.03)
    for name in ("forward", "backward", "sideways", "turn", "diagonal", "walk and turn"):
        assert shares[name] == pytest.approx(0.8 * 0.9 / 6, abs=0.02), name
    forward = cmd[classes == names.index("forward")]
    assert np.all(forward[:, 0] > 0) and np.all(forward[:, 1:3] == 0)


def test_commands_hold_for_the_interval_and_then_change(vel_env, vel_states):
    state = jax.tree.map(lambda x: x[:8], vel_states)
    step = jax.jit(jax.vmap(vel_env.step))
    seen = [np.asarray(state.pipeline_state.userdata)]
    for _ in range(2 * INTERVAL_STEPS):
        state = step(state, jp.zeros((8, vel_env.action_size)))
        seen.append(np.asarray(state.pipeline_state.userdata))
    changed = [bool(np.any(a != b)) for a, b in zip(seen[:-1], seen[1:])]
    # A new command after steps 3 and 6, none between (8 environments: one changes at least).
    assert changed == [False, False, True, False, False, True]


def test_tracking_reward_is_one_on_the_command_and_heading_mode_turns_toward_the_heading(vel_env, vel_states):
    qpos = np.asarray(vel_states.pipeline_state.qpos[0])
    heading = yaw(qpos[3:7])
    command = np.array([0.4, -0.2, 0.7], np.float32)
    qvel = np.zeros(vel_env.mj_model.nv, np.float32)
    c, s = np.cos(heading), np.sin(heading)
    qvel[:2] = [c * 0.4 + s * 0.2, s * 0.4 - c * 0.2]  # (0.4, -0.2) in the heading frame
    assert float(velocity.tracking_lin_vel(None, qpos, qvel, None, None, command)) == pytest.approx(1.0, abs=1e-5)
    assert float(velocity.tracking_ang_vel(None, qpos, qvel, None, None, command)) == pytest.approx(
        np.exp(-0.49 / velocity.TRACKING_SIGMA), rel=1e-4)
    # The task's own width (tracking_sigma) sets how sharply the terms fall off the command.
    narrow = TASKS["velocity"](make_config("velocity", tracking_sigma=0.05), vel_env.robot)
    terms = narrow.reward_terms(["tracking_lin_vel", "tracking_ang_vel"], None, qpos, qvel, None, heading,
                                np.array([0.4, -0.2, 0.7, 0.0], np.float32))
    assert float(terms["tracking_lin_vel"]) == pytest.approx(1.0, abs=1e-5)
    assert float(terms["tracking_ang_vel"]) == pytest.approx(np.exp(-0.49 / 0.05), rel=1e-3)
    # The yaw-rate term can have a width of its own.
    split = TASKS["velocity"](make_config("velocity", tracking_sigma=0.05, yaw_tracking_sigma=0.5), vel_env.robot)
    qvel_slow = qvel.copy()
    qvel_slow[:2] *= 0.5  # half the commanded planar velocity
    terms = split.reward_terms(["tracking_lin_vel", "tracking_ang_vel"], None, qpos, qvel_slow, None, heading,
                               np.array([0.4, -0.2, 0.7, 0.0], np.float32))
    assert float(terms["tracking_lin_vel"]) == pytest.approx(np.exp(-(0.2 ** 2 + 0.1 ** 2) / 0.05), rel=1e-3)
    assert float(terms["tracking_ang_vel"]) == pytest.approx(np.exp(-0.49 / 0.5), rel=1e-3)
    in_heading_mode = np.array([0.0, 0.0, 0.0, 1.0])
    asked = vel_env.task.commanded(in_heading_mode, qpos, heading + 0.3)
    assert float(asked[2]) == pytest.approx(velocity.HEADING_GAIN * 0.3, abs=1e-5)
    far = vel_env.task.commanded(in_heading_mode, qpos, heading + 3.0)
    assert float(far[2]) == pytest.approx(vel_env.config.command_yaw_rate[1])


def test_native_engine_observes_and_tracks_what_mjx_does(vel_env, vel_states):
    state = jax.tree.map(lambda x: x[5], vel_states)
    native = NativeEnv(vel_env.config)
    native.reset(seed=0)
    d = native.data
    for name in ("qpos", "qvel", "ctrl", "mocap_pos", "mocap_quat", "userdata"):
        getattr(d, name)[:] = np.asarray(getattr(state.pipeline_state, name))
    mujoco.mj_forward(native.mj_model, d)
    np.testing.assert_allclose(native.observe(), np.asarray(state.obs), atol=1e-5)
    assert native.observe()[:3] == pytest.approx(np.asarray(vel_env.task.commanded(
        native.command, native.data.qpos, native.heading)), abs=1e-6)
    _, reward, _, _, info = native.step(np.zeros(18))
    assert np.isfinite(reward) and {"tracking_lin_vel", "tracking_ang_vel"} <= set(info["terms"])


@pytest.mark.parametrize("settings, message", [
    ({"command_vx": (1.0, -0.5)}, "command_vx is a range"), ({"command_yaw_rate": (0.0, float("inf"))}, "finite"),
    ({"command_interval": 0.0}, "command_interval"), ({"command_zero_share": 1.5}, "command_zero_share"),
    ({"tracking_sigma": 0.0}, "tracking_sigma is a width above 0"),
    ({"yaw_tracking_sigma": -0.1}, "yaw_tracking_sigma is a width above 0")])
def test_bad_command_settings_are_refused_before_anything_is_built(settings, message):
    with pytest.raises(ValueError, match=message):
        NativeEnv(make_config("velocity", **settings))


def test_tracking_figures_of_a_known_rollout():
    dt, steps = 1 / 60, 240
    command = np.zeros((steps, 2, 4))
    command[:120, 0, 0] = 0.5  # forward, then zero
    command[:, 1, 2] = 1.0  # turning on the spot
    commanded = command[..., :3].copy()
    measured = commanded * 0.8  # 80% of every command
    qpos = np.zeros((steps, 2, 7))
    qpos[..., 3] = 1.0
    qpos[120:, 0, 0] = np.arange(120) * dt * 0.05  # drifting at 0.05 m/s while told to stand
    traj = {"command": command, "commanded": commanded, "velocity": measured, "qpos": qpos}
    task = type("T", (), {"robot": None})()
    summary, per_episode = tracking.tracking_summary(task, dt, traj, np.ones((steps, 2)), None)
    assert summary["classes"]["forward"]["velocity_rms"] == pytest.approx(0.1, abs=1e-6)
    assert summary["classes"]["forward"]["velocity_share"] == pytest.approx(0.8)
    assert summary["classes"]["turn"]["yaw_rate_rms"] == pytest.approx(0.2, abs=1e-6)
    # Each change's first second is left out: 60 of the forward command's 120 steps count.
    assert summary["classes"]["forward"]["steps"] == 120 - 60
    assert summary["stand_drift"]["speed_mean"] == pytest.approx(0.05, rel=0.03)


def test_falls_are_put_on_the_command_in_force():
    dt, steps = 1 / 50, 300
    command = np.zeros((steps, 3, 4))
    command[:100, :, 0] = 0.4  # forward for 2 s, then sideways
    command[100:, :, 1] = -0.3
    alive = np.ones((steps, 3))
    alive[130:, 0] = 0.0  # falls 0.58 s into the sideways command (its last step, 129)
    alive[60:, 2] = 0.0  # falls 1.18 s into the forward command
    traj = {"command": command, "commanded": command[..., :3], "velocity": command[..., :3],
            "qpos": np.tile(np.array([0, 0, 0.1, 1, 0, 0, 0.0]), (steps, 3, 1))}
    task = type("T", (), {"robot": None})()
    summary, _ = tracking.tracking_summary(task, dt, traj, alive, np.array([True, False, True]))
    falls = summary["falls"]
    assert falls["falls"] == 2 and falls["by_class"] == {"forward": 1, "sideways": 1}
    assert [f["seconds_into_command"] for f in falls["each"]] == pytest.approx([0.58, 1.18])
    assert falls["each"][0]["commanded"] == pytest.approx([0.0, -0.3, 0.0])
    assert falls["within_settle"] == 1
    assert any(label == "falls by the command in force" for label, _ in tracking.table_rows({"tracking": summary}))


def test_episodes_shorter_than_the_settling_window_get_a_table_not_a_crash():
    dt, steps = 1 / 50, 40  # 0.8 s: every step is within the first second of its command
    command = np.zeros((steps, 2, 4))
    command[..., 0] = 0.3
    traj = {"command": command, "commanded": command[..., :3], "velocity": command[..., :3],
            "qpos": np.tile(np.array([0, 0, 0.1, 1, 0, 0, 0.0]), (steps, 2, 1))}
    summary, _ = tracking.tracking_summary(type("T", (), {"robot": None})(), dt, traj, np.ones((steps, 2)), None)
    assert summary["steps"] == 0
    (label, text), = tracking.table_rows({"tracking": summary})
    assert "--episode_length" in text


def test_gait_terms_in_the_native_engine_follow_the_feet():
    """feet_air_time and foot_slip, asked for, from the episode's own foot bookkeeping: no slip on
    an episode's first step (its previous foot positions are not this episode's), touchdowns paid
    while walking, and the slip equal to the feet's measured planar speed on the floor."""
    env = NativeEnv(make_config("velocity", reward_scales={"feet_air_time": 1.0, "foot_slip": -1.0}))
    env.reset(seed=0)
    env.set_command(np.array([0.4, 0.0, 0.0, 0.0]))  # walk forward: the terms count
    rng, slips, touchdowns = np.random.default_rng(0), [], 0
    for t in range(60):
        before = env.info["foot_xy"].copy()
        *_, info = env.step(rng.uniform(-1, 1, env.action_size))
        slips.append(info["terms"]["foot_slip"])
        touchdowns += info["terms"]["feet_air_time"] != 0.0
        if t == 0:
            assert info["terms"]["foot_slip"] == 0.0
        else:
            speed = np.linalg.norm(env.info["foot_xy"] - before, axis=1) / env.dt
            stance = env.info["air_time"] == 0.0
            assert info["terms"]["foot_slip"] == pytest.approx(float((stance * speed ** 2).sum()), rel=1e-5)
    assert touchdowns > 0 and max(slips) > 0.0


def test_progress_line_divides_the_run_own_reward_scales_back():
    # a run trained with --reward_scale tracking_ang_vel=10 logs the term scaled by 10, not by the table's 5
    row = {"episode_length": 100, "eval/episode_reward/tracking_lin_vel": 0.5 * 20 * 100,
           "eval/episode_reward/tracking_ang_vel": 0.25 * 10 * 100}
    figure = velocity.VelocityTask.progress_figure(row, {"tracking_lin_vel": 20.0, "tracking_ang_vel": 10.0})
    assert figure == "tracking v 0.50 yaw 0.25"


def test_schedules_are_read_from_csv_and_json_and_bad_ones_refused(tmp_path):
    csv = tmp_path / "drive.csv"
    csv.write_text("t,vx,vy,yaw_rate\n0,0.5,0,0\n2.5,0,0,1.0  # turn\n4,0,0,0\n")
    table = commands.load_schedule(csv)
    schedule = commands.Schedule(table)
    assert list(schedule(1.0)) == [0.5, 0, 0] and list(schedule(3.0)) == [0, 0, 1.0]
    js = tmp_path / "drive.json"
    js.write_text(json.dumps([{"t": 0, "vx": 0.5, "vy": 0, "yaw_rate": 0}, [2.5, 0, 0, 1.0], [4, 0, 0, 0]]))
    np.testing.assert_array_equal(commands.load_schedule(js), table)
    for text, message in [("0,0.5,0\n", "4 values"), ("0,1,0,0\n0,1,0,0\n", "increase"), ("0,x,0,0\n", "cannot be read"),
                          ("0,nan,0,0\n", "finite")]:
        csv.write_text(text)
        with pytest.raises(ValueError, match=message):
            commands.load_schedule(csv)


def test_keyboard_steps_and_stops_within_the_ranges():
    keys = commands.Keyboard(((-0.5, 1.0), (-0.5, 0.5), (-1.5, 1.5)))
    for _ in range(20):
        keys.press(87)  # W
    keys.press(81)  # Q
    assert list(keys(0.0)) == [1.0, 0.0, 0.25]
    keys.press(commands.STOP_KEY)
    assert not keys(0.0).any() and not keys.press(73)  # I is the goal viewer's, not a driving key


def _walk_the_square(start_drift=(0.0, 0.0)):
    """A robot that does exactly what it is commanded, on the 2 m square from the origin; it stands
    `start_drift` m off the start when the follower first reads it. Returns the follower and the path."""
    class Point:
        def __init__(self):
            self.data = type("D", (), {"qpos": np.array([0.0, 0, 0.12, 1, 0, 0, 0])})()

    robot, dt = Point(), 1 / 60
    square = np.array([[2.0, 0], [2, 2], [0, 2], [0, 0]])
    follower = commands.PathFollower(square, ((-0.5, 1.0), (-0.5, 0.5), (-1.5, 1.5)))
    follower.reset(robot.data.qpos[:2])
    robot.data.qpos[:2] += start_drift
    path = []
    for step in range(60 * 60):
        vx, vy, wz = follower(step * dt, robot)
        h = yaw(robot.data.qpos[3:7])
        robot.data.qpos[:2] += dt * np.array([np.cos(h) * vx - np.sin(h) * vy, np.sin(h) * vx + np.cos(h) * vy])
        h += dt * wz
        robot.data.qpos[3:7] = [np.cos(h / 2), 0, 0, np.sin(h / 2)]
        path.append(robot.data.qpos[:2].copy())
    return follower, square, np.array(path)


def test_path_follower_walks_a_point_robot_around_the_square():
    follower, square, path = _walk_the_square()
    assert follower.reached == 4 and np.linalg.norm(path[-1]) < 0.15
    corners = np.vstack([[0, 0], square])
    deviation = np.min([segment_distance(path, np.broadcast_to(a, path.shape), np.broadcast_to(b, path.shape))
                        for a, b in zip(corners[:-1], corners[1:])], axis=0)
    assert deviation.max() < 0.3  # corners are cut by less than the lookahead


def test_path_follower_walks_a_closed_path_after_a_drift_at_the_start():
    """2 cm back and 3 cm left of the start, nearer the square's last side (x = 0) than its first,
    as a robot that turns on the spot before walking can be: the follower still walks all four."""
    follower, _, path = _walk_the_square(start_drift=(-0.02, 0.03))
    assert follower.reached == 4 and np.linalg.norm(path[-1]) < 0.15
    assert np.abs(path).max() > 1.9  # it walked out to the far corner


@pytest.fixture(scope="module")
def velocity_onnx(tmp_path_factory):
    """An untrained velocity-task run, evaluated and exported: enough to drive from play.py."""
    import dataclasses

    from hexa_mjx.deploy import export
    from hexa_mjx.training import checkpoints, config, networks

    run_dir = tmp_path_factory.mktemp("velocity") / "run"
    cfg = config.validate(config.parse_args(["--task", "velocity", "--hidden", "8", "8", "--episode_length", "90",
                                             "--num_envs", "8", "--batch_size", "8", "--num_minibatches", "1",
                                             "--cpu_devices", "1", "--run_dir", str(run_dir)]))
    (run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    checkpoints.save_checkpoint(run_dir, 0, networks.init_params(cfg, config.make_env_for(cfg)))
    return run_dir, export.export(run_dir, run_dir.parent / "velocity.onnx")


def test_eval_reports_tracking_and_export_names_the_command(velocity_onnx, tmp_path):
    from hexa_mjx.evaluation import evaluate, table
    from hexa_mjx.tasks import TASKS

    run_dir, onnx = velocity_onnx
    result = evaluate.evaluate(run_dir, episodes=2, video=False, out=tmp_path / "eval")
    t = result["summary"]["tracking"]
    assert t["settle_s"] == tracking.SETTLE_S and np.isfinite(t["velocity_rms"]) and t["classes"]
    text = table.format_table(result["summary"], TASKS["velocity"])
    assert "velocity RMS error" in text and "final distance" not in text
    meta = json.loads(onnx.with_suffix(".json").read_text())
    assert [f["name"] for f in meta["command"]] == ["vx", "vy", "yaw_rate"]
    trained = make_config(task="velocity").command_yaw_rate  # the run's own: the default range
    assert meta["command"][0]["units"] == "m/s" and meta["command"][2]["range"] == list(trained)
    assert meta["observation_layout"][0]["what"].startswith("command")


def run_play(*args):
    import subprocess
    import sys

    from hexa_mjx.robot import constants as robot

    return subprocess.run([sys.executable, str(robot.REPO_ROOT / "play.py"), *map(str, args)], capture_output=True,
                          text=True, cwd=robot.REPO_ROOT)


def test_play_drives_a_velocity_policy_from_a_schedule_and_along_a_path(velocity_onnx, tmp_path):
    _, onnx = velocity_onnx
    schedule = tmp_path / "drive.csv"
    schedule.write_text("t,vx,vy,yaw_rate\n0,0.3,0,0\n0.5,0,0,0\n")
    out = tmp_path / "r.json"
    proc = run_play("--policy", onnx, "--commands", schedule, "--json", out, "--video", tmp_path / "v.mp4")
    assert proc.returncode == 0 and "velocity RMS" in proc.stdout, proc.stderr
    assert (tmp_path / "v.mp4").stat().st_size > 0
    figures = json.loads(out.read_text())["tracking"]  # eval.py's figures, per class included
    assert figures["settle_s"] == tracking.SETTLE_S and "classes" in figures and "stand_drift" in figures
    proc = run_play("--policy", onnx, "--follow", "--waypoints", "0.5,0", "--no_video")
    assert proc.returncode == 0 and "waypoints reached" in proc.stdout, proc.stderr


def test_play_refuses_bad_driving_input_before_running(velocity_onnx, tmp_path):
    _, onnx = velocity_onnx
    bad = tmp_path / "bad.csv"
    bad.write_text("0,0.5,0,0\n0,0.5,0,0\n")
    cases = {(onnx, "--waypoints", "1,0"): "add --follow",
             (onnx, "--commands", bad): "increase row by row",
             (onnx, "--follow"): "give it with --waypoints",
             ("policies/navigate.onnx", "--commands", bad): "drive a velocity policy"}
    for args, message in cases.items():
        proc = run_play("--policy", *args, "--no_video")
        assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr, (args, proc.stderr)


def test_standing_still_scores_one_on_zero_commands_and_less_on_wider_ranges():
    task = lambda **kw: velocity.VelocityTask(make_config("velocity", **kw), None)  # noqa: E731
    assert tracking.standing_still(task(command_zero_share=1.0), draws=200) == (1.0, 1.0)
    narrow = tracking.standing_still(task(), draws=5000)
    wide = tracking.standing_still(task(command_vx=(-1.0, 2.0), command_yaw_rate=(-3.0, 3.0)), draws=5000)
    assert 0 < wide[0] < narrow[0] < 1 and 0 < wide[1] < narrow[1] < 1


def test_the_generalist_battery_walks_the_square_and_stops_at_its_end():
    from hexa_mjx.deploy import player
    from hexa_mjx.robot.constants import REPO_ROOT
    from hexa_mjx.studies import generalist

    shipped = str(REPO_ROOT / "policies" / "velocity.onnx")
    groups = [group for group, *_ in generalist.conditions(player.OnnxPolicy(shipped), terrain_seed=1)]
    # flat; bumps, 15-degree slopes, stairs; pushes; 8 physics corners; 6 legs x limp, locked; 9 pairs
    assert [groups.count(g) for g in generalist.TARGETS] == [1, 3, 1, 8, 12, 9]
    rows = generalist.battery(shipped, 1, groups=["push"])  # and the flat row, whose speed the others share
    assert [r["condition"] for r in rows] == ["flat, intact", "pushes up to 0.5 m/s"]
    flat = rows[0]
    assert flat["speed_share_of_intact"] == 1.0 and flat["speed"] == pytest.approx(8 / flat["path_time_s_median"])
    # 8 m at the follower's 0.5 m/s: about 16 s; an episode run to its 30 s end would say 30 s
    assert flat["path_completed_rate"] == 1.0 and 12 < flat["path_time_s_median"] < 25
    # its gait, from the native engine's foot contacts: six legs, the torso's speed the path's
    gait = flat["gait"]
    assert len(gait["duty_factor"]) == 6 and all(0 <= d <= 1 for d in gait["duty_factor"])
    assert 0.5 * 8 / flat["path_time_s_median"] < gait["speed"] < 2 * 8 / flat["path_time_s_median"]
    assert "| flat |" in generalist.gait_table([{**flat, "condition": "flat"}])
    row = {"group": "one leg", "path_completed_rate": 0.95, "speed_share_of_intact": 0.69, "fall_rate": 0.0}
    assert not generalist.meets(row) and generalist.meets({**row, "speed_share_of_intact": 0.7})
    assert not generalist.meets({**row, "group": "flat", "speed_share_of_intact": None, "fall_rate": 0.03})


def test_the_battery_gives_a_navigation_policy_the_square_as_waypoints():
    from hexa_mjx.deploy import player
    from hexa_mjx.robot.constants import REPO_ROOT
    from hexa_mjx.studies import generalist, robustness

    policies = REPO_ROOT / "policies"
    base = generalist.base_settings()
    row, = robustness.run_conditions(str(policies / "navigate.onnx"), [(base, None)], 1, path=generalist.SQUARE)
    # the shipped navigation policy walks the 8 m square at about 1 m/s (docs/RESULTS.md, the path
    # follower's table: 8.1 s); its episode ends at the last waypoint, not at 30 s
    assert row["path_completed_rate"] == 1.0 and 4 < row["path_time_s_median"] < 20, row
    assert row["gait"]["speed"] > 0.5 * 8 / row["path_time_s_median"]
    # without end_at_path (play.py) the episode goes on, and the path's time is still its last waypoint's
    policy = player.OnnxPolicy(policies / "navigate.onnx")
    env = robustness.path_env(policy, generalist.SQUARE, **base)
    episode = player.run_episode(policy, env, 0)
    assert episode["path_completed"] and episode["path_time_s"] == pytest.approx(row["path_time_s_median"])
    assert episode["steps"] * env.dt > 1.5 * episode["path_time_s"]  # it stood on well past the path's end
    with pytest.raises(ValueError, match="velocity policy .* or a navigation policy"):
        robustness.run_conditions(str(policies / "goal.onnx"), [(base, None)], 1, path=generalist.SQUARE)


def test_the_path_study_walks_the_square_with_the_follower_and_with_waypoints():
    from hexa_mjx.robot.constants import REPO_ROOT
    from hexa_mjx.studies import path_following

    policies = REPO_ROOT / "policies"
    square = {"square": path_following.PATHS["square"]}
    result = path_following.compare(str(policies / "velocity.onnx"), str(policies / "navigate.onnx"), square,
                                    episodes=1, episode_length=1500)["square"]
    follower, navigation = result["velocity + follower"], result["navigation"]
    # 8 m: the follower at its 0.5 m/s takes about 16 s, the navigation policy at its own pace less
    assert follower["completed_rate"] == 1.0 and 12 < follower["time_s_median"] < 25, follower
    assert navigation["completed_rate"] == 1.0 and navigation["time_s_median"] < follower["time_s_median"], navigation
    assert "| square | navigation | 100% |" in path_following.table({"square": result})
