"""train.py's flags, recipes, the compile cache's folder and the time-to-success study's parsing."""

import dataclasses
import json
import subprocess
import sys
import tomllib

import pytest

from hexa_mjx.training import config, jax_setup
from hexa_mjx.studies import time_to_success
from hexa_mjx.tasks import reward_variants
from hexa_mjx.training import recipes


def test_flags_and_their_negations():
    cfg = config.parse_args(["--task", "navigate", "--no_compile_cache", "--no_progress", "--resume"])
    assert cfg.task == "navigate" and cfg.reward == "navigate"  # the task's own reward by default
    assert not cfg.compile_cache and not cfg.progress and cfg.resume
    default = config.parse_args([])
    assert default.compile_cache and default.progress and default.reward == "goal_directed"


def test_recipe_fills_only_what_the_command_line_leaves():
    cfg = config.parse_args(["--preset", "paper", "--num_envs", "16"])  # the old spelling of --recipe
    paper = tomllib.loads((recipes.RECIPES_DIR / "paper.toml").read_text())["settings"]
    assert cfg.recipe == "paper" and cfg.num_envs == 16 and cfg.unroll_length == paper["unroll_length"] == 8


@pytest.mark.parametrize("name", recipes.names())
def test_every_recipe_names_known_settings_and_says_what_it_is_for(name):
    assert recipes.description(name)
    cfg = config.parse_args(["--recipe", name])
    for key, value in recipes.load(name, config.FIELDS).items():
        assert getattr(cfg, key) == value, key


def test_bad_recipes_are_one_clear_error(tmp_path, capsys):
    broken = tmp_path / "broken.toml"
    broken.write_text("[settings]\nnum_envs = ")
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("[settings]\nwarp_speed = 9")
    for recipe, message in (("nope", "no recipe 'nope'"), (str(broken), "is not valid TOML"),
                            (str(unknown), "unknown setting(s) ['warp_speed']")):
        with pytest.raises(SystemExit):
            config.parse_args(["--recipe", recipe])
        assert message in capsys.readouterr().err


def test_resume_takes_the_runs_own_settings(tmp_path):
    run_dir = tmp_path / "run"
    first = config.validate(config.parse_args(["--recipe", "fast", "--num_timesteps", "400000", "--seed", "2",
                                               "--run_dir", str(run_dir)]))
    (run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(first)))
    resumed = config.parse_args(["--run_dir", str(run_dir), "--resume"])
    assert dataclasses.replace(resumed, resume=False) == first
    # A recipe given on resume never replaces the run's step budget; a flag may extend it.
    again = config.parse_args(["--run_dir", str(run_dir), "--resume", "--recipe", "fast"])
    assert again.num_timesteps == 400_000 and again.num_evals == first.num_evals
    assert config.parse_args(["--run_dir", str(run_dir), "--resume", "--num_timesteps", "800000"]).num_timesteps == 800_000
    (run_dir / "config.json").write_text("{")
    with pytest.raises(SystemExit):
        config.parse_args(["--run_dir", str(run_dir), "--resume"])


def test_help_shows_the_groups():
    text = config.build_parser().format_help()
    for group in config.GROUPS:
        assert f"\n{group}:\n" in text


def test_compile_cache_folder_is_per_user_and_keyed(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    folder = jax_setup.compile_cache_dir()
    assert folder.parent == tmp_path / "hexa_mjx" and folder.name.startswith("xla-") and len(folder.name) == 16
    monkeypatch.setattr(jax_setup.jax, "__version__", "0.0.0")
    assert jax_setup.compile_cache_dir() != folder  # another jax, another folder


def test_time_to_success_reads_the_first_good_evaluation(tmp_path):
    rows = [{"step": 0, "walltime_s": 50.0, "success_rate": 0.0},
            {"step": 100, "walltime_s": 90.0, "success_rate": 0.875},
            {"step": 200, "walltime_s": 130.0, "success_rate": 0.9375},
            {"step": 300, "walltime_s": 170.0, "success_rate": 1.0}]
    path = tmp_path / "metrics.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert time_to_success.first_success(path, 0.9) == (200, 130.0)
    assert time_to_success.first_success(path, 1.0) == (300, 170.0)
    assert time_to_success.first_success(tmp_path / "none.jsonl", 0.9) is None


def test_time_to_success_reports_finished_runs(tmp_path, capsys):
    run = tmp_path / "run-s0"
    run.mkdir()
    rows = [{"step": 0, "walltime_s": 60.0, "success_rate": 0.0, "fall_rate": 0.5},
            {"step": 500, "walltime_s": 120.0, "success_rate": 0.9, "fall_rate": 0.25}]
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert time_to_success.main(["--runs", str(run), "--target", "0.855"]) == 0
    assert "success >= 85.5% at 2.0 min, 500 steps; run 500 steps in 2.0 min" in capsys.readouterr().out
    assert time_to_success.main(["--runs", str(tmp_path / "nothing")]) == 2


def test_time_to_success_configurations():
    assert time_to_success.parse_config("e4=--update_epochs 4 --lr 1e-3") == ("e4", ["--update_epochs", "4", "--lr", "1e-3"])
    assert time_to_success.parse_config("paper") == ("paper", ["--recipe", "paper"])
    with pytest.raises(SystemExit, match="unknown configuration"):
        time_to_success.parse_config("quick")


@pytest.mark.parametrize("flags, message", [
    (["--lr", "nan"], "--lr must be a finite number in (0, inf)"),
    (["--lr", "-1"], "--lr must be"),
    (["--discount", "2"], "--discount must be a finite number in (0, 1]"),
    (["--gae_lambda", "5"], "--gae_lambda must be"),
    (["--clip", "-1"], "--clip must be"),
    (["--ctrl_hz", "0"], "--ctrl_hz must be"),
    (["--batch_size", "0"], "--batch_size must be"),
    (["--num_minibatches", "0"], "--num_minibatches must be"),
    (["--hidden", "0"], "--hidden sizes must each be at least 1"),
    (["--max_grad_norm", "inf"], "--max_grad_norm must be"),
    (["--model", "no/such/robot.xml"], "--model no/such/robot.xml is not a file"),
])
def test_numeric_flags_out_of_range_are_rejected(flags, message, tmp_path):
    cfg = config.parse_args([*flags, "--run_dir", str(tmp_path / "run")])
    with pytest.raises(config.ConfigError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")
                       .replace("]", r"\]")):
        config.validate(cfg)
    assert not (tmp_path / "run").exists()


def test_model_flag_reaches_the_environment(tmp_path):
    from hexa_mjx.robot import constants as robot

    copy = tmp_path / "robot.xml"  # the model references no mesh files, so a copy loads anywhere
    copy.write_text(robot.MODEL_XML.read_text())
    cfg = config.validate(config.parse_args(["--model", str(copy), "--run_dir", str(tmp_path / "run")]))
    assert config.make_env_for(cfg).config.model_path == str(copy)
    assert config.make_env_for(cfg, task="navigate").config.model_path == str(copy)


def test_reward_scale_flag_reaches_the_environment_and_survives_the_run_config(tmp_path):
    argv = ["--task", "navigate", "--reward_scale", "body_contact=-30", "energy=0", "--run_dir", str(tmp_path / "run")]
    cfg = config.validate(config.parse_args(argv))
    scales = config.make_env_for(cfg).scales
    assert scales["body_contact"] == -30.0 and scales["energy"] == 0.0
    assert scales["goal_reached"] == reward_variants()["navigate"]["goal_reached"]  # the rest untouched
    (tmp_path / "run" / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    assert config.make_env_for(config.load_config(tmp_path / "run")).scales["body_contact"] == -30.0


@pytest.mark.parametrize("old, new", [("convert", "robot.convert"), ("sweeps", "studies.robustness")])
def test_commands_of_earlier_versions_still_run(old, new):
    proc = subprocess.run([sys.executable, "-m", f"hexa_mjx.{old}", "--help"], capture_output=True, text=True)
    assert proc.returncode == 0 and f"python -m hexa_mjx.{new}" in proc.stdout, proc.stderr


def test_import_hooks_import_nothing_while_finding():
    # Python 3.12 starts without importlib.machinery loaded: a finder that imports it while finding
    # a module is asked to find it again, without end. Dropping it here makes 3.11 do the same.
    code = ("import sys, hexa_mjx\n"
            "for name in ('importlib.machinery', 'importlib.util'): sys.modules.pop(name, None)\n"
            "import json.tool\n"
            "print('imported')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0 and "imported" in proc.stdout, proc.stderr[-2000:]


def test_init_from_takes_another_tasks_policy_that_observes_as_many_values(tmp_path, capsys):
    from hexa_mjx.robot import constants as robot
    from hexa_mjx.training import config as train_config

    navigate = str(robot.REPO_ROOT / "policies" / "navigate")

    cfg = train_config.parse_args(["--task", "velocity", "--init_from", navigate, "--run_dir",
                                   str(tmp_path / "a")])
    assert train_config.validate(cfg).init_from == navigate
    assert "navigate-task policy" in capsys.readouterr().out
    cfg = train_config.parse_args(["--task", "goal", "--init_from", navigate, "--run_dir", str(tmp_path / "b")])
    with pytest.raises(train_config.ConfigError, match="observing 67 values, 'goal' here, 52"):
        train_config.validate(cfg)
