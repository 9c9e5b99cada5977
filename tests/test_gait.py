"""Gait figures on synthetic foot-contact patterns whose answers are known by construction."""

import numpy as np
import pytest

from hexa_mjx.evaluation import gait

DT = 1 / 60  # s


def pattern(phases, duty, period, steps=600):
    """Stance (steps, legs): leg i is down for `duty` of each `period`-step cycle from phase i."""
    t = np.arange(steps)[:, None]
    return ((t / period - np.asarray(phases)[None]) % 1.0) < duty


def test_tripod():
    phases = [0, 0.5, 0.5, 0, 0, 0.5]
    stance = pattern(phases, 0.5, 20)
    xy = np.stack([np.arange(600) * 0.005, np.zeros(600)], 1)  # 0.3 m/s along x
    r = gait.analyze(stance, np.full(600, 12.0), xy, DT, mass=10.0, leg_length=0.16)
    assert r["class"] == "tripod"
    np.testing.assert_allclose(r["duty_factor"], 0.5, atol=0.02)
    np.testing.assert_allclose(r["stride_hz"], 3.0, atol=0.1)  # 60 Hz / 20 steps
    np.testing.assert_allclose(r["phase"], phases, atol=0.02)
    assert r["speed"] == pytest.approx(0.3, rel=0.01)
    assert r["froude"] == pytest.approx(0.3 ** 2 / (9.81 * 0.16), rel=0.02)
    assert r["cost_of_transport"] == pytest.approx(12.0 / (10.0 * 9.81 * 0.3), rel=0.01)  # P / (m g v)


def test_tetrapod_and_wave():
    tetra = pattern([0, 1 / 3, 2 / 3, 0, 1 / 3, 2 / 3], 2 / 3, 30)
    assert gait.analyze(tetra, np.ones(600), np.zeros((600, 2)), DT, 10.0, 0.16)["class"] == "tetrapod"
    wave = pattern([0, 1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6], 5 / 6, 36)
    assert gait.analyze(wave, np.ones(600), np.zeros((600, 2)), DT, 10.0, 0.16)["class"] == "wave"


def test_irregular_when_a_leg_never_steps_or_legs_disagree():
    stance = pattern([0, 0.5, 0.5, 0, 0, 0.5], 0.5, 20)
    stance[:, 1] = True  # one foot never lifts
    assert gait.analyze(stance, np.ones(600), np.zeros((600, 2)), DT, 10.0, 0.16)["class"] == "irregular"
    mixed = np.concatenate([pattern([0, 0.5, 0.5], 0.5, 20), pattern([0, 0.5, 0.5], 0.5, 40)], axis=1)
    assert gait.analyze(mixed, np.ones(600), np.zeros((600, 2)), DT, 10.0, 0.16)["class"] == "irregular"


def test_flicker_is_not_a_step():
    stance = pattern([0, 0.5, 0.5, 0, 0, 0.5], 0.5, 20)
    flicker = stance.copy()
    flicker[5::20, 0] = ~flicker[5::20, 0]  # one-step blips inside leg 1's stances and swings
    clean = gait.analyze(stance, np.ones(600), np.zeros((600, 2)), DT, 10.0, 0.16)
    noisy = gait.analyze(flicker, np.ones(600), np.zeros((600, 2)), DT, 10.0, 0.16)
    np.testing.assert_allclose(noisy["stride_hz"], clean["stride_hz"])
    assert noisy["class"] == "tripod"


def test_summary_over_episodes():
    stance = np.stack([pattern([0, 0.5, 0.5, 0, 0, 0.5], 0.5, 20)] * 3, axis=1)  # (T, 3 episodes, legs)
    stance[:, 2, 1] = True
    window = np.ones(stance.shape[:2])
    records = gait.of_episodes(stance, np.ones(stance.shape[:2]), np.zeros(stance.shape[:2] + (2,)), window,
                               DT, 10.0, 0.16)
    summary = gait.summarize(records)
    assert summary["class"] == "tripod" and summary["class_shares"]["irregular"] == pytest.approx(1 / 3)
    assert all(name in dict(gait.table_rows(summary)) for name in ("gait class (share of episodes)",))
