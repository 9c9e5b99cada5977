"""Bad input across train.py, eval.py, the converter and make_env: one clear line, exit 2, before
anything compiles, and nothing written. Each command runs in this process (its main function),
with the compiling step replaced by a failure, so a case that slipped past validation fails the
test instead of training."""

import dataclasses
import json
import sys
import time
from pathlib import Path

import pytest

from hexa_mjx.training import config, jax_setup, loop as training
from hexa_mjx.robot import convert
from hexa_mjx.mdp import config as env_config
from hexa_mjx.evaluation import evaluate as evaluation
from hexa_mjx.engines import make_env

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
import eval as eval_script  # noqa: E402  (the repository's eval.py)
import train as train_script  # noqa: E402

POLICY = str(ROOT / "policies" / "goal")
NAV_POLICY = str(ROOT / "policies" / "navigate")

TRAIN_CASES = [
    (["--lr", "nan"], "--lr must be a finite number"),
    (["--init_from", "runs/no-such-run"], "--init_from: runs/no-such-run is neither a run directory"),
    (["--lr", "-1"], "--lr must be a finite number in (0, inf)"),
    (["--lr", "0"], "--lr must be a finite number in (0, inf)"),
    (["--discount", "2"], "--discount must be a finite number in (0, 1]"),
    (["--discount", "0"], "--discount must be a finite number in (0, 1]"),
    (["--gae_lambda", "5"], "--gae_lambda must be a finite number in [0, 1]"),
    (["--clip", "-1"], "--clip must be a finite number"),
    (["--vf_coef", "-1"], "--vf_coef must be a finite number"),
    (["--ent_coef", "nan"], "--ent_coef must be a finite number"),
    (["--max_grad_norm", "0"], "--max_grad_norm must be a finite number"),
    (["--reward_scaling", "inf"], "--reward_scaling must be a finite number"),
    (["--mean_init_scale", "0"], "--mean_init_scale must be a finite number"),
    (["--init_noise_std", "0"], "--init_noise_std must be a finite number"),
    (["--batch_size", "0"], "--batch_size must be a finite number in [1, inf)"),
    (["--num_minibatches", "0"], "--num_minibatches must be a finite number in [1, inf)"),
    (["--num_envs", "0"], "--num_envs must be a finite number in [1, inf)"),
    (["--num_envs", "100"], "--num_envs 100 does not fit the batch shape"),
    (["--hidden", "0"], "--hidden sizes must each be at least 1"),
    (["--hidden"], "expected at least one argument"),
    (["--ctrl_hz", "0"], "--ctrl_hz must be a finite number in (0, inf)"),
    (["--ctrl_hz", "7"], "ctrl_hz"),
    (["--num_timesteps", "0"], "--num_timesteps must be at least 1"),
    (["--num_evals", "0"], "--num_evals must be at least 1"),
    (["--unroll_length", "0"], "--unroll_length must be at least 1"),
    (["--update_epochs", "0"], "--update_epochs must be at least 1"),
    (["--episode_length", "0"], "--episode_length must be at least 1"),
    (["--num_eval_envs", "0"], "--num_eval_envs must be at least 1"),
    (["--cpu_devices", "-1"], "--cpu_devices must be 0 (one per core) or more"),
    (["--seed", "abc"], "invalid int value: 'abc'"),
    (["--reward", "sideways"], "invalid choice: 'sideways'"),
    (["--ablate", "legs"], "invalid choice: 'legs'"),
    (["--task", "fly"], "invalid choice: 'fly'"),
    (["--reward_scale", "body_contact"], "write TERM=VALUE with a finite number"),
    (["--reward_scale", "body_contact=nan"], "write TERM=VALUE with a finite number"),
    (["--reward_scale", "shins=-3"], "unknown reward term 'shins'"),
    (["--task", "navigate", "--reward", "goal_directed"], "not one of the navigate task's"),
    (["--task", "navigate", "--goal_min_distance", "3", "--goal_max_distance", "1"], "0 <= min <= max"),
    (["--curriculum_levels", "4"], "the goal task has none"),
    (["--task", "navigate", "--curriculum_levels", "-1"], "curriculum_levels is a whole number of levels"),
    (["--start_yaw_noise", "-1"], "start_yaw_noise is a range in radians from 0 to pi"),
    (["--leg_failure_rate", "2"], "leg_failure_rate is a probability in [0, 1]"),
    (["--leg_failure_weights", "1", "1", "3", "3", "1", "1"], "weigh the legs of --leg_failure random"),
    (["--leg_failure", "random", "--leg_failure_weights", "1", "3"], "one weight per leg (6)"),
    (["--push_speed", "-1"], "push_speed is a speed in m/s"),
    (["--push_interval", "0"], "push_interval must be a time above 0 s"),
    (["--action_latency", "5"], "action_latency is in control steps from 0 to 1"),
    (["--obs_noise", "-1"], "obs_noise is a multiple of the noise scales"),
    (["--max_contact_points", "-1"], "max_contact_points must be 0"),
    (["--max_contact_points", "999"], "above the model's 40 robot-floor contact slots"),
    (["--model", "nowhere.xml"], "--model nowhere.xml is not a file"),
    (["--num_processes", "2", "--process_id", "5", "--coordinator", "localhost:1"], "--process_id must be in 0..1"),
    (["--num_processes", "2"], "needs --coordinator HOST:PORT"),
    (["--process_wait_timeout", "0"], "--process_wait_timeout must be positive seconds"),
    (["--policy_dist", "beta"], "invalid choice: 'beta'"),
    (["--terrain", "lava"], "invalid choice: 'lava'"),
    (["--terrain", "bumps", "--terrain_difficulty", "2"], "terrain_difficulty is a fraction from 0 to 1"),
]

EVAL_CASES = [
    (["--ckpt", "nowhere"], "neither a run directory"),
    (["--ckpt", POLICY, "--episodes", "0"], "--episodes must be at least 1"),
    (["--ckpt", POLICY, "--videos", "-1"], "--videos must be 0 or more"),
    (["--ckpt", POLICY, "--waypoints", "1,0 1"], "waypoint '1' is not x,y"),
    (["--ckpt", POLICY, "--waypoints", ""], "no waypoints"),
    (["--ckpt", POLICY, "--waypoints", "1,0"], "need a task that follows a path; the goal task does not"),
    (["--ckpt", POLICY, "--task", "fly"], "invalid choice: 'fly'"),
    (["--ckpt", NAV_POLICY, "--task", "stand", "--waypoints", "1,0"], "the stand task does not"),
    (["--ckpt", NAV_POLICY, "--goal_min_distance", "-1"], "0 <= min <= max"),
    (["--ckpt", POLICY, "--disabled_legs", "7"], "leg"),
    (["--ckpt", POLICY, "--disabled_legs", "1 2 3 4 5 6"], "all"),
    (["--ckpt", POLICY, "--disabled_legs", "x"], "leg"),
    (["--ckpt", POLICY, "--push_speed", "-1"], "push_speed is a speed in m/s"),
    (["--ckpt", POLICY, "--action_latency", "2"], "action_latency is in control steps from 0 to 1"),
    (["--ckpt", POLICY, "--out", "/proc/hexa_mjx_eval"], "cannot write to --out"),
    (["--ckpt", POLICY, "--max_contact_points", "999"], "above the model's 40 robot-floor contact slots"),
    (["--ckpt", POLICY, "--terrain", "lava"], "invalid choice: 'lava'"),
    (["--ckpt", POLICY, "--terrain", "steps", "--terrain_difficulty", "-1"], "terrain_difficulty is a fraction"),
]

CONVERT_CASES = [
    (["nowhere.urdf", "-o", "{tmp}/robot.xml"], "nowhere.urdf"),
    ([str(ROOT / "models" / "hexapod.xml"), "-o", "{tmp}/robot.xml"], ""),  # an MJCF is not a URDF
    (["nowhere.urdf", "-o", "{tmp}"], "is a folder"),
]

MAKE_ENV_CASES = [
    (dict(goal_distance=float("nan")), "goal_distance must be a finite number above 0"),
    (dict(success_radius=-1.0), "success_radius must be a finite number above 0"),
    (dict(solver_iterations=0), "solver_iterations"),
    (dict(max_contact_points=10_000), "max_contact_points"),
    (dict(ctrl_hz=0.0), "ctrl_hz"),
    (dict(episode_length=0), "episode_length must be at least 1"),
    (dict(disabled_legs=(1, 2, 3, 4, 5, 6)), "all"),
    (dict(disabled_legs=(9,)), "leg"),
    (dict(wings=2), "unknown environment setting"),
    (dict(terrain="lava"), "unknown terrain 'lava'"),
]


def one_error_line(err: str) -> bool:
    return sum("error:" in line for line in err.splitlines()) == 1 and "Traceback" not in err


@pytest.fixture
def nothing_compiles(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the input got past validation")

    monkeypatch.setattr(training, "train", refuse)
    monkeypatch.setattr(evaluation, "rollout", refuse)
    # JAX is already running in this process: keep the commands from pointing its compilation
    # cache at the user's folder for the rest of the suite.
    monkeypatch.setattr(jax_setup, "prepare_jax", lambda *args, **kwargs: None)


def run_main(main, argv):
    t0 = time.time()
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's own errors
        code = e.code
    return code, time.time() - t0


def test_the_table_holds_forty_distinct_cases():
    cases = [tuple(a) for a, _ in TRAIN_CASES + EVAL_CASES + CONVERT_CASES] + [repr(k) for k, _ in MAKE_ENV_CASES]
    assert len(set(cases)) == len(cases) >= 40


@pytest.mark.parametrize("argv, message", TRAIN_CASES, ids=[" ".join(a) for a, _ in TRAIN_CASES])
def test_train_rejects(argv, message, tmp_path, capsys, nothing_compiles):
    run_dir = tmp_path / "run"
    code, seconds = run_main(train_script.main, [*argv, "--run_dir", str(run_dir)])
    err = capsys.readouterr().err
    assert code == 2 and message in err and one_error_line(err), err
    assert seconds < 10 and not run_dir.exists()


@pytest.mark.parametrize("kind, message", [("file", "is a file, not a folder"),
                                           ("unwritable", "cannot write to --run_dir /proc/hexa_mjx_run"),
                                           ("a run", "already holds a run; pass --resume")])
def test_train_rejects_a_run_dir(kind, message, tmp_path, capsys, nothing_compiles):
    run_dir = {"file": tmp_path / "file", "unwritable": Path("/proc/hexa_mjx_run"), "a run": tmp_path / "run"}[kind]
    if kind == "file":
        run_dir.write_text("")
    elif kind == "a run":
        run_dir.mkdir()
        (run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(config.TrainConfig(run_dir=str(run_dir)))))
    before = sorted(tmp_path.rglob("*"))
    code, _ = run_main(train_script.main, ["--run_dir", str(run_dir)])
    err = capsys.readouterr().err
    assert code == 2 and message in err and one_error_line(err), err
    assert sorted(tmp_path.rglob("*")) == before


def test_train_rejects_a_resume_with_other_settings(tmp_path, capsys, nothing_compiles):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    saved = dataclasses.asdict(config.TrainConfig(seed=3, reward="goal_directed", run_dir=str(run_dir)))
    (run_dir / "config.json").write_text(json.dumps(saved))
    before = sorted(p.name for p in run_dir.iterdir())
    code, _ = run_main(train_script.main, ["--run_dir", str(run_dir), "--resume", "--seed", "4"])
    err = capsys.readouterr().err
    assert code == 2 and "holds a different run: seed=3" in err and "drop --seed" in err and one_error_line(err)
    assert sorted(p.name for p in run_dir.iterdir()) == before
    assert json.loads((run_dir / "config.json").read_text()) == saved


@pytest.mark.parametrize("argv, message", EVAL_CASES, ids=[" ".join(a) for a, _ in EVAL_CASES])
def test_eval_rejects(argv, message, tmp_path, capsys, nothing_compiles):
    out = tmp_path / "out"
    if "--out" not in argv:
        argv = [*argv, "--out", str(out)]
    code, seconds = run_main(eval_script.main, argv)
    err = capsys.readouterr().err
    assert code == 2 and message in err and one_error_line(err), err
    assert seconds < 10 and not out.exists()


@pytest.mark.parametrize("argv, message", CONVERT_CASES, ids=[" ".join(a) for a, _ in CONVERT_CASES])
def test_convert_rejects(argv, message, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, seconds = run_main(convert.main, argv)
    err = capsys.readouterr().err
    assert code == 2 and message in err and one_error_line(err), err
    assert seconds < 10 and sorted(tmp_path.iterdir()) == []


@pytest.mark.parametrize("overrides, message", MAKE_ENV_CASES, ids=[str(k) for k, _ in MAKE_ENV_CASES])
def test_make_env_rejects(overrides, message):
    with pytest.raises((ValueError, TypeError), match=message):
        env_config.check_config(env_config.make_config(**overrides))
        make_env(**overrides)
