"""One episode's logic for both engines: what happens around the physics on every control step.

`Episode` holds a task, its settings and the robot; the MJX environment and the native-MuJoCo
environment (`hexa_mjx.engines`) each own one and supply only their physics step, their contact
arrays and their random draws. The episode's bookkeeping is a dict of arrays (`info`), the same in
both engines: steps taken, success so far, goals completed, the curriculum level, the failed legs,
each foot's air time and running stance, the action latency, and after how many goals the goal
stays put (a waypoint path's length, or a draw under `--goal_stay_share`).
"""

from __future__ import annotations

import dataclasses

from hexa_mjx.mdp import curriculum, events, rewards
from hexa_mjx.mdp.config import EnvConfig, check_config
from hexa_mjx.robot.kinematics import fell as flipped, namespace
from hexa_mjx.robot.model import RobotModel, servo_power
from hexa_mjx.tasks import reward_variants, task_class


@dataclasses.dataclass(frozen=True)
class Contacts:
    """Robot-floor contact arrays of either engine: the geom pair and distance of each contact slot,
    and the foot spheres' centres (feet, 3), m."""

    geom1: object
    geom2: object
    dist: object
    foot_pos: object


def make_episode(config: EnvConfig, observe_as: str = "") -> "Episode":
    """The episode of `config`'s task, its settings checked, its robot built; `observe_as` names
    another task whose observation the policy sees (the report's policy on navigation goals)."""
    task_cls = task_class(config.task)
    config = dataclasses.replace(config, reward=config.reward or next(iter(task_cls.rewards)))
    check_config(config)
    task_cls.check(config)
    if config.goal_stay_share and not task_cls.chains_goals:
        raise ValueError(f"goal_stay_share keeps a goal in place among goals that follow one another; the "
                         f"{task_cls.name} task has none: leave it at 0 (the navigate task has them)")
    if config.reward not in reward_variants():
        raise ValueError(f"unknown reward {config.reward!r}; the {task_cls.name} task's are {list(task_cls.rewards)}")
    if config.reward not in task_cls.rewards:
        raise ValueError(f"reward {config.reward!r} is not one of the {task_cls.name} task's: {list(task_cls.rewards)}")
    scales = rewards.make_scales(task_cls.rewards[config.reward], config.ablate, config.reward_scales,
                                 extra_terms=task_cls.terms)
    robot = RobotModel(config)
    task = task_cls(config, robot)
    observer = task_class(observe_as)(config, robot) if observe_as and observe_as != task.name else task
    dt = robot.n_substeps * float(robot.mj_model.opt.timestep)
    return Episode(task, observer, scales, dt, robot.n_substeps)


class Episode:
    """The task-independent episode around a `task` (hexa_mjx.tasks): start, events, reward, ending."""

    def __init__(self, task, observer, scales: dict, dt: float, n_substeps: int):
        self.task, self.observer, self.scales = task, observer, scales
        self.config, self.robot = task.config, task.robot
        self.dt, self.n_substeps = dt, n_substeps
        self.active = [name for name, scale in scales.items() if scale != 0.0]
        self.push_every = events.push_steps(self.config.push_interval, dt)
        self.noise_scale = self.config.obs_noise * observer.noise_scale()
        # A curriculum over commands measures each episode's walking: m asked for and m walked.
        self.measures_walking = bool(self.config.curriculum_levels) and task.uses_command

    # -- starting an episode --------------------------------------------------

    def start_qpos(self, qpos0, draws, key, level=0, spawn=None):
        """An episode's start pose: the settled pose with the start noise, on a terrain at the
        curriculum `level`'s column (`spawn`: the terrain's square centres)."""
        cfg = self.config
        qpos = events.start_qpos(qpos0, cfg.start_joint_noise, self.task.start_yaw_range, self.robot.joint_lo,
                                 self.robot.joint_hi, draws, key)
        if spawn is not None and cfg.curriculum_levels:  # training only, so JAX only
            qpos = qpos.at[:2].add(events.level_spawn(level, spawn, draws, draws.fold_in(key, 6)))
        return qpos

    def start_info(self, draws, key) -> dict:
        """The bookkeeping of a new episode."""
        xp, legs = draws.xp, len(self.robot.legs)
        return {"t": xp.zeros((), xp.int32), "success": xp.zeros(()), "goals": xp.zeros((), xp.int32),
                "level": xp.zeros((), xp.int32),  # the curriculum's level, kept across episodes
                "failed_legs": events.draw_failure(self.config, legs, draws, draws.fold_in(key, 3),
                                                   pairs=self.robot.non_adjacent_pairs),
                "air_time": xp.zeros(legs),  # s since each foot last touched the floor
                "stance_avg": xp.ones(legs),  # running share of time on the floor (all down)
                "latency": events.draw_latency(self.config.action_latency, draws, draws.fold_in(key, 4)),
                **self._failure_kind(draws, key), **self._walking(xp), **self._stay(draws, key),
                # the feet's planar positions after the last step, for foot_slip (first step: unused)
                **({"foot_xy": xp.zeros((legs, 2))} if "foot_slip" in self.active else {})}

    # -- one control step -----------------------------------------------------

    def observe(self, qpos, qvel, ctrl, goal, heading, command, draws, key):
        """The policy's observation, with the configured noise."""
        obs = self.observer.observe(qpos, qvel, ctrl, goal, heading, command)
        return events.noisy(obs, self.noise_scale, draws, key) if self.config.obs_noise else obs

    def _gait_inputs(self, info, qpos, command, heading, stance, foot_pos) -> dict:
        """The gait terms' inputs (rewards.feet_air_time, rewards.foot_slip), when one is active:
        each foot's swing ending this step (s), stance, planar speed over the control step (m/s; 0
        on an episode's first step, whose previous position is the last episode's) and whether the
        command asks to move."""
        if "feet_air_time" not in self.active and "foot_slip" not in self.active:
            return {}
        xp = namespace(qpos)
        moving = 1.0
        if self.task.uses_command:
            moving = (xp.linalg.norm(self.task.commanded(command, qpos, heading)) > rewards.MOVING).astype(xp.float32)
        out = {"swing": xp.where(stance & (info["air_time"] > 0), info["air_time"], 0.0),
               "stance": stance.astype(xp.float32), "moving": moving}
        if "foot_xy" in info:
            step = xp.linalg.norm(foot_pos[:, :2] - info["foot_xy"], axis=-1) / self.dt
            out["foot_speed"] = xp.where(info["t"] > 0, step, 0.0)
        return out

    def _walking(self, xp) -> dict:
        """{"asked_m", "walked_m"} of a new episode, when the curriculum measures walking."""
        return {"asked_m": xp.zeros(()), "walked_m": xp.zeros(())} if self.measures_walking else {}

    def _stay(self, draws, key) -> dict:
        """{"stay_after": goals completed before the goal stays put once reached} of a new episode:
        a waypoint path's length (its last waypoint stays), a draw under goal_stay_share, or
        nothing (goals follow one another to the end)."""
        if self.config.waypoints:
            return {"stay_after": draws.xp.asarray(len(self.config.waypoints), draws.xp.int32)}
        if not self.config.goal_stay_share:
            return {}
        return {"stay_after": events.draw_stay_after(self.config.goal_stay_share, draws, draws.fold_in(key, 10))}

    def _failure_kind(self, draws, key) -> dict:
        """{"failure_locked": 0/1} of a new episode under failure_mode "mixed"; nothing otherwise."""
        if self.config.failure_mode != "mixed":
            return {}
        return {"failure_locked": events.draw_locked(self.config, draws, draws.fold_in(key, 9))}

    def failed_servos(self, info):
        """Whether each actuator's leg has failed this episode; under failure_mode "mixed", how
        (0 working, 1 limp, 2 locked)."""
        failed = info["failed_legs"][self.robot.actuator_leg] > 0
        if self.config.failure_mode == "mixed":
            return failed * (1 + info["failure_locked"]).astype(namespace(failed).int32)
        return failed

    def delay(self, info):
        """Physics steps of each control step for which the previous command still holds."""
        return namespace(info["latency"]).round(info["latency"] * self.n_substeps)

    def servo_ctrl(self, step, delay, target, previous, qpos, failed):
        """The servo targets at physics step `step` (latency, then failed servos)."""
        return events.servo_ctrl(step, delay, target, previous, qpos[self.robot.actuator_qpos], failed,
                                 self.config, self.robot.hold_ctrl)

    def transition(self, info, prev_qpos, qpos, qvel, goal, heading, command, contacts: Contacts, actuator_force,
                   finite, draws, key):
        """Everything after the physics of one control step: termination, reward terms, goals,
        commands and bookkeeping. Returns (info, unscaled reward terms, figures, target): `figures`
        hold the step's distance, success so far, goals, whether it fell, ended, reached or
        completed a goal; `target` the next step's goal, heading and command."""
        xp, cfg = namespace(qpos), self.config
        fell = flipped(qpos[3:7])
        done = fell | ~finite
        # Every term sees the goal of this step; a goal reached now is replaced only afterwards, so
        # the step that draws a new goal pays no spurious approach reward or penalty.
        dist = xp.linalg.norm(goal - qpos[:2])
        reached = self.task.reached(dist, qpos, heading, command)
        completed = self.task.goal_completed(reached, info["goals"])
        if "stay_after" in info:  # this episode's goal stays put once that many were completed
            completed = completed & (info["goals"] < info["stay_after"])
        stance = self.robot.foot_stance(contacts.geom1, contacts.geom2, contacts.dist)
        air_time = xp.where(stance, 0.0, info["air_time"] + self.dt)
        stance_avg = rewards.running_stance(info["stance_avg"], stance, self.dt)
        bad, non_foot = self.robot.contact_counts(contacts.geom1, contacts.geom2, contacts.dist, contacts.foot_pos,
                                                  cfg.lift_clearance)
        power = servo_power(actuator_force, qvel, self.robot.actuator_dof)
        gait = self._gait_inputs(info, qpos, command, heading, stance, contacts.foot_pos)
        terms = rewards.terms([name for name in self.active if name in rewards.TERMS], cfg, prev_qpos, qpos, qvel,
                              goal, bad, non_foot, done, completed, power, ground=self.robot.ground(qpos[:2]),
                              air_time=air_time, working=1.0 - info["failed_legs"], stance_avg=stance_avg, **gait)
        terms.update(self.task.reward_terms(self.active, prev_qpos, qpos, qvel, goal, heading, command))
        # In the scales' order: the reward sums in it.
        terms = self.task.mask_terms({name: terms[name] for name in self.active}, command)

        t = info["t"] + 1
        over = done | (t >= cfg.episode_length)
        goals = info["goals"] + completed
        level, walking = info["level"], {}
        if self.measures_walking:
            asked, walked = self.task.walking(qpos, qvel, command, heading)
            walking = {"asked_m": info["asked_m"] + asked * self.dt, "walked_m": info["walked_m"] + walked * self.dt}
        if cfg.curriculum_levels:
            up, down = self.task.level_moves(completed, over, done, goals, walking, command)
            level = curriculum.next_level(level, cfg.curriculum_levels, up, down)
        # A new goal is drawn only on the step that completes one (native MuJoCo draws nothing else).
        next_goal = draws.select(completed, lambda: self.task.next_goal(qpos, goal, goals, draws, key, level),
                                 lambda: goal)
        command, heading = self.task.next_command(t, command, heading, draws, draws.fold_in(key, 8), level)
        success = xp.maximum(info["success"], reached.astype(xp.float32))
        info = {**info, "t": t, "success": success, "goals": goals, "level": level, "air_time": air_time,
                "stance_avg": stance_avg, **walking}
        if "foot_xy" in info:
            info["foot_xy"] = contacts.foot_pos[:, :2]
        figures = {"distance": dist, "success": success, "goals": goals, "fell": fell, "done": done, "over": over,
                   "reached": reached, "completed": completed, "non_foot": non_foot}
        return info, terms, figures, {"goal": next_goal, "heading": heading, "command": command}

    def scaled(self, terms: dict) -> dict:
        """Each term times its scale."""
        return {name: self.scales[name] * value for name, value in terms.items()}

    def restart_info(self, info, over, draws, key, rate=None, p=None) -> dict:
        """`info` for the step after: a new episode's where `over` (brax's auto-reset keeps `info`,
        so the next episode's leg failure and latency are drawn here), the curriculum level kept."""
        xp = draws.xp
        failed = events.draw_failure(self.config, len(self.robot.legs), draws, draws.fold_in(key, 3), rate, p,
                                     self.robot.non_adjacent_pairs)
        latency = events.draw_latency(self.config.action_latency, draws, draws.fold_in(key, 4))
        kind = {name: xp.where(over, value, info[name])
                for name, value in {**self._failure_kind(draws, key), **self._stay(draws, key)}.items()}
        return {**info, "t": xp.where(over, 0, info["t"]), "success": xp.where(over, 0.0, info["success"]),
                "goals": xp.where(over, 0, info["goals"]),
                "failed_legs": xp.where(over, failed, info["failed_legs"]),
                "air_time": xp.where(over, 0.0, info["air_time"]), "stance_avg": xp.where(over, 1.0, info["stance_avg"]),
                "latency": xp.where(over, latency, info["latency"]), **kind,
                **{name: xp.where(over, 0.0, info[name]) for name in self._walking(xp)}}
