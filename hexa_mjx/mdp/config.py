"""Environment settings, shared by the MJX environment and the native-MuJoCo engine.

Imports neither JAX nor MuJoCo: the player and deployment code read these settings too.
"""

from __future__ import annotations

import dataclasses
import math

from hexa_mjx.robot import constants as robot
from hexa_mjx.mdp.terrain import KINDS as TERRAINS, LEVEL_TILES

STAY_AFTER_MAX = 3  # goals completed, at most, before the one that stays (goal_stay_share)


def setting(default, help: str, **meta):
    """A field with its help (and argparse metadata: choices, nargs, type), shown by every command."""
    if isinstance(default, (list, tuple, dict)):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata={"help": help, **meta})
    return dataclasses.field(default=default, metadata={"help": help, **meta})


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """Environment settings; `make_env(**overrides)` sets any of them by name. Fields with help are
    the command-line flags of train.py, eval.py and play.py (hexa_mjx.cli)."""

    task: str = "goal"  # a key of hexa_mjx.tasks.TASKS
    reward: str = ""  # a reward variant of the task (hexa_mjx.tasks); "": the task's own
    ablate: tuple[str, ...] = ()  # keys of rewards.ABLATIONS whose terms are zeroed
    reward_scales: dict = dataclasses.field(default_factory=dict)  # per-term scale overrides
    model_path: str = str(robot.MODEL_XML)
    ctrl_hz: float = setting(60.0, "control rate, Hz (240 / whole number)")
    episode_length: int = setting(1000, "control steps per episode")
    success_radius: float = 0.5  # m
    # The goal bonus is paid only while nothing but the feet touches the floor. The report pays it
    # for being within the radius; with that, policies reached the goal, then rested on their shins
    # there for the rest of the episode (100 per step dwarfs -1 per contact). False: the report's bonus.
    bonus_on_feet_only: bool = True
    target_height: float = 0.12  # m, torso-origin height the height term aims for
    lift_clearance: float = 0.02  # m, foot height above which a leg's floor contact is "bad"
    settle_steps: int = 100  # physics steps the start pose settles before the first observation
    # Start-state noise, drawn per reset (the report starts every episode from the same pose).
    start_joint_noise: float = setting(0.0, "rad, uniform noise on each joint's start angle, drawn per episode "
                                            "(0: the report's fixed start)")
    start_yaw_noise: float = setting(0.0, "rad, uniform noise on the start heading, drawn per episode (tasks that "
                                          "start from any heading ignore it)")
    solver_iterations: int | None = None  # None: the model's own setting
    ls_iterations: int | None = None
    # MJX gives every robot-floor geom pair fixed contact slots (40 on the report's hexapod: box 4,
    # capsules 2, spheres 1) and solves for all of them each step. N > 0 keeps only the N deepest
    # (MJX's `max_contact_points`); 0 keeps every slot. See docs/RESULTS.md, "Speed".
    max_contact_points: int = setting(0, "MJX keeps only this many deepest robot-floor contacts per step "
                                         "(0: all 40 slots)")
    goal_distance: float = setting(1.5, "goal task: m, the goal's distance ahead (+x) of the start")
    # Navigation: goals at a bearing uniform over 360 degrees from the torso and a distance uniform
    # in [goal_min_distance, goal_max_distance]; a new one each time one is reached.
    goal_min_distance: float = setting(0.5, "navigate: m, nearest goal distance drawn")
    goal_max_distance: float = setting(3.0, "navigate: m, farthest goal distance drawn")
    # Navigation: the observed distance is capped here (0: goal_max_distance). A policy keeps the
    # cap it was trained with when evaluated on another range.
    goal_distance_cap: float = 0.0  # m
    # Goal tasks: the goal terms pay for approach and speed toward the goal up to this speed, so a
    # policy can be asked for a cruise speed it keeps on a failed leg, as a path follower's commands are.
    goal_speed_cap: float = setting(0.0, "goal tasks: m/s, the goal terms (approach, speed toward the goal) pay for "
                                         "speed up to this and no more (0: no cap, the report's terms)")
    # Navigation: chained goals never ask the policy to stop, yet a path's last waypoint does. In
    # this share of episodes, after 0 to STAY_AFTER_MAX goals, the next goal stays where it is once
    # reached, and the in-radius bonus pays for standing on it (hexa_mjx.mdp.events.draw_stay_after).
    goal_stay_share: float = setting(0.0, f"navigate: share of episodes in which, after 0 to {STAY_AFTER_MAX} random "
                                          "goals, the goal stays put once reached, so the policy learns to stop and "
                                          "stand at a goal (waypoint paths: their last waypoint always stays)")
    # Training only: hexa_mjx.mdp.curriculum; on a terrain the level also picks the column of
    # terrain squares an episode starts on (hexa_mjx.mdp.terrain).
    curriculum_levels: int = setting(0, "a curriculum of this many levels (0: none), training only: navigate's "
                                        "goals start near and ahead and their ranges open as an environment reaches "
                                        "goals; on a terrain each level starts on harder squares (velocity: up a "
                                        "level for an episode that walks its commands without a fall; "
                                        "hexa_mjx.mdp.curriculum)")
    waypoints: tuple = setting((), "navigate: walk a path instead, \"x,y x,y ...\" in metres from the start, world "
                                   "frame, or a file holding that; the last waypoint stays the goal")
    # Velocity commands (hexa_mjx.tasks.velocity): (vx, vy, yaw rate) in the heading frame, drawn
    # uniformly in these ranges, held for command_interval, a share of them exactly zero (stand).
    command_vx: tuple = setting((-0.5, 0.6), "velocity: m/s, forward speed range MIN MAX of the commands",
                                nargs=2, type=float, metavar=("MIN", "MAX"))
    command_vy: tuple = setting((-0.5, 0.5), "velocity: m/s, sideways (left) speed range MIN MAX of the commands",
                                nargs=2, type=float, metavar=("MIN", "MAX"))
    command_yaw_rate: tuple = setting((-1.0, 1.0), "velocity: rad/s, yaw rate range MIN MAX of the commands "
                                      "(counter-clockwise positive)", nargs=2, type=float, metavar=("MIN", "MAX"))
    command_interval: float = setting(4.0, "velocity: s each command holds before the next is drawn")
    command_zero_share: float = setting(0.1, "velocity: share of the commands that are exactly zero (stand still)")
    tracking_sigma: float = setting(0.25, "velocity: width of the tracking terms exp(-error^2 / sigma), (m/s)^2 and "
                                    "(rad/s)^2 (legged_gym's and Playground's 0.25); the yaw-rate term's too unless "
                                    "--yaw_tracking_sigma is set")
    yaw_tracking_sigma: float = setting(0.0, "velocity: width of the yaw-rate tracking term alone, (rad/s)^2, as "
                                        "Isaac Lab sets each term's own; 0: the same as --tracking_sigma")
    command_heading_share: float = setting(0.0, "velocity: share of the commands that give a heading to turn to "
                                                "instead of a yaw rate (legged_gym's heading mode)")
    goal_mode_share: float = setting(0.5, "drive: share of the episodes in goal mode (the navigate task's goals); "
                                          "the rest follow velocity commands. A waypoint path is walked in goal mode")
    command_mode_gain: float = setting(1.0, "drive: every reward term of a command-mode step is multiplied by "
                                            "this, so that the two modes' advantages weigh alike in PPO's batch")
    # Leg failure: a failed leg's three servos stop working. The policy is not told which leg failed.
    disabled_legs: tuple = setting((), "legs whose servos fail in every episode, e.g. \"3\" or \"1 4\" "
                                       "(numbers from 1)")
    leg_failure: str = setting("none", "'random': each episode one random leg's servos fail (with "
                                       "--leg_failure_rate); the policy is not told which", choices=["none", "random"])
    leg_failure_rate: float = setting(0.5, "probability that an episode has a failed leg (--leg_failure random)")
    leg_failure_weights: tuple = setting((), "relative chance of each leg (1, 2, ...) being the failed one "
                                             "(--leg_failure random), e.g. 1 1 3 3 1 1 (default: uniform)",
                                         nargs="+", type=float)
    failure_mode: str = setting("limp", "a failed leg's servos give no torque (limp), hold the start angles "
                                        "(locked), or either with even odds, drawn per episode (mixed)",
                                choices=["limp", "locked", "mixed"])
    leg_failure_pairs: float = setting(0.0, "share of the failing episodes (--leg_failure random) in which two "
                                            "non-adjacent legs fail instead of one, the pair drawn uniformly")
    push_speed: float = setting(0.0, "m/s, pushes: the torso's planar velocity is kicked by up to this every "
                                     "--push_interval in a random direction (0: none)")
    push_interval: float = setting(3.0, "s between pushes")
    action_latency: float = setting(0.0, "control steps (0 to 1): each episode's commands reach the servos up to "
                                         "this late; until then the previous command holds")
    obs_noise: float = setting(0.0, "observation noise, a multiple of hexa_mjx.mdp.observations.NOISE_SCALES "
                                    "(1: Playground's levels)")
    terrain: str = setting("flat", "ground: the flat floor, or a heightfield (hexa_mjx.mdp.terrain: 4 cm bumps, "
                                   "10-degree slopes, 3 cm steps, patches of each (mixed), 15-degree slopes "
                                   "(steep), stairs of 5 cm risers, or patches of every kind (hard))", choices=list(TERRAINS))
    terrain_seed: int = setting(0, "seed of the generated terrain")
    terrain_difficulty: float = setting(1.0, "the terrain's heights and slopes as a fraction of the full sizes "
                                             "(0 to 1)")


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
    if not (math.isfinite(config.goal_stay_share) and 0 <= config.goal_stay_share <= 1):
        raise ValueError(f"goal_stay_share is a share of the episodes in [0, 1], got {config.goal_stay_share}")
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
    if config.failure_mode not in ("limp", "locked", "mixed"):
        raise ValueError(f"failure_mode is 'limp', 'locked' or 'mixed', got {config.failure_mode!r}")
    if not (math.isfinite(config.leg_failure_pairs) and 0 <= config.leg_failure_pairs <= 1):
        raise ValueError(f"leg_failure_pairs is a share of the failing episodes in [0, 1], got {config.leg_failure_pairs}")
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
    for name in ("command_vx", "command_vy", "command_yaw_rate"):
        bounds = getattr(config, name)
        if len(bounds) != 2 or not all(math.isfinite(float(b)) for b in bounds) or bounds[0] > bounds[1]:
            raise ValueError(f"{name} is a range MIN MAX of two finite numbers with MIN <= MAX, got {list(bounds)}")
    if not (math.isfinite(config.command_interval) and config.command_interval > 0):
        raise ValueError(f"command_interval must be a time above 0 s, got {config.command_interval}")
    if not (math.isfinite(config.tracking_sigma) and config.tracking_sigma > 0):
        raise ValueError(f"tracking_sigma is a width above 0, got {config.tracking_sigma}")
    if not (math.isfinite(config.yaw_tracking_sigma) and config.yaw_tracking_sigma >= 0):
        raise ValueError(f"yaw_tracking_sigma is a width above 0 (or 0 for tracking_sigma's), got "
                         f"{config.yaw_tracking_sigma}")
    if not (math.isfinite(config.goal_speed_cap) and config.goal_speed_cap >= 0):
        raise ValueError(f"goal_speed_cap is a speed in m/s above 0 (or 0 for no cap), got {config.goal_speed_cap}")
    if not (math.isfinite(config.command_mode_gain) and config.command_mode_gain > 0):
        raise ValueError(f"command_mode_gain is a factor above 0, got {config.command_mode_gain}")
    for name in ("command_zero_share", "command_heading_share", "goal_mode_share"):
        if not 0 <= getattr(config, name) <= 1:
            raise ValueError(f"{name} is a share from 0 to 1, got {getattr(config, name)}")
    for point in config.waypoints:
        if len(point) != 2 or not all(math.isfinite(float(c)) for c in point):
            raise ValueError(f"a waypoint is a pair of finite coordinates x,y in metres, got {point}")
