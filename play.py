"""Run a trained policy on native MuJoCo, outside the trainer: results, an MP4, or the live viewer.

    python play.py --policy policies/goal.onnx                       # one episode -> play-goal.mp4
    python play.py --policy policies/navigate.onnx --episodes 20 --json results.json --no_video
    python play.py --policy policies/navigate.onnx --waypoints "2,0 2,2 0,2 0,0" --episode_length 1500
    python play.py --policy policies/navigate.onnx --viewer          # drag the goal around
    python play.py --policy runs/goal_directed-s0                    # a run or checkpoint (exports it first)
    python play.py --policy policies/navigate.onnx --terrain bumps --terrain_seed 1 --episodes 64 --no_video
    python play.py --policy policies/velocity.onnx --viewer          # drive it: arrows/WASD, Q/E, space
    python play.py --policy policies/velocity.onnx --commands drive.csv --episode_length 1200
    python play.py --policy policies/velocity.onnx --follow --waypoints "2,0 2,2 0,2 0,0" --episode_length 2400

With an ONNX file, this imports only mujoco, onnxruntime and NumPy (and imageio for the video).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

try:
    from hexa_mjx import cli
except ImportError as e:  # a MUJOCO_GL that MuJoCo cannot use
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    what = p.add_argument_group("what to run", "the policy, its episodes and the physics")
    output = p.add_argument_group("output", "results, video, the viewer")
    what.add_argument("--policy", required=True, help="exported .onnx file, run directory or checkpoint folder")
    what.add_argument("--episodes", type=int, default=1, help="episodes to run (each from its own seeded start)")
    what.add_argument("--seed", type=int, default=0, help="seed of the first episode's start and goals")
    output.add_argument("--json", default="", help="write per-episode results and a summary to this file")
    output.add_argument("--video", default="", help="MP4 of the first episode (default play-<policy name>.mp4)")
    output.add_argument("--no_video", "--no-video", action="store_true", help="write no video")
    output.add_argument("--viewer", action="store_true", help="open MuJoCo's interactive viewer (needs a display)")
    what.add_argument("--model", default=None, help="MJCF model (default: the project's models/hexapod.xml)")
    what.add_argument("--randomize", action="store_true", help="a randomized physics model every episode (friction, "
                   "masses, payload, servo gains and limits, damping, armature: hexa_mjx.mdp.randomization.Ranges)")
    cli.add_env_flags(p, unset="the policy's own")
    drive = p.add_argument_group("driving a velocity policy", "where a velocity-task policy's commands come from "
                                 "(default: the task's own random commands)")
    drive.add_argument("--commands", default="", help="a schedule of (t, vx, vy, yaw_rate) rows, CSV or JSON "
                       "(hexa_mjx.deploy.commands; docs/DEPLOYMENT.md), instead of the task's random commands")
    drive.add_argument("--follow", action="store_true", help="walk --waypoints with the path follower, which turns "
                       "the path into velocity commands (pure pursuit)")
    drive.add_argument("--follow_speed", type=float, default=0.5, help="m/s, the path follower's cruising speed "
                       "(default: 0.5)")
    what.add_argument("--terrain_contacts", default="all", choices=["all", "mjx"],
                      help="'all': every heightfield contact MuJoCo C makes; 'mjx': made as MJX makes them, side-wall "
                           "normals turned up and only those within 1 mm of the deepest kept (hexa_mjx.engines."
                           "terrain_contacts)")
    what.add_argument("--solver", default="trained", choices=["trained", "default"],
                   help="'trained': the model's fast solver setting (1 iteration); 'default': MuJoCo's default "
                        "accuracy (100 iterations, 50 line-search), the sim-to-sim check")
    output.add_argument("--benchmark", action="store_true", help="time the policy alone (one observation per call, "
                   "one thread) and exit")
    args = p.parse_args(cli.signed_values(sys.argv[1:] if argv is None else list(argv)))
    if args.episodes < 1:
        p.error(f"--episodes must be at least 1, got {args.episodes}")
    if args.viewer and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        p.error("--viewer needs a display, and neither DISPLAY nor WAYLAND_DISPLAY is set: run without --viewer "
                "to write an MP4, or start it under a display (for example `xvfb-run python play.py ...`)")
    return args


def cli_waypoints(args):
    """The --waypoints as an (n, 2) array, m from the start."""
    import numpy as np

    return np.array(cli.parse_waypoints(args.waypoints), float)


def onnx_file(policy: str, scratch: str) -> Path:
    """The ONNX file to play: the file itself, or a run/checkpoint exported into `scratch`."""
    path = Path(policy)
    if path.is_dir():
        from hexa_mjx.deploy import export
        from hexa_mjx.training import jax_setup

        jax_setup.prepare_jax()
        print(f"exporting {path} to ONNX ...", flush=True)
        return export.export(path, Path(scratch) / f"{path.resolve().name}.onnx")
    if not path.is_file():
        raise FileNotFoundError(f"--policy {path} is neither an ONNX file nor a run or checkpoint directory")
    return path


# The command line top to bottom: load, check, then benchmark, view or play.
def main(argv=None) -> int:
    args = parse_args(argv)
    if args.viewer:
        os.environ["MUJOCO_GL"] = "glfw"  # the window's OpenGL, not the off-screen default
    try:
        from hexa_mjx.deploy import commands, player
        from hexa_mjx.tasks import TASKS
        from hexa_mjx.evaluation import video
    except ImportError as e:  # a missing package, or a MUJOCO_GL that MuJoCo cannot use
        print(f"error: {e}", file=sys.stderr)
        return 2

    try:
        with tempfile.TemporaryDirectory() as scratch:
            policy = player.OnnxPolicy(onnx_file(args.policy, scratch))
        overrides = cli.env_overrides(args)
        if args.solver == "default":
            overrides.update(solver_iterations=100, ls_iterations=50)  # MuJoCo's defaults
        trained = TASKS[policy.metadata["task"]]
        velocity, by_goals = trained.uses_command, trained.follows_waypoints
        if velocity and args.waypoints and not (args.follow or by_goals):
            raise ValueError("a velocity policy walks waypoints through the path follower: add --follow")
        if args.waypoints and not (by_goals or args.follow):
            raise ValueError(f"--waypoints need a task that follows a path; this is a {policy.metadata['task']}-task "
                             "policy")
        if (args.commands or args.follow) and not velocity:
            raise ValueError(f"--commands and --follow drive a velocity policy; this is a {policy.metadata['task']}-task "
                             "policy")
        if args.follow and not args.waypoints:
            raise ValueError('--follow walks a path: give it with --waypoints "x,y x,y ..."')
        if args.commands and args.follow:
            raise ValueError("--commands and --follow both set the commands: choose one")
        if not (0 < args.follow_speed <= 5):
            raise ValueError(f"--follow_speed is a speed in m/s above 0 (at most 5), got {args.follow_speed}")
        schedule = commands.Schedule(commands.load_schedule(args.commands)) if args.commands else None
        if args.follow:
            # The follower walks them, not the task; without it a drive policy walks them in goal mode.
            overrides.pop("waypoints")
        env = player.env_for(policy, args.model, randomize=args.randomize, terrain_contacts=args.terrain_contacts,
                             **overrides)
        if args.json:
            out = Path(args.json)
            if out.is_dir():
                raise ValueError(f"--json {out} is a folder; name a file")
            out.parent.mkdir(parents=True, exist_ok=True)
        if not player.model_matches(policy, env):
            print(f"note: {env.config.model_path} differs from the model the policy was trained on", file=sys.stderr)
    except (FileNotFoundError, ValueError, OSError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    task = policy.metadata["task"]
    if args.benchmark:
        rates = player.inference_rates(policy, env.observe())
        print(f"{policy.path}: {sorted(rates)[len(rates) // 2]:,.0f} policy steps/s on one thread (median of "
              f"{len(rates)} runs of 2,000 calls; {min(rates):,.0f} to {max(rates):,.0f}); the robot needs "
              f"{policy.metadata['control_hz']:g}")
        return 0
    if args.viewer:
        print("viewer: double-click the goal and Ctrl+right-drag to move it; I/J/K/L move it 0.25 m, N draws a new "
              "goal, R restarts; close the window to stop")
        player.view(policy, env, args.seed)
        return 0

    print(f"{policy.path}: {task} policy on native MuJoCo, {args.episodes} episode(s)")
    episodes, start = [], time.perf_counter()
    for i in range(args.episodes):
        source = schedule
        if args.follow:
            source = commands.PathFollower(env.robot.start_xy + cli_waypoints(args), env.task.command_ranges,
                                           speed=args.follow_speed, success_radius=env.config.success_radius)
        ep = player.run_episode(policy, env, args.seed + i, record=(i == 0 and not args.no_video), source=source)
        episodes.append(ep)
        if env.task.has_goal:
            figure = (f"{'success' if ep['success'] else 'no success':10s} final distance {ep['final_distance']:.2f} m  "
                      f"goals {ep['goals_reached']:2d}")
        elif args.follow:
            figure = f"waypoints reached {ep['waypoints_reached']} of {len(cli_waypoints(args))}"
        else:
            rms = ep["velocity_rms"]
            figure = f"velocity RMS error {'-' if rms is None else format(rms, '.3f')} m/s"
        print(f"episode {i:3d}: {figure}  {'fell' if ep['fell'] else 'upright'}  "
              f"feet only {ep['feet_only_share']:.0%} of {ep['steps']} steps")
    elapsed = time.perf_counter() - start
    s = player.summarize(episodes)
    rate = f"{sum(e['steps'] for e in episodes) / elapsed:,.0f} control steps/s with the policy (one core)"
    if env.task.has_goal:
        speed = s["speed_to_first_goal"]
        print(f"summary: success {s['success_rate']:.0%}, falls {s['fall_rate']:.0%}, final distance "
              f"{s['final_distance_mean']:.2f} m, goals/episode {s['goals_per_episode']:.1f}, feet only "
              f"{s['feet_only_share']:.1%} of steps, speed to the first goal "
              f"{'-' if speed is None else format(speed, '.3f')} m/s; {rate}")
    else:
        print(f"summary: falls {s['fall_rate']:.0%}, feet only {s['feet_only_share']:.1%} of steps; {rate}")
    t = None
    # Waypoints walked in a drive policy's goal mode record no commands to track.
    if env.task.uses_command and all("trajectory" in e for e in episodes):
        t = player.tracking(env, episodes)
        drift = t["stand_drift"]
        if t["steps"] and not args.follow:  # the follower's commands change every step: none settles
            print(f"tracking ({t['settle_s']} s after each change left out, {t['average_s']} s average): velocity "
                  f"RMS {t['velocity_rms']:.3f} m/s, yaw rate RMS {t['yaw_rate_rms']:.3f} rad/s"
                  + (f", drift commanded to stand {drift['speed_mean']:.3f} m/s" if drift["commands"] else ""))
        if args.follow:
            done = [e.get("waypoints_reached", 0) == len(cli_waypoints(args)) for e in episodes]
            print(f"path follower: every waypoint reached in {sum(done)} of {len(done)} episodes")
    if args.json:
        player.write_json(Path(args.json), policy, env, episodes, t)
        print(f"wrote {args.json}")
    if not args.no_video:
        path = Path(args.video or f"play-{policy.path.stem}.mp4")
        traj = episodes[0]["trajectory"]
        try:
            shown = traj.get("commanded")
            shown = None if shown is None else shown[np.minimum(np.arange(len(traj["qpos"])), len(shown) - 1)]
            goals = traj["goal"] if env.task.has_goal or args.follow else None  # the follower's waypoint
            video.render_video(env, traj["qpos"], path, goals, cli.parse_waypoints(args.waypoints) if args.follow
                               else env.config.waypoints, commands=shown)
        except RuntimeError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
