"""Off-screen MP4 video of a recorded trajectory (MuJoCo C and NumPy; no JAX).

eval.py renders its MJX rollouts with it, play.py its native-MuJoCo episodes: frames are
rendered from stored joint positions, so any engine's trajectory can be drawn.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from hexa_mjx.robot import constants as robot
from hexa_mjx import atomic

GL_PACKAGES = "libegl1 libegl-mesa0 libosmesa6"  # Debian/Ubuntu
VIDEO_FPS = 30  # frames per second of videos (real time: every ctrl_hz / 30th control step)


def render_video(env, qpos_frames: np.ndarray, path: Path, goals: np.ndarray, waypoints=(), width=640,
                 height=480, fps: float = VIDEO_FPS, shadows: bool = False, commands=None, workers: int = 0) -> int:
    """Render qpos frames (T, nq, one per control step) from the tracking camera into a real-time
    MP4 of about `fps` frames per second, with the goal marker at each frame's goal (T, 2; None:
    no marker), the waypoint path (start -> waypoints) and each frame's velocity command (T, 3;
    `draw_command`) drawn. Returns the number of frames written.

    Shadows, the skybox and the floor's reflection are off unless `shadows`: with software
    OpenGL (no GPU) shadows cost 5x the frame rate and the reflection, a second pass over the
    scene, 1.3x (docs/RESULTS.md, "Evaluation time", "Cheaper evaluations"). The frames are drawn
    by `workers` processes (0: one per core, at most RENDER_WORKERS), each a contiguous part of
    the video with one rendering thread (software OpenGL spreads one frame over the cores poorly)."""
    import imageio.v2 as imageio

    if not os.environ.get("MUJOCO_GL"):
        raise RuntimeError(f"no off-screen OpenGL found (neither EGL nor OSMesa): install it with "
                           f"`apt-get install {GL_PACKAGES}`, or pass --no-video")
    stride = max(int(round(1 / (env.dt * fps))), 1)
    if goals is None:  # the marker far below the floor, out of the camera's view
        goals = np.full((len(qpos_frames), 2), np.nan)
    commands = [None] * len(qpos_frames) if commands is None else list(commands)
    corners = np.vstack([qpos_frames[0, :2], np.asarray(waypoints, float).reshape(-1, 2) + env.qpos0[:2]])
    frames = list(zip(qpos_frames[::stride], goals[::stride], commands[::stride]))
    workers = min(workers or len(os.sched_getaffinity(0)), RENDER_WORKERS, max(len(frames) // MIN_FRAMES_PER_WORKER, 1))
    parts = np.array_split(np.arange(len(frames)), workers)
    draw = dict(corners=corners if waypoints else None, width=width, height=height, shadows=shadows)
    # The encoder is an ffmpeg subprocess. JAX warns on any fork in a threaded process; subprocess's
    # fork is followed at once by exec in C, which is safe, so that warning is noise here.
    warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
    with atomic.replacing(path) as tmp, imageio.get_writer(tmp, fps=1 / (env.dt * stride), codec="libx264",
                                                            quality=7, macro_block_size=16) as writer:
        helpers = [start_render_worker(env.mj_model, [frames[i] for i in part], draw) for part in parts[1:]]
        for image in render_frames(env.mj_model, [frames[i] for i in parts[0]], threads=1 if helpers else 0, **draw):
            writer.append_data(image)
        for helper, part in zip(helpers, parts[1:]):
            for image in finish_render_worker(helper, len(part), height, width):
                writer.append_data(image)
    return len(frames)


def start_render_worker(model, frames, draw: dict) -> subprocess.Popen:
    """A process (`python -m hexa_mjx.evaluation.render_worker`) that draws `frames` with one
    rendering thread; its own imports are MuJoCo and NumPy only, where a spawned multiprocessing
    worker would import the caller's script (eval.py's JAX) first."""
    proc = subprocess.Popen([sys.executable, "-m", "hexa_mjx.evaluation.render_worker"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, "LP_NUM_THREADS": "1"})
    pickle.dump((model, frames, draw), proc.stdin)  # our own child reads it: no user-supplied file is unpickled
    proc.stdin.close()
    return proc


def finish_render_worker(proc: subprocess.Popen, count: int, height: int, width: int) -> np.ndarray:
    """The (count, height, width, 3) frames a render worker drew."""
    raw = proc.stdout.read()
    error = proc.stderr.read().decode(errors="replace")
    if proc.wait() != 0 or len(raw) != count * height * width * 3:
        raise RuntimeError(f"a video render worker failed (exit code {proc.returncode}): {error.strip()[-2000:]}")
    return np.frombuffer(raw, np.uint8).reshape(count, height, width, 3)


RENDER_WORKERS = 4  # processes that draw one video's frames at most
MIN_FRAMES_PER_WORKER = 60  # a shorter video is drawn in one process: a worker takes about a second to start


def render_frames(model, frames, corners=None, width=640, height=480, shadows=False, threads: int = 0) -> np.ndarray:
    """Draw (qpos, goal or NaN, command or None) frames from the tracking camera: (N, height, width, 3)
    uint8. `threads`: software OpenGL's rendering threads (LP_NUM_THREADS; 0: its default)."""
    import mujoco

    if threads:  # read by Mesa's llvmpipe when the context is made
        os.environ["LP_NUM_THREADS"] = str(threads)
    data = mujoco.MjData(model)
    mocap = model.body_mocapid[model.body(robot.GOAL_BODY).id]
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as e:
        backend = os.environ.get("MUJOCO_GL", "none")
        raise RuntimeError(
            f"off-screen OpenGL ({backend}) is not usable: {e}. Install it with "
            f"`apt-get install {GL_PACKAGES}` (or try MUJOCO_GL=osmesa), "
            "or pass --no-video") from e
    images = np.empty((len(frames), height, width, 3), np.uint8)
    for k, (qpos, goal, command) in enumerate(frames):
        data.qpos[:] = qpos
        data.mocap_pos[mocap] = (*qpos[:2], -10.0) if np.isnan(goal[0]) else (*goal, 0.0)
        mujoco.mj_forward(model, data)
        renderer.update_scene(data, camera=robot.TRACKING_CAMERA)
        set_effects(renderer.scene, shadows)
        if corners is not None:
            draw_path(renderer.scene, corners)
        if command is not None:
            draw_command(renderer.scene, qpos, command)
        images[k] = renderer.render()
    renderer.close()
    return images


def set_effects(scene, on: bool) -> None:
    """Shadows, skybox and the floor's reflection on or off (costly in software OpenGL)."""
    import mujoco

    for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_SKYBOX, mujoco.mjtRndFlag.mjRND_REFLECTION):
        scene.flags[flag] = on


def draw_path(scene, corners: np.ndarray, width=0.01, height=0.003) -> None:
    """Add the polyline through `corners` (x, y on the floor, m) to a MuJoCo scene as thin capsules."""
    import mujoco

    for a, b in zip(corners[:-1], corners[1:]):
        if scene.ngeom >= scene.maxgeom:
            return
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.eye(3).ravel(),
                            np.array([0.9, 0.5, 0.1, 1.0], np.float32))
        mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_CAPSULE, width, np.array([*a, height]),
                             np.array([*b, height]))
        scene.ngeom += 1


ARROW_M_PER_MPS = 0.5  # m of arrow per m/s of commanded velocity
TURN_M_PER_RADPS = 0.15  # m of the turn arrow per rad/s of commanded yaw rate


def draw_command(scene, qpos: np.ndarray, command) -> None:
    """Add a velocity command (vx, vy, yaw rate; heading frame) to a MuJoCo scene at the torso in
    pose `qpos`: a blue arrow for the planar velocity, an orange arrow across the front for the yaw
    rate (to the left: counter-clockwise), a red ball for "stand still"."""
    import mujoco

    from hexa_mjx.robot.kinematics import yaw

    heading = float(yaw(np.asarray(qpos[3:7])))
    c, s = np.cos(heading), np.sin(heading)
    world = lambda v: np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], 0.0])  # noqa: E731
    base = np.array([qpos[0], qpos[1], qpos[2] + 0.15])
    vx, vy, wz = (float(x) for x in command[:3])
    parts = []
    if vx == 0 and vy == 0 and wz == 0:
        parts.append((mujoco.mjtGeom.mjGEOM_SPHERE, base, base, [0.9, 0.1, 0.1, 1.0], 0.025))
    if vx or vy:
        parts.append((mujoco.mjtGeom.mjGEOM_ARROW, base, base + ARROW_M_PER_MPS * world((vx, vy)), [0.1, 0.3, 0.9, 1], 0.025))
    if wz:
        front = base + world((0.12, 0.0))
        parts.append((mujoco.mjtGeom.mjGEOM_ARROW, front, front + TURN_M_PER_RADPS * wz * world((0.0, 1.0)),
                      [0.95, 0.55, 0.1, 1], 0.02))
    for kind, a, b, rgba, width in parts:
        if scene.ngeom >= scene.maxgeom:
            return
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(geom, kind, np.full(3, width), a, np.eye(3).ravel(), np.array(rgba, np.float32))
        if kind != mujoco.mjtGeom.mjGEOM_SPHERE:
            mujoco.mjv_connector(geom, kind, width, a, b)
        scene.ngeom += 1


def render_rates(model, qpos, frames: int = 60, repeats: int = 3, width: int = 640, height: int = 480) -> dict:
    """Frames per second rendering `qpos` from the tracking camera, shadows and skybox off and on
    (median of `repeats`), with the OpenGL backend MUJOCO_GL names."""
    import statistics
    import time

    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    renderer = mujoco.Renderer(model, height=height, width=width)
    rates = {}
    for shadows in (False, True):
        runs = []
        for _ in range(repeats):
            start = time.perf_counter()
            for _ in range(frames):
                renderer.update_scene(data, camera=robot.TRACKING_CAMERA)
                set_effects(renderer.scene, shadows)
                renderer.render()
            runs.append(frames / (time.perf_counter() - start))
        rates["shadows" if shadows else "plain"] = statistics.median(runs)
    renderer.close()
    return rates


def main(argv=None) -> None:
    """`python -m hexa_mjx.evaluation.video --benchmark`: the renderer's frame rate on this machine."""
    import argparse

    from hexa_mjx.mdp.config import EnvConfig
    from hexa_mjx.robot.model import RobotModel

    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.evaluation.video", description=main.__doc__)
    parser.add_argument("--benchmark", action="store_true", help="time off-screen rendering")
    parser.add_argument("--frames", type=int, default=60)
    args = parser.parse_args(argv)
    if not args.benchmark:
        parser.error("nothing to do: pass --benchmark")
    rm = RobotModel(EnvConfig())
    rates = render_rates(rm.mj_model, rm.qpos0, args.frames)
    print(f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}: 640x480 frames/s, median of 3 runs of {args.frames}: "
          f"{rates['plain']:.1f} without shadows and skybox (eval.py's default), {rates['shadows']:.1f} with them "
          f"({rates['plain'] / rates['shadows']:.1f}x)")


if __name__ == "__main__":
    main()
