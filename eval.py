"""Evaluate a trained policy and render it.

    python eval.py --ckpt runs/goal_directed-s0            # latest checkpoint of a run
    python eval.py --ckpt runs/goal_directed-s0/checkpoints/000002000896 --episodes 256 --no-video
    python eval.py --ckpt runs/goal_directed-s0 --start_joint_noise 0.1 --start_yaw_noise 0.3  # perturbed starts
    python eval.py --ckpt runs/goal_directed-s0 --max_contact_points 0  # physics with every contact slot

Runs N episodes with the deterministic policy batched on MJX, prints a table, writes
<out>/metrics.json and <out>/episode_<i>.mp4 (out defaults to <run dir>/eval).
"""

import argparse
import sys

from hexa_mjx import evaluation


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
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    try:
        result = evaluation.evaluate(args.ckpt, episodes=args.episodes, videos=args.videos, out=args.out,
                                     seed=args.seed, video=args.video, start_joint_noise=args.start_joint_noise,
                                     start_yaw_noise=args.start_yaw_noise,
                                     max_contact_points=args.max_contact_points)
    except (FileNotFoundError, RuntimeError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"checkpoint {result['checkpoint']} (step {result['step']:,})")
    print(evaluation.format_table(result["summary"]))
    for path in result["videos"]:
        print(f"video: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
