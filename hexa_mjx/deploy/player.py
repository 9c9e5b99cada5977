"""Run an exported ONNX policy on native MuJoCo: episodes, per-episode results, video, viewer.

This path imports only mujoco, onnxruntime and NumPy (imageio to encode a video): the shape of a
deployment. `play.py` is its command-line face.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from hexa_mjx.mdp import randomization
from hexa_mjx.mdp.config import EnvConfig, make_config
from hexa_mjx.deploy.export import FORMAT, METADATA_KEY
from hexa_mjx.engines.native import NativeEnv
from hexa_mjx.tasks import TASKS
from hexa_mjx import atomic


class OnnxPolicy:
    """An exported policy: observation (n,) or (batch, n) float32 -> action in [-1, 1]."""

    def __init__(self, path: str | Path, threads: int = 1):
        import onnxruntime as ort

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"policy {path} not found")
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = threads
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types for unreadable files
            raise ValueError(f"{path} is not a readable ONNX model ({str(e)[:160]})") from e
        meta = self.session.get_modelmeta().custom_metadata_map
        if METADATA_KEY not in meta:
            raise ValueError(f"{path} has no hexa_mjx metadata: export a run with `python -m hexa_mjx.deploy.export RUN -o FILE`")
        self.metadata = json.loads(meta[METADATA_KEY])
        if self.metadata.get("format") != FORMAT:
            raise ValueError(f"{path} was exported in metadata format {self.metadata.get('format')}; this version "
                             f"reads format {FORMAT}: re-export it with `python -m hexa_mjx.deploy.export`")
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        shape_in, shape_out = inputs[0].shape[-1], outputs[0].shape[-1]
        if (len(inputs), len(outputs)) != (1, 1) or (shape_in, shape_out) != (
                self.metadata["observation_size"], self.metadata["action_size"]):
            raise ValueError(f"{path}: its graph maps {shape_in} -> {shape_out} values but its metadata says "
                             f"{self.metadata['observation_size']} -> {self.metadata['action_size']}; re-export it")
        self.path, self.input = path, inputs[0].name

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, np.float32)
        return self.session.run(None, {self.input: obs.reshape(-1, obs.shape[-1])})[0].reshape(
            obs.shape[:-1] + (-1,))


def env_for(policy: OnnxPolicy, model_path: str | Path | None = None, randomize: bool = False,
            terrain_contacts: str = "all", **overrides) -> NativeEnv:
    """The native environment a policy was trained on, with `EnvConfig` overrides (goal range,
    waypoints, episode length...) and, with `randomize`, randomized physics every episode;
    `terrain_contacts` as NativeEnv takes it. Checks that the model's joints and observation match
    the policy."""
    meta = policy.metadata
    task = meta["env_config"].get("task")
    if task not in TASKS:
        raise ValueError(f"{policy.path} is a policy for task {task!r}; this version knows {list(TASKS)}")
    size = TASKS[task].layout(meta["action_size"])[-1][1]
    if size != meta["observation_size"]:
        raise ValueError(f"the {task} task observes {size} values, the policy {policy.path} "
                         f"expects {meta['observation_size']}: it was exported for another task or version")
    settings = {**meta["env_config"], **{k: v for k, v in overrides.items() if v is not None}}
    # A policy file never names a file to open: the project's model, or the one the user passes
    # (checked against the policy's model hash, model_matches).
    settings.pop("model_path", None)
    if model_path is not None:
        settings["model_path"] = str(model_path)
    known = {f.name for f in dataclasses.fields(EnvConfig)}  # a newer export's extra settings are ignored
    env = NativeEnv(make_config(**{k: v for k, v in settings.items() if k in known}),
                    ranges=randomization.Ranges() if randomize else None, terrain_contacts=terrain_contacts)
    joints = env.robot.actuator_joints
    if joints != meta["joint_order"]:
        raise ValueError(f"the model {env.config.model_path} drives joints {joints}, but the policy "
                         f"{policy.path} was trained on {meta['joint_order']}; pass the model it was trained on "
                         f"(--model .../{meta['model']['file']})")
    return env


def model_matches(policy: OnnxPolicy, env: NativeEnv) -> bool:
    """Whether the model file is byte-for-byte the one the policy was trained on."""
    return hashlib.sha256(Path(env.config.model_path).read_bytes()).hexdigest() == policy.metadata["model"]["sha256"]


def run_episode(policy: OnnxPolicy, env: NativeEnv, seed: int, record: bool = False, source=None,
                end_at_path: bool = False) -> dict:
    """One deterministic episode from the start drawn by `seed`; `record` keeps qpos and goal per
    step. `source(t, env) -> (vx, vy, yaw rate)` (hexa_mjx.deploy.commands) drives a velocity
    policy instead of the task's own random commands; a source with a `goal` (the path follower)
    also moves the goal marker, and one that is `finished` ends the episode. A navigation policy
    given `waypoints` reports the path as the follower does, and `end_at_path` ends its episode at
    the last waypoint. Policies driven by commands record them and the velocities reached; a
    recorded path also the waypoints reached at every step."""
    waypoints = len(env.config.waypoints) if env.task.follows_waypoints and source is None else 0
    obs = env.reset(seed=seed)
    if hasattr(source, "reset"):
        source.reset(env.data.qpos[:2])
    start_goal_dist = env.goal_distance()
    qpos, goals, reached = [env.data.qpos.copy()], [env.goal], [0]
    commanding = env.task.uses_command and not waypoints  # a drive policy given waypoints walks in goal mode
    track = {"command": [], "commanded": [], "velocity": []}
    total, feet_only, steps, first_arrival, path_done = 0.0, 0, 0, None, None
    stance, power, xy = [], [], []  # per step, for the gait (hexa_mjx.evaluation.gait)
    while True:
        if source is not None:
            env.set_command([*source(steps * env.dt, env), 0.0])
            if hasattr(source, "goal"):
                env.set_goal(source.goal)
            obs = env.observe()
        if commanding:
            track["command"].append(env.command)
            track["commanded"].append(env.task.commanded(env.command, env.data.qpos, env.heading))
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        steps += 1
        feet_only += info["feet_only"]
        stance.append(env.foot_stance())
        power.append(env.servo_power())
        xy.append(env.data.qpos[:2].copy())
        if commanding:
            track["velocity"].append(env.task.measured(env.data.qpos, env.data.qvel))
        if info["success"] and first_arrival is None:
            first_arrival = steps * env.dt
        if record or commanding:
            qpos.append(env.data.qpos.copy())
            goals.append(env.goal)
            reached.append(source.reached if hasattr(source, "reached") else info["goals_reached"])
        if path_done is None and (source.completed if hasattr(source, "completed")
                                  else waypoints and info["goals_reached"] >= waypoints):
            path_done = steps  # the path's time: when its last waypoint counted, not the episode's end
        if terminated or truncated or getattr(source, "finished", False) or (end_at_path and path_done):
            break
    result = {"seed": seed, "success": bool(info["success"]), "final_distance": info["distance"],
              "fell": info["fell"], "nonfinite": info["nonfinite"], "goals_reached": info["goals_reached"],
              "steps": steps, "return": total, "feet_only_share": feet_only / steps,
              "first_arrival_s": first_arrival, "first_goal_distance": start_goal_dist,
              "gait": episode_gait(env, np.array(stance), np.array(power), np.array(xy))}
    if hasattr(source, "reached"):
        result["waypoints_reached"] = source.reached
    elif waypoints:
        result["waypoints_reached"] = int(info["goals_reached"])  # capped at the path's length (mdp.episode)
    if hasattr(source, "reached") or waypoints:
        result["path_completed"] = path_done is not None
        result["path_time_s"] = None if path_done is None else path_done * env.dt
    if commanding:
        from hexa_mjx.evaluation.tracking import episode_errors

        errors = episode_errors(*(np.array(track[k]) for k in ("commanded", "velocity", "command")), env.dt)
        result.update(velocity_rms=errors.get("velocity_rms"), yaw_rate_rms=errors.get("yaw_rate_rms"))
    if record or commanding:
        result["trajectory"] = {"qpos": np.array(qpos), "goal": np.array(goals), "reached": np.array(reached),
                                **({k: np.array(v) for k, v in track.items()} if commanding else {})}
    return result


def episode_gait(env: NativeEnv, stance: np.ndarray, power: np.ndarray, xy: np.ndarray) -> dict:
    """The gait of a whole episode past its first SETTLE_STEPS (gait.analyze), as JSON values."""
    from hexa_mjx.evaluation import gait

    sl = slice(min(gait.SETTLE_STEPS, len(stance)), None)
    record = gait.analyze(stance[sl], power[sl], xy[sl], env.dt, env.robot.mass, env.robot.leg_length)
    return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in record.items()}


def tracking(env: NativeEnv, episodes: list[dict]) -> dict:
    """The velocity task's tracking figures (hexa_mjx.evaluation.tracking) over recorded episodes."""
    from hexa_mjx.evaluation import tracking as figures

    steps = max(e["steps"] for e in episodes)
    traj = {k: np.zeros((steps, len(episodes), *episodes[0]["trajectory"][k].shape[1:]))
            for k in ("command", "commanded", "velocity")}
    traj["qpos"] = np.zeros((steps, len(episodes), env.mj_model.nq))
    alive = np.zeros((steps, len(episodes)))
    for i, e in enumerate(episodes):
        n = e["steps"]
        for k in ("command", "commanded", "velocity"):
            traj[k][:n, i] = e["trajectory"][k]
        traj["qpos"][:n, i] = e["trajectory"]["qpos"][1:]
        alive[:n, i] = 1.0
    fell = np.array([e["fell"] for e in episodes], bool)
    summary, _ = figures.tracking_summary(env.task, env.dt, traj, alive, fell)
    return summary


def summarize(episodes: list[dict]) -> dict:
    """Rates and means over episodes, and their gait (hexa_mjx.evaluation.gait.summarize)."""
    from hexa_mjx.evaluation import gait

    def mean(key):
        return float(np.mean([e[key] for e in episodes]))

    arrivals = [e["first_arrival_s"] for e in episodes if e["first_arrival_s"] is not None]
    # Speed to the first goal: its start distance over the time to first enter the radius, m/s.
    speeds = [e["first_goal_distance"] / e["first_arrival_s"] for e in episodes if e["first_arrival_s"]]
    tracked = [e["velocity_rms"] for e in episodes if e.get("velocity_rms") is not None]
    path = {}
    if all("path_completed" in e for e in episodes):  # walked a path: the follower's, or waypoints
        times = [e["path_time_s"] for e in episodes if e["path_completed"]]
        path = {"path_completed_rate": mean("path_completed"),
                "path_time_s_median": float(np.median(times)) if times else None}
    return {"episodes": len(episodes), "success_rate": mean("success"), "fall_rate": mean("fell"), **path,
            "velocity_rms_mean": float(np.mean(tracked)) if tracked else None,
            "nonfinite_rate": mean("nonfinite"), "final_distance_mean": mean("final_distance"),
            "goals_per_episode": mean("goals_reached"), "feet_only_share": mean("feet_only_share"),
            "first_arrival_s_mean": float(np.mean(arrivals)) if arrivals else None,
            "speed_to_first_goal": float(np.mean(speeds)) if speeds else None,
            **({"gait": without_nan(gait.summarize([e["gait"] for e in episodes]))}
               if all("gait" in e for e in episodes) else {})}


def without_nan(value):
    """`value` (nested dicts and lists) with NaN as None: JSON has no NaN, and None equals None."""
    if isinstance(value, dict):
        return {k: without_nan(v) for k, v in value.items()}
    if isinstance(value, list):
        return [without_nan(v) for v in value]
    return None if isinstance(value, float) and np.isnan(value) else value


def write_json(path: Path, policy: OnnxPolicy, env: NativeEnv, episodes: list[dict], tracking: dict | None = None) -> None:
    """Per-episode results and their summary (with the velocity task's `tracking` figures, eval.py's
    per-class table included), written atomically."""
    rows = [{k: v for k, v in e.items() if k not in ("trajectory", "gait")} for e in episodes]
    doc = {"policy": str(policy.path), "task": env.config.task, "engine": "mujoco (native C)",
           "model": env.config.model_path, "model_matches_training": model_matches(policy, env),
           "summary": summarize(episodes), **({"tracking": tracking} if tracking else {}), "episodes": rows}
    atomic.write(path, json.dumps(doc, indent=1))


def inference_rates(policy: OnnxPolicy, obs: np.ndarray, calls: int = 2000, repeats: int = 5) -> list[float]:
    """Policy calls per second, one observation per call as a controller makes them, per repeat."""
    import time

    policy(obs)  # warm-up
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            policy(obs)
        rates.append(calls / (time.perf_counter() - start))
    return rates


# Viewer keys (GLFW key codes): move the goal in the world's x/y plane, or draw a new one.
GOAL_KEYS = {73: (0.25, 0.0), 75: (-0.25, 0.0), 74: (0.0, 0.25), 76: (0.0, -0.25)}  # I, K, J, L; m
NEW_GOAL_KEY = 78  # N
RESET_KEY = 82  # R


def view(policy: OnnxPolicy, env: NativeEnv, seed: int = 0) -> None:
    """Run the policy in MuJoCo's interactive viewer, in real time, until the window closes.

    The goal is the `goal` mocap body: double-click it and Ctrl+right-drag to move it, or use
    I/J/K/L (+x, +y, -x, -y by 0.25 m), N (a new goal from the task) and R (a new episode). A
    velocity policy is driven from the keyboard instead (hexa_mjx.deploy.commands.KEY_STEPS):
    arrows or W/A/S/D for the planar velocity, Q/E for the yaw rate, space to stop; the command is
    drawn on the robot."""
    import time

    import mujoco.viewer

    from hexa_mjx.deploy.commands import Keyboard
    from hexa_mjx.evaluation.video import draw_command

    pending = []
    keyboard = Keyboard(env.task.command_ranges) if env.task.uses_command else None
    with mujoco.viewer.launch_passive(env.mj_model, env.data, key_callback=pending.append) as viewer:
        with viewer.lock():  # follow the torso from behind and above
            viewer.cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
            viewer.cam.trackbodyid = env.robot.torso
            viewer.cam.distance, viewer.cam.elevation, viewer.cam.azimuth = 2.0, -30.0, 135.0
        obs, episode = env.reset(seed=seed), 0
        while viewer.is_running():
            tick = time.perf_counter()
            with viewer.lock():
                for key in pending:
                    if keyboard is not None and keyboard.press(key):
                        print(f"command: vx {keyboard.command[0]:+.2f} m/s, vy {keyboard.command[1]:+.2f} m/s, "
                              f"yaw rate {keyboard.command[2]:+.2f} rad/s", flush=True)
                    elif key in GOAL_KEYS:
                        env.set_goal(env.goal + np.array(GOAL_KEYS[key]))
                    elif key == NEW_GOAL_KEY:
                        env.set_goal(env.new_goal())
                    elif key == RESET_KEY:
                        episode += 1
                        obs = env.reset(seed=seed + episode)
                pending.clear()
                if keyboard is not None:
                    env.set_command([*keyboard.command, 0.0])
                    obs = env.observe()
                    viewer.user_scn.ngeom = 0
                    draw_command(viewer.user_scn, env.data.qpos, keyboard.command)
                obs, _, terminated, truncated, _ = env.step(policy(obs))
                if terminated or truncated:
                    episode += 1
                    obs = env.reset(seed=seed + episode)
            viewer.sync()
            time.sleep(max(0.0, env.dt - (time.perf_counter() - tick)))
