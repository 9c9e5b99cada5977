"""Checkpoint integrity: a digest and a finiteness check on load, and resume's fall-back."""

import dataclasses
import json

import jax
import numpy as np
import pytest

from hexa_mjx.training import checkpoints, config, networks, optimizer_state


@pytest.fixture(scope="module")
def template(env):
    return networks.init_params(config.TrainConfig(hidden=[8, 8]), env)


def save_two(run_dir, template):
    bumped = jax.tree.map(lambda x: x + 1 if np.issubdtype(np.asarray(x).dtype, np.floating) else x, template)
    checkpoints.save_checkpoint(run_dir, 100, template)
    return checkpoints.save_checkpoint(run_dir, 200, bumped)


def test_a_damaged_checkpoint_is_an_error_and_resume_falls_back(template, tmp_path, capsys):
    newest = save_two(tmp_path, template)
    assert "sha256" in json.loads((newest / "step.json").read_text())
    assert checkpoints.load_latest(tmp_path, template)[0] == 200
    biggest = max((f for f in (newest / "params").rglob("*") if f.is_file()), key=lambda f: f.stat().st_size)
    data = bytearray(biggest.read_bytes())
    data[len(data) // 2:len(data) // 2 + 64] = b"\xff" * 64  # a few bytes changed on disk
    biggest.write_bytes(bytes(data))
    with pytest.raises(RuntimeError, match="do not match the checksum"):
        checkpoints.load_checkpoint(newest, template)
    step, params, _, _ = checkpoints.load_latest(tmp_path, template)
    assert step == 100 and "falling back to the checkpoint before it" in capsys.readouterr().err
    np.testing.assert_array_equal(jax.tree.leaves(params)[0], jax.tree.leaves(template)[0])


def test_non_finite_parameters_are_refused(template, tmp_path):
    poisoned = jax.tree.map(lambda x: x * np.nan if np.issubdtype(np.asarray(x).dtype, np.floating) else x, template)
    path = checkpoints.save_checkpoint(tmp_path, 100, poisoned)
    with pytest.raises(RuntimeError, match="non-finite"):
        checkpoints.load_checkpoint(path, template)
    assert checkpoints.load_latest(tmp_path, template) == (0, None, None, None)


def test_saving_and_loading_print_nothing(template, tmp_path, capfd):
    path = checkpoints.save_checkpoint(tmp_path, 100, template)
    checkpoints.load_checkpoint(path, template)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_the_optimizer_state_round_trips_and_is_checked(template, env, tmp_path):
    adam_template = optimizer_state.adam_template(template)
    adam = jax.tree.map(lambda x: np.asarray(x) + 3, adam_template)  # moments 3, step count 3
    path = checkpoints.save_checkpoint(tmp_path, 100, template, adam)
    restored = checkpoints.load_optimizer(path, adam_template)
    assert int(restored[0].count) == 3
    jax.tree.map(np.testing.assert_array_equal, restored, adam)
    with pytest.raises(RuntimeError, match="does not fit"):  # another network's sizes
        checkpoints.load_optimizer(path, optimizer_state.adam_template(
            networks.init_params(config.TrainConfig(hidden=[4, 4]), env)))
    (path / checkpoints.OPTIMIZER_FILE).write_bytes(b"damaged")
    with pytest.raises(RuntimeError, match="do not match the checksum"):
        checkpoints.load_checkpoint(path, template)
    older = checkpoints.save_checkpoint(tmp_path, 50, template)  # as written before Adam's state was saved
    assert checkpoints.load_optimizer(older, adam_template) is None


def test_resume_falls_back_past_a_bad_optimizer_state(template, tmp_path, capsys):
    adam_template = optimizer_state.adam_template(template)
    checkpoints.save_checkpoint(tmp_path, 100, template, adam_template)
    poisoned = jax.tree.map(lambda x: np.asarray(x) * np.nan if np.issubdtype(np.asarray(x).dtype, np.floating)
                            else x, adam_template)
    checkpoints.save_checkpoint(tmp_path, 200, template, poisoned)
    step, _, adam, _ = checkpoints.load_latest(tmp_path, template, adam_template)
    assert step == 100 and adam is not None and "non-finite (NaN or inf) optimizer state" in capsys.readouterr().err


def test_a_full_disk_keeps_the_last_checkpoint_and_leaves_nothing_behind(tmp_path, monkeypatch):
    import errno

    from hexa_mjx.training import crash_points as faults

    template = ({"w": np.ones(3, np.float32)},)
    checkpoints.save_checkpoint(tmp_path, 64, template)
    monkeypatch.setenv(faults.VARIABLE, "checkpoint-writing:ENOSPC")
    with pytest.raises(checkpoints.CheckpointWriteError, match="No space left on device") as caught:
        checkpoints.save_checkpoint(tmp_path, 128, template)
    assert isinstance(caught.value.__cause__, OSError) and caught.value.__cause__.errno == errno.ENOSPC
    assert "000000000128" in str(caught.value) and "--resume" in str(caught.value)
    assert [s for s, _ in checkpoints.list_checkpoints(tmp_path)] == [64]
    assert not list((tmp_path / "checkpoints").glob("tmp-*"))
    assert checkpoints.load_checkpoint(checkpoints.list_checkpoints(tmp_path)[0][1], template)[0] == 64


def velocity_row(step, lin, ang, falls, scales, length=1000.0):
    """An evaluation row of a velocity run whose tracking terms average `lin` and `ang` per step."""
    return {"step": step, "episode_length": length, "fall_rate": falls, "success_rate": 0.0,
            "eval/episode_reward/tracking_lin_vel": lin * scales["tracking_lin_vel"] * length,
            "eval/episode_reward/tracking_ang_vel": ang * scales["tracking_ang_vel"] * length}


def test_best_is_the_checkpoint_the_evaluations_chose(template, tmp_path):
    from hexa_mjx.training import checks, selection

    cfg = config.TrainConfig(task="velocity", reward_scale=["tracking_ang_vel=10"], run_dir=str(tmp_path))
    (tmp_path / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    scales = checks.run_scales(cfg)
    rows = [velocity_row(0, 0.95, 0.95, 0.0, scales),  # the evaluation before training: no checkpoint
            velocity_row(100, 0.80, 0.40, 0.0, scales), velocity_row(200, 0.90, 0.44, 0.0, scales),
            velocity_row(300, 0.91, 0.46, 0.16, scales)]  # tracks best, falls in 16% of episodes
    (tmp_path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows) + '{"step": 4')
    for step in (100, 200, 300):
        checkpoints.save_checkpoint(tmp_path, step, template)
    assert [s for s, _ in selection.scored_rows(tmp_path)] == [100, 200, 300]
    assert selection.best_step(tmp_path)[0] == 200
    assert checkpoints.resolve_checkpoint(tmp_path / "best") == (tmp_path, tmp_path / "checkpoints" / "000000000200")
    # a tie goes to the later checkpoint
    (tmp_path / "metrics.jsonl").write_text("".join(json.dumps(velocity_row(s, 0.9, 0.4, 0.0, scales)) + "\n"
                                                    for s in (100, 200, 300)))
    assert selection.best_step(tmp_path)[0] == 300


def test_a_larger_evaluation_chooses_while_it_covers_the_latest_checkpoint(template, tmp_path):
    from hexa_mjx.training import checks, reselection, selection

    cfg = config.TrainConfig(task="velocity", reward_scale=["tracking_ang_vel=10"], run_dir=str(tmp_path))
    (tmp_path / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    scales = checks.run_scales(cfg)
    write = lambda name, rows: (tmp_path / name).write_text("".join(json.dumps(r) + "\n" for r in rows))  # noqa: E731
    write("metrics.jsonl", [velocity_row(s, 0.9, 0.4, falls, scales) for s, falls in ((100, 0.1), (200, 0.0), (300, 0.1))])
    for step in (100, 200, 300):
        checkpoints.save_checkpoint(tmp_path, step, template)
    assert selection.best_step(tmp_path)[0] == 200  # the training evaluations' choice
    # the larger evaluation of the last two finds a fall at 200 and none at 300
    write(reselection.SELECTION_FILE, [velocity_row(200, 0.9, 0.4, 0.02, scales), velocity_row(300, 0.9, 0.4, 0.0, scales)])
    assert [s for s, _ in selection.scored_rows(tmp_path)] == [200, 300]
    assert checkpoints.resolve_checkpoint(tmp_path / "best")[1].name == "000000000300"
    with open(tmp_path / reselection.SELECTION_FILE, "a") as f:  # a damaged line is left out
        f.write('{"step": 3')
    assert selection.best_step(tmp_path)[0] == 300
    # trained on past it: the training evaluations choose again
    checkpoints.save_checkpoint(tmp_path, 400, template)
    write("metrics.jsonl", [velocity_row(s, 0.9, 0.4, falls, scales)
                            for s, falls in ((100, 0.1), (200, 0.0), (300, 0.1), (400, 0.05))])
    assert selection.best_step(tmp_path)[0] == 200


def test_best_of_a_run_without_evaluated_checkpoints_says_what_to_do(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps(dataclasses.asdict(config.TrainConfig(run_dir=str(tmp_path)))))
    with pytest.raises(FileNotFoundError, match="pass the run directory"):
        checkpoints.resolve_checkpoint(tmp_path / "best")


def test_selection_scores_count_falls_against_every_task():
    from hexa_mjx.tasks import TASKS

    row = {"success_rate": 1.0, "goals_per_episode": 5.0, "fall_rate": 0.0, "episode_length": 1000.0,
           "eval/episode_reward/tracking_lin_vel": 10_000.0, "eval/episode_reward/tracking_ang_vel": 5_000.0}
    scales = {"tracking_lin_vel": 10.0, "tracking_ang_vel": 5.0}
    for name, task in TASKS.items():
        assert task.selection_score({**row, "fall_rate": 0.5}, scales) < task.selection_score(row, scales), name
