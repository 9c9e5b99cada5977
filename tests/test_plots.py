"""Learning-curve plots from synthetic metrics files."""

import json

import matplotlib.image as mpimg
import pytest

from hexa_mjx.evaluation import plots


def test_plot_runs_writes_png(tmp_path):
    for name, slope in (("a", 1.0), ("b", 0.5)):
        run = tmp_path / name
        run.mkdir()
        rows = [{"step": s, "final_distance": 1.5 - slope * s / 1e6, "success_rate": slope * s / 2e6,
                 "episode_return": 100 * slope * s / 1e6, "goal_bonus": 10 * s / 1e6} for s in (0, 5e5, 1e6)]
        (run / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    out = plots.plot_runs([tmp_path / "a", tmp_path / "b"], tmp_path / "img" / "curves.png", title="t")
    image = mpimg.imread(out)
    assert image.shape[0] > 300 and image.shape[1] > 500
    assert image.std() > 0.01  # not blank


def test_missing_metrics_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="is .* a train.py run directory"):
        plots.read_metrics(tmp_path)


def test_curriculum_runs_get_falls_and_level_panels(tmp_path):
    rows = [{"step": s, "final_distance": 1.0, "success_rate": 0.5, "episode_return": 1.0, "goals_per_episode": 2.0,
             "fall_rate": 0.1, "curriculum/level_mean": s / 1e6} for s in (0, 1e6)]
    keys = [key for key, _ in plots.panels_for(rows)]
    assert keys[3] == "goals_per_episode" and keys[-2:] == ["fall_rate", "curriculum/level_mean"]
    plain = [{k: v for k, v in r.items() if not k.startswith("curriculum")} for r in rows]
    assert "curriculum/level_mean" not in [key for key, _ in plots.panels_for(plain)]
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    image = mpimg.imread(plots.plot_runs([run], tmp_path / "c.png"))
    assert image.shape[1] > 1.3 * image.shape[0]  # three panels wide


def test_scheduled_leg_failure_runs_get_one_line_per_leg(tmp_path):
    rows = [{"step": s, "final_distance": 1.0, "success_rate": 0.5, "episode_return": 1.0, "goals_per_episode": 2.0,
             "fall_rate": 0.1, **{f"leg_failure/p_leg{k}": k / 21 for k in range(1, 7)}} for s in (0, 1e6)]
    panels = [key for key, _ in plots.panels_for(rows)]
    assert panels[-2:] == ["fall_rate", "leg_failure/p_leg*"]
    lines = plots.series(rows, "leg_failure/p_leg*")
    assert list(lines) == [f" leg {k}" for k in range(1, 7)] and lines[" leg 3"] == [3 / 21, 3 / 21]
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    assert mpimg.imread(plots.plot_runs([run], tmp_path / "c.png")).std() > 0.01


def test_velocity_runs_get_tracking_panels_instead_of_goals(tmp_path):
    rows = [{"step": s, "final_distance": 1.0, "success_rate": 0.0, "goal_bonus": 5e4, "goals_per_episode": 0.0,
             "episode_return": 8e3, "episode_length": 990.0, "fall_rate": 0.1, "curriculum/level_mean": s / 1e6,
             "eval/episode_reward/tracking_lin_vel": 6e3, "eval/episode_reward/tracking_ang_vel": 2e3}
            for s in (0, 1e6)]
    keys = [key for key, _ in plots.panels_for(rows)]
    assert keys[:2] == ["eval/episode_reward/tracking_lin_vel", "eval/episode_reward/tracking_ang_vel"]
    assert not {"final_distance", "success_rate", "goal_bonus"} & set(keys)
    assert keys[-2:] == ["fall_rate", "curriculum/level_mean"]
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    assert mpimg.imread(plots.plot_runs([run], tmp_path / "c.png")).std() > 0.01
