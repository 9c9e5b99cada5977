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
    from hexa_mjx import cli
    from hexa_mjx.evaluation import evaluate as evaluation, table
    from hexa_mjx.training import jax_setup
    from hexa_mjx.tasks import TASKS
except ImportError as e:  # a missing package, or a MUJOCO_GL that MuJoCo cannot use
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="eval.py", description=__doc__.split("\n\n")[0])
    what = parser.add_argument_group("what to evaluate", "the policy, its episodes and the task they run")
    output = parser.add_argument_group("output", "what is written besides the table")
    what.add_argument("--ckpt", required=True, help="a run directory (its latest checkpoint) or one checkpoint")
    what.add_argument("--episodes", type=int, default=128, help="episodes to run (default: 128)")
    output.add_argument("--videos", type=int, default=1, help="episodes to render (default: 1)")
    output.add_argument("--no_video", "--no-video", dest="video", action="store_false", help="skip rendering")
    output.add_argument("--out", default=None, help="output folder (default: <run dir>/eval)")
    what.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    what.add_argument("--task", default=None, choices=sorted(TASKS),
                        help="run the policy on this task's goals, seeing its own task's observation (default: its "
                             "own task; e.g. the report's policy on navigation goals, as a baseline)")
    what.add_argument("--randomize", action="store_true",
                        help="each episode on its own randomized physics (train.py --randomize's ranges)")
    cli.add_env_flags(parser)
    output.add_argument("--shadows", action="store_true",
                        help="render shadows, the skybox and reflections (5x slower without a GPU)")
    parser.add_argument_group("run", "compiling").add_argument("--no_compile_cache", dest="compile_cache", action="store_false",
                        help="don't keep compiled programs in the per-user cache folder")
    args = parser.parse_args(cli.signed_values(sys.argv[1:] if argv is None else list(argv)))
    jax_setup.prepare_jax(compile_cache=args.compile_cache)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    if args.videos < 0:
        parser.error("--videos must be 0 or more")
    try:
        result = evaluation.evaluate(args.ckpt, episodes=args.episodes, videos=args.videos, out=args.out,
                                     seed=args.seed, video=args.video, task=args.task, shadows=args.shadows,
                                     randomize=args.randomize, **cli.env_overrides(args))
    except (FileNotFoundError, RuntimeError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"checkpoint {result['checkpoint']} (step {result['step']:,})")
    print(table.format_table(result["summary"], TASKS[result["config"]["task"]]))
    for path in result["videos"]:
        print(f"video: {path}")
    if "paths" in result:
        print(f"tracks from above: {result['paths']}")
    print(f"foot-contact diagram: {result['gait_diagram']}")
    print("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in result["time_s"].items()) + " (the rollout includes "
          "compiling it, seconds when the compile cache has it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
