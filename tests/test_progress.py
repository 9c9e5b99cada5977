"""The progress line's time left: from the recent training rate and the evaluations still to come,
not from the rate since launch (which counts compiling)."""

import pytest

from hexa_mjx.training.progress import RATE_WINDOW, Eta


def test_time_left_uses_the_recent_rate_and_the_evaluations_to_come():
    eta = Eta(total_steps=10_000, num_evals=11)  # an evaluation every 1,000 steps
    eta.update(100.0, 0)  # 100 s of compiling before the first update: not part of any rate
    for i in range(1, RATE_WINDOW + 5):
        eta.update(100.0 + i, 100 * i)  # 100 steps/s from then on
    step = 100 * (RATE_WINDOW + 4)
    assert eta.rate == pytest.approx(100.0)
    assert eta.left(step) == pytest.approx((10_000 - step) / 100.0)  # no evaluation measured yet
    eta.evaluation(30.0)
    eta.evaluation(10.0)
    eta.evaluation(20.0)
    to_come = -(-(10_000 - step) // 1_000)
    assert eta.left(step) == pytest.approx((10_000 - step) / 100.0 + to_come * 20.0)  # the median evaluation


def test_an_evaluation_starts_a_new_rate_window():
    eta = Eta(total_steps=1_000, num_evals=2)
    eta.update(0.0, 0)
    eta.update(1.0, 100)
    eta.paused()
    eta.update(31.0, 100)  # the 30 s evaluation in between is not training time
    eta.update(32.0, 200)
    assert eta.rate == pytest.approx(100.0)
    assert Eta(1_000, 2).left(0) != Eta(1_000, 2).left(0)  # NaN before any rate


def test_damaged_metrics_lines_are_dropped_with_a_note(tmp_path, capsys):
    import json

    from hexa_mjx.training.progress import keep_rows_up_to

    path = tmp_path / "metrics.jsonl"
    path.write_text('{"step": 0, "x": 1}\n[1]\n{"step": 64}\n{"step": 64}\n{"step": 128}\n{"step": 19')
    assert keep_rows_up_to(tmp_path, 64) == {0, 64}
    assert [json.loads(line)["step"] for line in path.read_text().splitlines()] == [0, 64]
    assert f"{path}: dropped 2 line(s)" in capsys.readouterr().out
