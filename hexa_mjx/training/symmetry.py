"""The robot's rotational symmetry, and a loss that asks the policy to respect it (`--symmetry_loss`).

The hexapod's six legs are one leg copied around the torso's vertical axis every 60 degrees, so
calling another leg "leg 1" describes the same robot: its observation is the original's with every
planar vector turned by that leg's bearing and the legs' joints relabelled, and the action it should
take is the original's relabelled alike. A policy that learnt its gait on one labelling need not
keep it under another; one that does treats every leg alike, so that no leg carries the gait alone
(a leg failure study's concern: docs/ROBUSTNESS.md). The torso's collision box repeats under a half
turn only (its inertia nearly under every turn), so the other turns are near symmetries.

The loss is the mirror loss of symmetric locomotion (Yu et al. 2018; Mittal et al. 2024, as Isaac
Lab's rsl_rl symmetry settings add it to PPO's): the mean squared difference between the policy's
mean action on each relabelled observation and the relabelled mean action, over the turns asked.
"""

from __future__ import annotations

import numpy as np

# How each slice of an observation's layout turns with the torso's frame, by what it holds:
# "planar" turns its first two values (x, y) and keeps the rest, "legs" relabels per-joint values,
# "scalar" keeps it. A layout with a slice none of these name cannot be turned.
SLICE_RULES = (("joint angles", "legs"), ("joint velocities", "legs"), ("previous action", "legs"),
               ("command (vx, vy, yaw rate), heading frame", "planar"), ("goal direction (x, y), heading frame", "planar"),
               ("torso linear velocity (x, y) heading frame", "planar"), ("angular velocity, body frame", "planar"),
               ("gravity direction, body frame", "planar"), ("torso height", "scalar"), ("goal distance", "scalar"))
BEARING_TOLERANCE = np.radians(1.0)  # rad: how far a leg may sit from its copy's turned bearing


def leg_turns(bearings, turns: int) -> list[tuple[float, np.ndarray]]:
    """For each of `turns` equal turns of a full circle but the identity, (angle in rad, source):
    `source[i]` is the leg that sits at leg i's bearing plus the angle. Raises when a leg has no
    copy there."""
    bearings = np.asarray(bearings, float)
    out = []
    for k in range(1, turns):
        angle = 2 * np.pi * k / turns
        gap = np.angle(np.exp(1j * (bearings[None, :] - bearings[:, None] - angle)))  # [i, j]: j's bearing - i's - angle
        source = np.argmin(np.abs(gap), axis=1)
        worst = np.abs(gap[np.arange(len(bearings)), source]).max()
        if worst > BEARING_TOLERANCE or len(set(source)) != len(bearings):
            raise ValueError(f"symmetry_loss: this robot's legs do not repeat every {360 / turns:.0f} degrees "
                             f"(hip bearings {np.degrees(bearings).round(1).tolist()} deg); set --symmetry_turns to a "
                             "turn they repeat under, or leave --symmetry_loss at 0")
        out.append((angle, source))
    return out


def relabel_maps(layout, actuator_leg, bearings, turns: int) -> tuple[np.ndarray, np.ndarray]:
    """The observation and action maps of each turn: (turns - 1, obs, obs) and (turns - 1, act,
    act) matrices M with relabelled = M @ original. Joint slices and actions are in actuator order
    (`actuator_leg[a]` the leg of actuator a, the same kinds of joint in the same order per leg)."""
    actuator_leg = np.asarray(actuator_leg)
    per_leg = [np.flatnonzero(actuator_leg == leg) for leg in range(len(bearings))]
    if len({len(a) for a in per_leg}) != 1:
        raise ValueError("symmetry_loss: every leg must have the same joints")
    size = layout[-1][1]
    obs_maps, act_maps = [], []
    for angle, source in leg_turns(bearings, turns):
        act = np.zeros((len(actuator_leg), len(actuator_leg)), np.float32)
        for leg, src in enumerate(source):
            act[per_leg[leg], per_leg[src]] = 1.0
        c, s = np.cos(angle), np.sin(angle)
        turn = np.array([[c, s], [-s, c]], np.float32)  # a vector's components in the frame turned by `angle`
        obs = np.zeros((size, size), np.float32)
        for start, end, what, _ in layout:
            rule = next((r for key, r in SLICE_RULES if key in what), None)
            if rule is None:
                raise ValueError(f"symmetry_loss: the observation slice {what!r} has no rule for turning it; "
                                 "this task's observation cannot be relabelled")
            if rule == "legs":
                obs[start:end, start:end] = act
            else:
                obs[start:end, start:end] = np.eye(end - start)
                if rule == "planar":
                    obs[start:start + 2, start:start + 2] = turn
        obs_maps.append(obs)
        act_maps.append(act)
    return np.stack(obs_maps), np.stack(act_maps)


def maps_for(env, turns: int) -> tuple[np.ndarray, np.ndarray]:
    """`relabel_maps` of an environment's task and robot, its legs' bearings from the settled start."""
    robot = env.robot
    if not np.array_equal(robot.actuator_qpos, 7 + np.arange(len(robot.actuator_qpos))):
        raise ValueError("symmetry_loss: the joints' order in qpos must be the actuators' order")
    return relabel_maps(env.task.layout(len(robot.ctrl_lo)), robot.actuator_leg, robot.hip_bearings, turns)


def mirror_loss(network, weight: float, obs_maps, act_maps, policy_key=None):
    """`loss(params, normalizer, observation) -> weight x mean squared gap` between the policy's
    mean action on each relabelled observation and the relabelled mean action (the latter held
    fixed, as rsl_rl holds it). `policy_key`: the policy's entry of a dict observation."""
    import jax
    import jax.numpy as jp

    obs_maps, act_maps = jp.asarray(obs_maps), jp.asarray(act_maps)
    act_size = act_maps.shape[-1]

    def mean_action(params, normalizer, obs):
        out = network.policy_network.apply(normalizer, params.policy, obs)
        # brax's Gaussian policy returns (mean, std); its tanh-Gaussian one, mean and scale in one array
        return out[0] if isinstance(out, tuple) else out[..., :act_size]

    def loss(params, normalizer, observation):
        own = observation[policy_key] if policy_key else observation
        turned = jp.einsum("kij,...j->k...i", obs_maps, own)  # (turns - 1, batch..., obs)
        if policy_key:  # the policy network reads its own entry alone
            turned = {policy_key: turned}
        target = jp.einsum("kij,...j->k...i", act_maps, jax.lax.stop_gradient(mean_action(params, normalizer, own)))
        return weight * jp.mean((mean_action(params, normalizer, turned) - target) ** 2)

    return loss
