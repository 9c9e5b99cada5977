"""Evaluate a trained policy and render it.

    python eval.py --ckpt runs/goal_directed-s0            # latest checkpoint of a run
    python eval.py --ckpt runs/goal_directed-s0/checkpoints/000002000896 --episodes 256 --no-video
    python eval.py --ckpt runs/goal_directed-s0 --start_joint_noise 0.1 --start_yaw_noise 0.3  # perturbed starts
    python eval.py --ckpt runs/goal_directed-s0 --max_contact_points 0  # physics with every contact slot
    python eval.py --ckpt runs/navigate-s0 --episodes 256                # goals in every direction
    python eval.py --ckpt runs/navigate-s0 --waypoints "1,0 1,1 0,1 0,0" --episode_length 3000
    python eval.py --ckpt runs/goal_directed-s0 --task navigate          # the report's policy on those goals

Runs N episodes with the deterministic policy batched on MJX, prints a table, writes
<out>/metrics.json and <out>/episode_<i>.mp4 (out defaults to <run dir>/eval).
"""

import argparse
import sys

try:
    from hexa_mjx.evaluation import evaluate as evaluation, nav_metrics
    from hexa_mjx.training import jax_setup
    from hexa_mjx.mdp import terrain
    from hexa_mjx.tasks import TASKS
except ImportError as e:  # a missing package, or a MUJOCO_GL that MuJoCo cannot use
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="eval.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--ckpt", required=True, help="a run directory (its latest checkpoint) or one checkpoint")
    parser.add_argument("--episodes", type=int, default=128, help="episodes to run (default: 128)")
    parser.add_argument("--videos", type=int, default=1, help="episodes to render (default: 1)")
    parser.add_argument("--no-video", dest="video", action="store_false", help="skip rendering")
    parser.add_argument("--out", default=None, help="output folder (default: <run dir>/eval)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--start_joint_noise", type=float, default=None,
                        help="rad, uniform noise on each joint's start angle (default: the run's setting)")
    parser.add_argument("--start_yaw_noise", type=float, default=None,
                        help="rad, uniform noise on the start heading (default: the run's setting)")
    parser.add_argument("--max_contact_points", type=int, default=None,
                        help="contact points the physics keeps per step, 0: all (default: the run's setting)")
    parser.add_argument("--task", default=None, choices=sorted(TASKS),
                        help="run the policy on this task's goals (default: its own; 'navigate' also takes "
                             "a report-task policy, as a baseline)")
    parser.add_argument("--waypoints", default=None,
                        help="navigate: walk a path instead, \"x,y x,y ...\" in metres from the start, world frame, "
                             "or a file holding that")
    parser.add_argument("--goal_min_distance", type=float, default=None, help="navigate: m (default: the run's)")
    parser.add_argument("--goal_max_distance", type=float, default=None, help="navigate: m (default: the run's)")
    parser.add_argument("--episode_length", type=int, default=None,
                        help="control steps per episode (default: the run's)")
    parser.add_argument("--disabled_legs", default=None,
                        help='legs whose servos fail in every episode, e.g. "3" or "1 4" (numbers from 1)')
    parser.add_argument("--leg_failure", default=None, choices=["none", "random"],
                        help="'random': one random leg fails per episode (default: the run's)")
    parser.add_argument("--failure_mode", default=None, choices=["limp", "locked"],
                        help="a failed leg's servos give no torque (limp) or hold the start angles (locked)")
    parser.add_argument("--push_speed", type=float, default=None, help="m/s, kicks to the torso (default: the run's)")
    parser.add_argument("--push_interval", type=float, default=None, help="s between kicks (default: the run's)")
    parser.add_argument("--action_latency", type=float, default=None, help="control steps of command delay, 0-1")
    parser.add_argument("--obs_noise", type=float, default=None, help="observation noise level (1: Playground's)")
    parser.add_argument("--randomize", action="store_true",
                        help="each episode on its own randomized physics (train.py --randomize's ranges)")
    parser.add_argument("--terrain", default=None, choices=terrain.KINDS,
                        help="ground to evaluate on (default: the run's; hexa_mjx.mdp.terrain)")
    parser.add_argument("--terrain_seed", type=int, default=None, help="seed of the generated terrain (default: 0)")
    parser.add_argument("--terrain_difficulty", type=float, default=None,
                        help="terrain sizes as a fraction of the full ones, 0 to 1 (default: the run's)")
    parser.add_argument("--shadows", action="store_true",
                        help="render shadows and the skybox (5x slower without a GPU)")
    parser.add_argument("--no_compile_cache", dest="compile_cache", action="store_false",
                        help="don't keep compiled programs in the per-user cache folder")
    args = parser.parse_args(argv)
    jax_setup.prepare_jax(compile_cache=args.compile_cache)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    if args.videos < 0:
        parser.error("--videos must be 0 or more")
    try:
        waypoints = nav_metrics.parse_waypoints(args.waypoints) if args.waypoints is not None else None
        disabled = parse_legs(args.disabled_legs) if args.disabled_legs is not None else None
        result = evaluation.evaluate(args.ckpt, episodes=args.episodes, videos=args.videos, out=args.out,
                                     seed=args.seed, video=args.video, task=args.task, shadows=args.shadows,
                                     randomize=args.randomize,
                                     start_joint_noise=args.start_joint_noise, start_yaw_noise=args.start_yaw_noise,
                                     max_contact_points=args.max_contact_points, waypoints=waypoints,
                                     goal_min_distance=args.goal_min_distance,
                                     goal_max_distance=args.goal_max_distance, episode_length=args.episode_length,
                                     disabled_legs=disabled, failure_mode=args.failure_mode,
                                     leg_failure="none" if disabled else args.leg_failure,
                                     push_speed=args.push_speed, push_interval=args.push_interval,
                                     action_latency=args.action_latency, obs_noise=args.obs_noise,
                                     terrain=args.terrain, terrain_seed=args.terrain_seed,
                                     terrain_difficulty=args.terrain_difficulty)
    except (FileNotFoundError, RuntimeError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"checkpoint {result['checkpoint']} (step {result['step']:,})")
    print(evaluation.format_table(result["summary"]))
    for path in result["videos"]:
        print(f"video: {path}")
    if "paths" in result:
        print(f"tracks from above: {result['paths']}")
    print(f"foot-contact diagram: {result['gait_diagram']}")
    return 0


def parse_legs(text: str) -> tuple[int, ...]:
    """Leg numbers from "3" or "1 4" or "1,4"."""
    try:
        return tuple(int(x) for x in text.replace(",", " ").split())
    except ValueError:
        raise ValueError(f'--disabled_legs takes leg numbers from 1, like "3" or "1 4", got {text!r}') from None


if __name__ == "__main__":
    sys.exit(main())
