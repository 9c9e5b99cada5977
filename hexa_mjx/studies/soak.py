"""Soak: hostile actions for millions of env steps, and a training run killed again and again.

    python -m hexa_mjx.studies.soak [--env_steps 10000000] [--kills 20] [--terms 5] [--out runs/soak] [--seed 0]

Not a unit test: about an hour on a 2-core CPU (runs/soak took 27 min for the actions, 33 for the
kills). Two parts, each skippable:

1. **Actions** (`--env_steps`): batched environments (training's wrappers, randomized physics,
   pushes) stepped with actions that are per step and environment, uniform in [-1, 1], huge
   (x1e6), all NaN, all +-inf, or a per-joint mix of those. Counts non-finite observations and
   rewards (the target is none), and the episodes that ended on a non-finite physics state.
2. **Kills** (`--kills`): a small training run (`--train_args`, by default the fast preset for
   1.97M steps) first runs uninterrupted; then the same run is started in another folder, killed
   with SIGKILL after a random delay and resumed, until `--kills` kills have landed, then stopped
   with SIGTERM (a scheduler's preemption) `--terms` times the same way, then resumed to the end.
   Each delay is uniform between 0 and the uninterrupted run's time to its second
   checkpoint (plus imports), narrowed near the run's end so that every signal lands before it
   finishes, so a kill lands anywhere: importing, compiling, training, evaluating, writing a
   checkpoint. Checks: every evaluation row exactly once and one per
   checkpoint, every checkpoint readable, no `tmp-*` left, Adam's step count at every checkpoint
   equal to the updates trained up to it, each SIGTERM answered with exit code 143 within the
   grace period; and whether the rows (but for their clock fields) and every final parameter,
   normalizer and Adam's state included, are bit-identical to the uninterrupted run's.

Writes `<out>/soak.json` (a skipped part keeps its earlier figures); prints a summary. A finished
run directory is reused.
"""

from __future__ import annotations

import argparse
import functools
import json
import random
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
# 30 intervals of 4 updates of 16,384 steps: brax rounds each interval up to whole updates, so a
# budget on this grid keeps every resumed run's evaluations on the uninterrupted run's steps.
DEFAULT_TRAIN = "--preset fast --num_timesteps 1966080 --num_evals 31 --start_joint_noise 0.1"
IMPORT_S = 10.0  # train.py's start before its run clock: imports, model compile
GRACE_S = 30.0  # s: the grace period a scheduler gives between SIGTERM and SIGKILL (docs/RELIABILITY.md)


def hostile_actions(key, num_envs: int, action_size: int):
    """Actions per environment: uniform in [-1, 1] (40%), x1e6 (15%), NaN (15%), +-inf (15%), or a
    per-joint mix of all four (15%)."""
    import jax
    import jax.numpy as jp

    k_mode, k_u, k_sign, k_mix = jax.random.split(key, 4)
    u = jax.random.uniform(k_u, (num_envs, action_size), minval=-1, maxval=1)
    sign = jp.where(jax.random.bernoulli(k_sign, 0.5, u.shape), 1.0, -1.0)
    kinds = jp.stack([u, u * 1e6, jp.full_like(u, jp.nan), sign * jp.inf])  # (4, envs, joints)
    mode = jax.random.choice(k_mode, 5, (num_envs, 1), p=jp.array([0.4, 0.15, 0.15, 0.15, 0.15]))
    per_joint = jax.random.randint(k_mix, u.shape, 0, 4)
    pick = jp.where(mode == 4, per_joint, mode)
    return jp.take_along_axis(kinds, pick[None], axis=0)[0]


def soak_actions(env_steps: int, num_envs: int, seed: int, chunk: int = 100) -> dict:
    """Step `num_envs` randomized, pushed environments with hostile actions for `env_steps` env steps."""
    import jax
    import jax.numpy as jp

    from hexa_mjx.training import config
    from hexa_mjx.mdp import randomization
    from hexa_mjx.engines import wrappers

    cfg = config.TrainConfig(randomize=True, push_speed=0.5, start_joint_noise=0.1)
    env = config.make_env_for(cfg)
    keys = jax.random.split(jax.random.PRNGKey(seed), num_envs)
    models = functools.partial(randomization.randomization_fn(env), rng=jax.random.split(keys[0], num_envs))
    batched = wrappers.wrap_for_training(env, episode_length=cfg.episode_length, randomization_fn=models)

    def run(state, key):
        def body(carry, _):
            state, key, bad_obs, bad_reward, nonfinite_ends, ends = carry
            key, k = jax.random.split(key)
            state = batched.step(state, hostile_actions(k, num_envs, env.action_size))
            bad_obs += (~jp.isfinite(state.obs).all(axis=-1)).sum()
            bad_reward += (~jp.isfinite(state.reward)).sum()
            nonfinite_ends += (state.metrics["nonfinite"] > 0).sum()
            ends += (state.done > 0).sum()
            return (state, key, bad_obs, bad_reward, nonfinite_ends, ends), None

        zero = jp.zeros((), jp.int32)
        carry, _ = jax.lax.scan(body, (state, key, zero, zero, zero, zero), None, length=chunk)
        return carry[0], carry[1], jp.stack(carry[2:])

    run = jax.jit(run)
    state = jax.jit(batched.reset)(keys)
    key = jax.random.PRNGKey(seed + 1)
    totals, steps, t0, shown = np.zeros(4, np.int64), 0, time.time(), 0.0
    while steps < env_steps:
        state, key, counts = run(state, key)
        totals += np.asarray(counts)
        steps += chunk * num_envs
        if time.time() - shown > 15:
            shown = time.time()
            print(f"  actions: {steps:,}/{env_steps:,} env steps, {steps / (shown - t0):,.0f}/s; non-finite "
                  f"observations {totals[0]}, rewards {totals[1]}", flush=True)
    return {"env_steps": steps, "num_envs": num_envs, "nonfinite_observations": int(totals[0]),
            "nonfinite_rewards": int(totals[1]), "episodes_ended_nonfinite": int(totals[2]),
            "episodes_ended": int(totals[3]), "seconds": round(time.time() - t0, 1)}


def train_command(args: list[str], run_dir: Path, resume: bool) -> list[str]:
    return [sys.executable, str(ROOT / "train.py"), *args, "--run_dir", str(run_dir), *(["--resume"] * resume)]


def rows(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]


def finished(run_dir: Path, args: list[str]) -> bool:
    from hexa_mjx.training import checkpoints, config

    if not (run_dir / "config.json").is_file():
        return False
    found = checkpoints.list_checkpoints(run_dir)
    return bool(found) and found[-1][0] >= config.parse_args(args).num_timesteps


# Long by design: one scenario (train, kill at random, resume, compare) read top to bottom.
def soak_kills(kills: int, terms: int, train_args: list[str], out: Path, seed: int) -> dict:
    """The uninterrupted run, then the same run killed `kills` times and stopped by SIGTERM `terms`
    times, resumed after each; see the module doc."""
    import jax

    from hexa_mjx.training import checkpoints, config, networks, optimizer_state
    from hexa_mjx.training.progress import TIMING_FIELDS
    from hexa_mjx.training.resume import EXIT_CODE

    whole, killed = out / "uninterrupted", out / "killed"
    if not finished(whole, train_args):
        t0 = time.time()
        subprocess.run(train_command(train_args, whole, resume=(whole / "config.json").is_file()), check=True)
        (out / "uninterrupted_s.txt").write_text(f"{time.time() - t0:.1f}\n")
    reference = rows(whole)
    # Kills land between the start and about the second checkpoint (IMPORT_S covers the imports
    # before the run's clock starts), so a resumed run usually gets somewhat further each time. An
    # exact resume loses little, so the window is at most twice the training time left per signal
    # still to send: each attempt also spends its start-up, so every signal lands before the end.
    longest = IMPORT_S + reference[2]["walltime_s"]
    interval_s = reference[1]["walltime_s"] - reference[0]["walltime_s"]
    final_step, training_s = reference[-1]["step"], reference[-1]["walltime_s"] - reference[0]["walltime_s"] + interval_s

    rng = random.Random(seed)
    attempts, landed, stopped, t0 = [], 0, 0, time.time()
    while landed + stopped < kills + terms and not finished(killed, train_args):
        how = signal.SIGKILL if landed < kills else signal.SIGTERM
        resume = (killed / "config.json").is_file()
        proc = subprocess.Popen(train_command(train_args, killed, resume), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        found = checkpoints.list_checkpoints(killed)
        left_s = training_s * (1 - (found[-1][0] if found else 0) / final_step)
        window = min(longest, 2 * left_s / (kills + terms - landed - stopped))
        delay, answered_s = rng.uniform(0, window), None
        try:
            output = proc.communicate(timeout=delay)[0]
        except subprocess.TimeoutExpired:
            proc.send_signal(how)
            sent = time.time()
            try:  # a scheduler kills a job that outlives its grace period
                output = proc.communicate(timeout=GRACE_S if how == signal.SIGTERM else None)[0]
            except subprocess.TimeoutExpired:
                proc.kill()
                output = proc.communicate()[0]
            answered_s = round(time.time() - sent, 1)
        resumed = [line for line in output.splitlines() if line.startswith(("resuming", "removed", "warning"))]
        attempts.append({"signal": signal.Signals(how).name, "delay_s": round(delay, 1), "window_s": round(window, 1),
                         "returncode": proc.returncode, "answered_s": answered_s, "log": resumed})
        landed += proc.returncode == -signal.SIGKILL and how == signal.SIGKILL
        stopped += answered_s is not None and how == signal.SIGTERM
        found = checkpoints.list_checkpoints(killed)
        print(f"  attempt {len(attempts)}: {'finished' if answered_s is None else signal.Signals(how).name} after "
              f"{delay:5.1f} s (exit {proc.returncode}); latest checkpoint {found[-1][0] if found else 0:,}", flush=True)
    subprocess.run(train_command(train_args, killed, resume=True), check=True, stdout=subprocess.DEVNULL)
    killed_s = time.time() - t0

    cfg = config.load_config(whole)
    template = networks.init_params(cfg, config.make_env_for(cfg))
    adam_template = optimizer_state.adam_template(template)
    unreadable, adam_counts_continue = [], True
    per_update = cfg.update_epochs * cfg.num_minibatches  # Adam steps per PPO update
    saved = checkpoints.list_checkpoints(killed)
    for step, path in saved:
        try:
            checkpoints.load_checkpoint(path, template)
            adam = checkpoints.load_optimizer(path, adam_template)
            # A fresh Adam at any resume would count fewer steps than the updates trained so far.
            adam_counts_continue &= int(adam[0].count) == step // cfg.steps_per_update * per_update
        except RuntimeError as e:
            unreadable.append(str(e))
    finals = [checkpoints.list_checkpoints(whole)[-1][1], saved[-1][1]]
    (_, a), (_, b) = (checkpoints.load_checkpoint(p, template) for p in finals)
    adam_a, adam_b = (checkpoints.load_optimizer(p, adam_template) for p in finals)
    flat = lambda tree: np.concatenate([np.ravel(x) for x in jax.tree.leaves(tree)])  # noqa: E731
    killed_rows = rows(killed)
    steps_whole, steps_killed = [r["step"] for r in reference], [r["step"] for r in killed_rows]
    last_a, last_b = reference[-1], killed_rows[-1]
    clockless = lambda rs: [{k: v for k, v in r.items() if k not in TIMING_FIELDS} for r in rs]  # noqa: E731
    # NaN != NaN in Python: compare the rows as JSON text, which writes NaN the same way each time.
    same_rows = json.dumps(clockless(reference), sort_keys=True) == json.dumps(clockless(killed_rows), sort_keys=True)
    terms_sent = [a for a in attempts if a["signal"] == "SIGTERM" and a["answered_s"] is not None]
    return {
        "train_args": train_args, "kills_delivered": landed, "terms_delivered": stopped,
        "attempts": attempts, "kill_delay_max_s": round(longest, 1),
        # Each evaluation once, one per checkpoint (and step 0), on the uninterrupted run's steps.
        # (A SIGTERM between two evaluations leaves a checkpoint without a row.)
        "rows_each_once": len(set(steps_killed)) == len(steps_killed)
                          and set(steps_killed) - {0} <= {s for s, _ in saved},
        "checkpoints_between_evaluations": sorted(s for s, _ in saved if s not in set(steps_whole)),
        "same_steps_as_uninterrupted": steps_killed == steps_whole, "rows": len(steps_killed),
        "rows_bit_identical": same_rows,
        "params_bit_identical": bool(np.array_equal(flat(a), flat(b))),
        "adam_state_bit_identical": bool(np.array_equal(flat(adam_a), flat(adam_b))),
        # 143: stopped as asked; -15: the signal's default action, before train.py's imports had
        # installed its handler (nothing trained yet); 0: the run had finished its last update.
        "term_exit_codes": sorted(a["returncode"] for a in terms_sent),
        "terms_answered_within_grace": all(a["returncode"] in (EXIT_CODE, -signal.SIGTERM, 0)
                                           and a["answered_s"] <= GRACE_S for a in terms_sent),
        "term_answer_s_max": max((a["answered_s"] for a in terms_sent), default=None),
        "adam_counts_continue": adam_counts_continue,
        "checkpoints": len(saved), "unreadable_checkpoints": unreadable,
        "tmp_left": len(list((killed / "checkpoints").glob("tmp-*"))),
        "adam_count": [int(adam_a[0].count), int(adam_b[0].count)],
        "policy_param_relative_difference": float(np.linalg.norm(flat(a[1]) - flat(b[1])) / np.linalg.norm(flat(a[1]))),
        "final_evaluation": {key: [last_a.get(key), last_b.get(key)] for key in
                             ("step", "success_rate", "final_distance", "episode_return", "fall_rate")},
        "killed_run_total_s": round(killed_s, 1),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env_steps", type=int, default=10_000_000, help="hostile-action env steps (0 skips)")
    parser.add_argument("--num_envs", type=int, default=256, help="environments stepped together")
    parser.add_argument("--kills", type=int, default=20, help="SIGKILLs of the training run (0 skips)")
    parser.add_argument("--terms", type=int, default=5, help="SIGTERMs of the training run, after the SIGKILLs")
    parser.add_argument("--train_args", default=DEFAULT_TRAIN, help="train.py flags of the killed run")
    parser.add_argument("--out", type=Path, default=Path("runs/soak"), help="folder for the runs and soak.json")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and of the kill delays")
    args = parser.parse_args(argv)
    if min(args.env_steps, args.kills, args.terms) < 0 or args.num_envs < 1:
        parser.error("--env_steps, --kills and --terms must be >= 0 and --num_envs >= 1")
    train_args = shlex.split(args.train_args)
    if args.kills or args.terms:
        from hexa_mjx.training import config

        try:
            config.parse_args([*train_args, "--run_dir", str(args.out / "killed")])
        except (config.ConfigError, SystemExit) as e:
            parser.error(f"--train_args: {e}")
        if any(a in train_args for a in ("--run_dir", "--resume")):
            parser.error("--train_args: leave out --run_dir and --resume (the soak sets them)")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "soak.json"
    report = json.loads(path.read_text()) if path.is_file() else {}
    if args.env_steps:
        print(f"actions: {args.env_steps:,} env steps on {args.num_envs} environments", flush=True)
        report["actions"] = soak_actions(args.env_steps, args.num_envs, args.seed)
        print(json.dumps(report["actions"]), flush=True)
    if args.kills or args.terms:
        print(f"kills: {args.kills} SIGKILLs and {args.terms} SIGTERMs of train.py {args.train_args}", flush=True)
        report["kills"] = soak_kills(args.kills, args.terms, train_args, args.out, args.seed)
        print(json.dumps({k: v for k, v in report["kills"].items() if k != "attempts"}), flush=True)
    path.write_text(json.dumps(report, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
