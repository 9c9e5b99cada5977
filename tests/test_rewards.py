"""Reward terms as pure functions, and the variant/ablation scale tables."""

import jax.numpy as jp
import numpy as np
import pytest

from hexa_mjx.mdp import rewards
from hexa_mjx.tasks import reward_variants

VARIANTS = reward_variants()


def scaled(term, *args, reward="goal_directed"):
    return VARIANTS[reward][term] * float(rewards.TERMS[term](*args))


def test_one_cm_toward_goal_gives_ten():
    assert scaled("goal_approach", jp.float32(1.50), jp.float32(1.49)) == pytest.approx(10.0, rel=1e-4)
    assert scaled("goal_approach", jp.float32(1.49), jp.float32(1.50)) == pytest.approx(-10.0, rel=1e-4)


def test_velocity_alignment_is_speed_toward_goal():
    goal_dir = jp.array([1.0, 0.0])
    assert scaled("velocity_alignment", jp.array([0.2, 0.0]), goal_dir) == pytest.approx(1.0)
    assert scaled("velocity_alignment", jp.array([0.0, 0.3]), goal_dir) == pytest.approx(0.0)
    assert scaled("velocity_alignment", jp.array([-0.2, 0.0]), goal_dir) == pytest.approx(-1.0)
    # 5 * |v| * cos(45 deg) for a diagonal velocity
    assert scaled("velocity_alignment", jp.array([0.1, 0.1]), goal_dir) == pytest.approx(5 * np.hypot(0.1, 0.1) * np.cos(np.pi / 4))


@pytest.mark.parametrize("xp", [np, jp], ids=["numpy", "jax"])
def test_goal_speed_cap_pays_speed_toward_the_goal_up_to_the_cap_only(xp):
    """Both goal terms, through rewards.terms as either engine calls it: a walk at 1.2 m/s toward
    a goal 2 m ahead is paid as one at the 0.8 m/s cap; 0.5 m/s and a step away are paid in full."""
    from hexa_mjx.mdp.config import EnvConfig

    def paid(speed, cap):
        config = EnvConfig(goal_speed_cap=cap)
        qpos, qvel = np.zeros(25), np.zeros(24)
        qpos[0], qvel[0] = speed / config.ctrl_hz, speed  # one control step toward +x at `speed`
        out = rewards.terms(["goal_approach", "velocity_alignment"], config, xp.zeros(25), xp.asarray(qpos),
                            xp.asarray(qvel), xp.asarray([2.0, 0.0]), 0, 0, False, False, 0.0)
        return float(out["goal_approach"]) * config.ctrl_hz, float(out["velocity_alignment"])  # both in m/s

    assert paid(1.2, 0.0) == pytest.approx((1.2, 1.2), rel=1e-4)
    assert paid(1.2, 0.8) == pytest.approx((0.8, 0.8), rel=1e-4)
    assert paid(0.5, 0.8) == pytest.approx((0.5, 0.5), rel=1e-4)
    assert paid(-0.5, 0.8) == pytest.approx((-0.5, -0.5), rel=1e-4)


def test_goal_speed_cap_is_a_speed():
    from hexa_mjx.mdp.config import EnvConfig, check_config

    with pytest.raises(ValueError, match="goal_speed_cap is a speed in m/s"):
        check_config(EnvConfig(goal_speed_cap=-1.0))


def test_goal_bonus_only_inside_radius():
    assert scaled("goal_bonus", jp.float32(0.49), 0.5) == 100.0
    assert scaled("goal_bonus", jp.float32(0.51), 0.5) == 0.0


def test_goal_bonus_needs_only_feet_on_the_floor():
    assert scaled("goal_bonus", jp.float32(0.2), 0.5, jp.int32(0)) == 100.0
    assert scaled("goal_bonus", jp.float32(0.2), 0.5, jp.int32(2)) == 0.0


def test_shaping_penalties():
    assert scaled("stability", jp.float32(0.1), jp.float32(-0.2)) == pytest.approx(-0.15)
    assert scaled("height", jp.float32(0.22), 0.12) == pytest.approx(-0.2)
    assert scaled("height", jp.float32(0.02), 0.12) == pytest.approx(-0.2)
    assert scaled("energy", jp.full(18, 2.0)) == pytest.approx(-1e-4 * 18 * 4)
    assert scaled("contact_quality", jp.int32(3)) == pytest.approx(-1.5)
    assert scaled("body_contact", jp.int32(2)) == pytest.approx(-2.0)
    assert scaled("termination", jp.bool_(True)) == -200.0
    assert scaled("termination", jp.bool_(False)) == 0.0


def test_idle_feet_counts_working_feet_up_longer_than_the_limit():
    limit = rewards.IDLE_AIR_TIME
    air = jp.asarray([0.0, limit + 0.1, limit - 0.1, 3.0, limit + 0.01, 0.2])
    assert float(rewards.idle_feet(air, jp.ones(6))) == 3.0  # legs 2, 4 and 5
    failed_leg_4 = jp.asarray([1.0, 1.0, 1.0, 0.0, 1.0, 1.0])  # a limp leg's foot is not the policy's
    assert float(rewards.idle_feet(air, failed_leg_4)) == 2.0
    assert rewards.make_scales(VARIANTS["navigate"])["idle_feet"] == 0.0  # off unless asked for
    assert rewards.make_scales(VARIANTS["navigate"])["low_duty"] == 0.0
    assert rewards.make_scales(VARIANTS["navigate"], overrides={"idle_feet": -5})["idle_feet"] == -5.0


def test_low_duty_is_each_working_feet_shortfall_below_the_minimum_share():
    share = jp.asarray([0.0, rewards.MIN_DUTY / 2, rewards.MIN_DUTY, 0.5, 0.0, 1.0])
    assert float(rewards.low_duty(share, jp.ones(6))) == pytest.approx(1.0 + 0.5 + 0 + 0 + 1.0 + 0)
    assert float(rewards.low_duty(share, jp.asarray([1.0, 1.0, 1.0, 1.0, 0.0, 1.0]))) == pytest.approx(1.5)


def test_feet_air_time_pays_each_touchdown_for_its_swing_within_the_window():
    lo, hi = rewards.AIR_TIME_MIN, rewards.AIR_TIME_MAX
    swing = jp.asarray([0.0, lo, lo + 0.1, hi + 1.0, 0.05, 0.0])  # legs 1 and 6 did not touch down now
    expected = 0.0 + 0.0 + 0.1 + (hi - lo) + (0.05 - lo)
    assert float(rewards.feet_air_time(swing, jp.ones(6))) == pytest.approx(expected)
    failed_leg_4 = jp.asarray([1.0, 1.0, 1.0, 0.0, 1.0, 1.0])
    assert float(rewards.feet_air_time(swing, failed_leg_4)) == pytest.approx(expected - (hi - lo))
    assert float(rewards.feet_air_time(swing, jp.ones(6), moving=0.0)) == 0.0  # standing still: no term


def test_foot_slip_is_the_squared_speed_of_the_feet_on_the_floor():
    speed = jp.asarray([0.1, 0.2, 0.0, 1.0, 0.3, 0.0])
    stance = jp.asarray([1.0, 1.0, 1.0, 0.0, 1.0, 0.0])  # leg 4 swings: its speed does not count
    assert float(rewards.foot_slip(speed, stance)) == pytest.approx(0.01 + 0.04 + 0.09)
    assert float(rewards.foot_slip(speed, stance, moving=0.0)) == 0.0
    assert rewards.make_scales(VARIANTS["navigate"])["feet_air_time"] == 0.0  # both off unless asked for
    assert rewards.make_scales(VARIANTS["navigate"])["foot_slip"] == 0.0


def test_running_stance_settles_at_the_share_of_time_down():
    dt, avg = 1 / 60, jp.ones(2)
    for t in range(60 * 20):  # 20 s of a foot down one step in four, and one never down
        avg = rewards.running_stance(avg, jp.asarray([t % 4 == 0, False]), dt)
    assert float(avg[0]) == pytest.approx(0.25, abs=0.02)
    assert float(avg[1]) < 1e-6  # e^-20


def test_forward_motion_terms():
    # 1000 * d_moved * cos(theta): 2 cm at 60 degrees off +x gives 1 cm of forward progress
    prev, now = jp.array([0.0, 0.0]), jp.array([0.02 * np.cos(np.pi / 3), 0.02 * np.sin(np.pi / 3)])
    assert scaled("forward_progress", prev, now, reward="forward_motion") == pytest.approx(10.0, rel=1e-4)
    assert scaled("forward_velocity", jp.array([0.3, 0.5]), reward="forward_motion") == pytest.approx(1.5)


def test_variants_differ_only_in_task_terms():
    goal, forward = VARIANTS["goal_directed"], VARIANTS["forward_motion"]
    assert set(goal) == set(forward) == set(VARIANTS["navigate"]) == set(rewards.TERMS)
    navigate = VARIANTS["navigate"]
    assert {k for k in goal if goal[k] != navigate[k]} == {"goal_reached", "body_contact"}
    differing = {k for k in goal if goal[k] != forward[k]}
    assert differing == {"goal_approach", "velocity_alignment", "goal_bonus", "forward_progress", "forward_velocity"}
    assert forward["goal_bonus"] == 0.0


@pytest.mark.parametrize("reward", sorted(VARIANTS))
@pytest.mark.parametrize("ablation", sorted(rewards.ABLATIONS))
def test_ablation_zeroes_exactly_its_terms(reward, ablation):
    full = rewards.make_scales(VARIANTS[reward])
    ablated = rewards.make_scales(VARIANTS[reward], ablate=[ablation])
    for term in full:
        expected = 0.0 if term in rewards.ABLATIONS[ablation] else full[term]
        assert ablated[term] == expected, term


def test_scale_overrides_and_errors():
    report = VARIANTS["goal_directed"]
    assert rewards.make_scales(report, overrides={"height": -5})["height"] == -5.0
    with pytest.raises(ValueError, match="unknown ablation 'legs'"):
        rewards.make_scales(report, ablate=["legs"])
    with pytest.raises(ValueError, match="unknown reward term 'speed'"):
        rewards.make_scales(report, overrides={"speed": 1.0})
    assert rewards.make_scales(report, overrides={"speed": 1.0}, extra_terms=("speed",))["speed"] == 1.0
