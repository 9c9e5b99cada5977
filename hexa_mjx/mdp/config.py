"""Environment settings, shared by the MJX environment and the native-MuJoCo engine.

Imports neither JAX nor MuJoCo: the player and deployment code read these settings too.
"""

from __future__ import annotations

import dataclasses
import math

from hexa_mjx.robot import constants as robot
from hexa_mjx.mdp.terrain import KINDS as TERRAINS, LEVEL_TILES


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Environment settings; `make_env(**overrides)` sets any of them by name."""

    task: str = "goal"  # a key of hexa_mjx.tasks.TASKS
    reward: str = ""  # a key of rewards.VARIANTS valid for the task; "": the task's own
    ablate: tuple[str, ...] = ()  # keys of rewards.ABLATIONS whose terms are zeroed
    reward_scales: dict = dataclasses.field(default_factory=dict)  # per-term scale overrides
    model_path: str = str(robot.MODEL_XML)
    ctrl_hz: float = 60.0  # Hz, policy rate; 240 Hz physics / ctrl_hz must be whole
    episode_length: int = 1000  # control steps
    success_radius: float = 0.5  # m
    # The goal bonus is paid only while nothing but the feet touches the floor. The report pays it
    # for being within the radius; with that, policies reached the goal, then rested on their shins
    # there for the rest of the episode (100 per step dwarfs -1 per contact). False: the report's bonus.
    bonus_on_feet_only: bool = True
    target_height: float = 0.12  # m, torso-origin height the height term aims for
    lift_clearance: float = 0.02  # m, foot height above which a leg's floor contact is "bad"
    settle_steps: int = 100  # physics steps the start pose settles before the first observation
    # Start-state noise, drawn per reset (the report starts every episode from the same pose).
    start_joint_noise: float = 0.0  # rad, each joint's start angle is offset uniformly in +-this
    start_yaw_noise: float = 0.0  # rad, the start heading is turned uniformly in +-this (navigate: always pi)
    solver_iterations: int | None = None  # None: the model's own setting
    ls_iterations: int | None = None
    # MJX gives every robot-floor geom pair fixed contact slots (40 on the report's hexapod: box 4,
    # capsules 2, spheres 1) and solves for all of them each step. N > 0 keeps only the N deepest
    # (MJX's `max_contact_points`); 0 keeps every slot. See docs/RESULTS.md, "Speed".
    max_contact_points: int = 0
    # Report task ("goal"): one goal this far ahead (+x) of the start.
    goal_distance: float = 1.5  # m
    # Navigation task ("navigate"): goals at a bearing uniform over 360 degrees from the torso and a
    # distance uniform in [goal_min_distance, goal_max_distance]; a new one each time one is reached.
    goal_min_distance: float = 0.5  # m
    goal_max_distance: float = 3.0  # m
    # Navigation: the observed distance is capped here (0: goal_max_distance). A policy keeps the
    # cap it was trained with when evaluated on another range.
    goal_distance_cap: float = 0.0  # m
    # Navigation, training only: a curriculum of this many levels (0: none) that opens the bearing
    # and distance ranges per environment as it reaches goals (hexa_mjx.mdp.curriculum); on a terrain
    # the level also picks the column of terrain squares it starts on (hexa_mjx.mdp.terrain).
    curriculum_levels: int = 0
    # Navigation: a fixed path instead of random goals, ((x, y), ...) in metres, world frame,
    # relative to the start position. The last waypoint stays the goal once reached.
    waypoints: tuple = ()
    # Leg failure: a failed leg's three servos stop working. "limp": no torque; "locked": held at the
    # start pose's angles. `disabled_legs` fails these legs (1-based) in every episode; with
    # `leg_failure="random"`, each episode fails one leg drawn uniformly, with probability
    # `leg_failure_rate`; `leg_failure_weights` (one per leg) make some legs likelier to be the
    # failed one. The policy is not told which leg failed.
    disabled_legs: tuple = ()
    leg_failure: str = "none"  # "none" | "random"
    leg_failure_rate: float = 0.5  # probability that an episode has a failed leg (random)
    leg_failure_weights: tuple = ()  # relative chance of each leg, legs 1, 2, ... ((): uniform)
    failure_mode: str = "limp"  # "limp" | "locked"
    # Pushes: every `push_interval` s the torso's planar velocity gets a kick in a random direction
    # of a speed uniform in [0, push_speed] m/s (0: no pushes).
    push_speed: float = 0.0  # m/s
    push_interval: float = 3.0  # s
    # Action latency: each episode's commands reach the servos this late, uniform in [0, action_latency]
    # control steps (at most 1), in whole physics steps; until then the previous command holds.
    action_latency: float = 0.0  # control steps
    # Observation noise: uniform in +-obs_noise x hexa_mjx.mdp.observations.NOISE_SCALES on joint angles and
    # velocities and the torso's velocities (0: none; 1: Playground's locomotion levels).
    obs_noise: float = 0.0
    # Rough terrain (hexa_mjx.mdp.terrain): "flat" (the floor plane), "bumps", "slopes", "steps" or
    # "mixed", generated at `terrain_seed`, its sizes scaled by `terrain_difficulty` (0 to 1).
    terrain: str = "flat"
    terrain_seed: int = 0
    terrain_difficulty: float = 1.0


def make_config(task: str = "goal", reward: str = "", **overrides) -> EnvConfig:
    """An EnvConfig from keyword settings, with a clear error for an unknown name; `ablate` may be
    one name or several, `waypoints` any sequence of (x, y) pairs."""
    fields = {f.name for f in dataclasses.fields(EnvConfig)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise TypeError(f"unknown environment setting(s) {unknown}; valid names are {sorted(fields - {'reward', 'task'})}")
    if "ablate" in overrides:
        ablate = overrides["ablate"]
        overrides["ablate"] = (ablate,) if isinstance(ablate, str) else tuple(ablate)
    if "waypoints" in overrides:
        overrides["waypoints"] = tuple(tuple(float(c) for c in p) for p in overrides["waypoints"])
    return EnvConfig(task=task, reward=reward, **overrides)


def check_config(config: EnvConfig) -> None:
    """Raise ValueError for settings out of range (before any model is built or compiled)."""
    for name in ("ctrl_hz", "success_radius", "goal_distance", "goal_max_distance", "target_height"):
        value = getattr(config, name)
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number above 0, got {value}")
    if not (math.isfinite(config.goal_distance_cap) and config.goal_distance_cap >= 0):
        raise ValueError(f"goal_distance_cap must be 0 (the range's end) or a distance in m, got {config.goal_distance_cap}")
    for name in ("start_joint_noise", "start_yaw_noise"):
        if not 0 <= getattr(config, name) <= math.pi:
            raise ValueError(f"{name} is a range in radians from 0 to pi, got {getattr(config, name)}")
    if not (math.isfinite(config.goal_min_distance) and 0 <= config.goal_min_distance <= config.goal_max_distance):
        raise ValueError(f"the goal distance range needs 0 <= min <= max, got min {config.goal_min_distance} "
                         f"and max {config.goal_max_distance} m")
    if config.episode_length < 1:
        raise ValueError(f"episode_length must be at least 1, got {config.episode_length}")
    for name in ("solver_iterations", "ls_iterations"):
        value = getattr(config, name)
        if value is not None and not (isinstance(value, int) and value >= 1):
            raise ValueError(f"{name} must be at least 1 (or None: the model's own setting), got {value}")
    if config.max_contact_points < 0:
        raise ValueError(f"max_contact_points must be 0 (every contact slot) or positive, "
                         f"got {config.max_contact_points}")
    if not (math.isfinite(config.push_speed) and 0 <= config.push_speed <= 5):
        raise ValueError(f"push_speed is a speed in m/s from 0 (no pushes) to 5, got {config.push_speed}")
    if not (math.isfinite(config.push_interval) and config.push_interval > 0):
        raise ValueError(f"push_interval must be a time above 0 s, got {config.push_interval}")
    if not (math.isfinite(config.action_latency) and 0 <= config.action_latency <= 1):
        raise ValueError(f"action_latency is in control steps from 0 to 1, got {config.action_latency}")
    if config.terrain not in TERRAINS:
        raise ValueError(f"unknown terrain {config.terrain!r}; choose one of {list(TERRAINS)}")
    if not (math.isfinite(config.terrain_difficulty) and 0 <= config.terrain_difficulty <= 1):
        raise ValueError(f"terrain_difficulty is a fraction from 0 to 1, got {config.terrain_difficulty}")
    if not (math.isfinite(config.obs_noise) and 0 <= config.obs_noise <= 10):
        raise ValueError(f"obs_noise is a multiple of the noise scales from 0 to 10, got {config.obs_noise}")
    if config.leg_failure not in ("none", "random"):
        raise ValueError(f"leg_failure is 'none' or 'random', got {config.leg_failure!r}")
    if config.failure_mode not in ("limp", "locked"):
        raise ValueError(f"failure_mode is 'limp' or 'locked', got {config.failure_mode!r}")
    if not 0 <= config.leg_failure_rate <= 1:
        raise ValueError(f"leg_failure_rate is a probability in [0, 1], got {config.leg_failure_rate}")
    weights = config.leg_failure_weights
    if weights and not (all(math.isfinite(w) and w >= 0 for w in weights) and sum(weights) > 0):
        raise ValueError(f"leg_failure_weights are relative chances, each 0 or more and not all 0, got {list(weights)}")
    if config.disabled_legs and config.leg_failure != "none":
        raise ValueError("disabled_legs and leg_failure='random' exclude each other: choose fixed or random failures")
    for leg in config.disabled_legs:
        if not isinstance(leg, int) or isinstance(leg, bool) or leg < 1:
            raise ValueError(f"disabled_legs are leg numbers from 1, got {list(config.disabled_legs)}")
    if len(set(config.disabled_legs)) != len(config.disabled_legs):
        raise ValueError(f"disabled_legs names a leg twice: {list(config.disabled_legs)}")
    if not (isinstance(config.curriculum_levels, int) and 0 <= config.curriculum_levels <= 100):
        raise ValueError(f"curriculum_levels is a whole number of levels from 0 (no curriculum) to 100, "
                         f"got {config.curriculum_levels}")
    if config.terrain != "flat" and config.curriculum_levels > LEVEL_TILES:
        raise ValueError(f"on a terrain the curriculum has at most {LEVEL_TILES} levels (the terrain's columns of "
                         f"squares), got curriculum_levels {config.curriculum_levels}")
    for point in config.waypoints:
        if len(point) != 2 or not all(math.isfinite(float(c)) for c in point):
            raise ValueError(f"a waypoint is a pair of finite coordinates x,y in metres, got {point}")
