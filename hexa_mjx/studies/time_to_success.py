"""Wall time to a good policy: train configurations side by side and time their first success.

    python -m hexa_mjx.studies.time_to_success --configs default fast --seeds 0 1 2 --out runs/tts

Each run is a real `train.py` process (compile included, as a user sees it), given the same
seeds; configurations take turns within each seed so that machine noise falls on all of them.
A run stops (SIGTERM, which train.py treats as Ctrl-C) at its first evaluation with success at or above
`--target`, unless `--full` lets it finish its budget. It prints, per configuration and seed:
wall time and env steps to that evaluation; seconds from launch to train.py's "training compiled"
line (the first update; absent with --no_progress) and to its first evaluation row; with `--full`,
the share of the run spent evaluating (train.py's last lines); and a median-and-range summary.
A configuration's flags may name another checkout of hexa_mjx (`--checkout DIR`), whose train.py
then runs: two versions side by side, e.g. `--configs fast "before=--checkout ../old --recipe fast"`.
Everything is also written to `<out>/time_to_success.json`.

`--verify 128` checks each run with eval.py afterwards (128 episodes, the run's own starts): the
checkpoints from its first training evaluation at the target on, until one reaches the target in
eval.py too (the time to success that counts), and, with `--full`, the final checkpoint against
the report task's targets (median final distance, falls, body contact). A run stopped at its
first success leaves no checkpoint of that step (it is stopped as the row is written), so
`--verify` needs `--full`.
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# Configurations: train.py flags. "default" is train.py as it is; recipes are named by train.py.
CONFIGS = {
    "default": [],
    "paper": ["--recipe", "paper"],
    "fast": ["--recipe", "fast"],
}
# Random starts, as the evaluations that decide success are meant to be (eval.py's perturbed starts).
RANDOM_STARTS = ["--start_joint_noise", "0.1", "--start_yaw_noise", "0.3"]
EVALUATION_SHARE = re.compile(r"evaluations: (\d+) took (\d+) s, (\d+)% of the run's")
CHECKOUT = "--checkout"  # a configuration's flag: run DIR/train.py (another version of the code) instead of this one's
FIRST_UPDATE = re.compile(r"training compiled and its first (?:update|rollout) ran in (\d+) s \((\d+) s since the start\)")


def parse_config(text: str) -> tuple[str, list[str]]:
    """A configuration: a name from CONFIGS, or NAME=FLAGS (e.g. "e4=--update_epochs 4"; with
    "--checkout DIR" among the flags, DIR's train.py runs: another version side by side)."""
    if "=" in text:
        name, flags = text.split("=", 1)
        return name, flags.split()
    if text not in CONFIGS:
        raise SystemExit(f"error: unknown configuration {text!r}; use one of {sorted(CONFIGS)} or NAME='--flag value ...'")
    return text, CONFIGS[text]


def first_success(metrics_path: Path, target: float):
    """(step, walltime_s) of the first evaluation row with success_rate >= target, or None."""
    if not metrics_path.is_file():
        return None
    return first_row_at([json.loads(line) for line in metrics_path.read_text().splitlines()], target)


def first_row_at(rows: list[dict], target: float):
    """(step, walltime_s) of the first of `rows` with success_rate >= target, or None."""
    for row in rows:
        if row.get("success_rate", 0.0) >= target:
            return row["step"], row["walltime_s"]
    return None


def run_one(flags: list[str], run_dir: Path, target: float, full: bool, timeout_s: float) -> dict:
    """Train once in a subprocess; stop it at its first success unless `full`. Times are seconds
    from launch: to the first training update's line and to the first evaluation row's."""
    root = ROOT
    if CHECKOUT in flags:
        at = flags.index(CHECKOUT)
        root, flags = Path(flags[at + 1]).resolve(), flags[:at] + flags[at + 2:]
    cmd = [sys.executable, str(root / "train.py"), *flags, "--run_dir", str(run_dir.resolve())]
    t0 = time.time()
    # A shell's background job ignores SIGINT, and its children inherit that: stop runs with SIGTERM,
    # which train.py handles as Ctrl-C (the last complete checkpoint is kept).
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out, hit, first_update, first_row, share = [], None, None, None, None
    for line in proc.stdout:
        out.append(line)
        if FIRST_UPDATE.search(line) and first_update is None:
            first_update = round(time.time() - t0, 1)
        if line.startswith("step ") and first_row is None:
            first_row = round(time.time() - t0, 1)
        match = EVALUATION_SHARE.search(line)
        if match:
            share = int(match.group(3)) / 100
        if hit is None and line.startswith("step "):
            hit = first_success(run_dir / "metrics.jsonl", target)
            if hit and not full:
                proc.send_signal(signal.SIGTERM)
        if time.time() - t0 > timeout_s:
            proc.send_signal(signal.SIGTERM)
    proc.wait()
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()] if (
        run_dir / "metrics.jsonl").is_file() else []
    # Seconds from the step-0 evaluation to the last one: training (first compile included) and evaluations.
    trained_s = rows[-1]["walltime_s"] - rows[0]["walltime_s"] if len(rows) > 1 else None
    return {"command": " ".join(cmd[1:]), "returncode": proc.returncode, "wall_s": time.time() - t0,
            "first_update_s": first_update, "first_row_s": first_row, "evaluation_share": share,
            "success_step": hit[0] if hit else None, "success_wall_s": hit[1] if hit else None,
            "trained_s": trained_s, "last": rows[-1] if rows else None, "log_tail": "".join(out[-5:])}


def evaluate_checkpoint(checkpoint: Path, episodes: int) -> dict:
    """eval.py's summary of one checkpoint (no video), with the seconds eval.py took."""
    out = checkpoint.parent.parent / "verify" / checkpoint.name
    t0 = time.time()
    proc = subprocess.run([sys.executable, str(ROOT / "eval.py"), "--ckpt", str(checkpoint), "--episodes",
                           str(episodes), "--no-video", "--out", str(out)], cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"eval.py failed on {checkpoint}:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    summary = json.loads((out / "metrics.json").read_text())["summary"]
    return {"step": int(checkpoint.name), "eval_s": round(time.time() - t0, 1),
            "success_rate": summary["success_rate"], "final_distance_median": summary["final_distance_median"],
            "fall_rate": summary["fall_rate"], "feet_only_steps": summary.get("feet_only_steps"),
            "body_contact": summary["reward_terms"].get("body_contact")}


def verify_run(run_dir: Path, target: float, episodes: int) -> dict:
    """eval.py on the run's checkpoints from its first training evaluation at `target` on, until one
    reaches `target`; and on its last checkpoint. Wall times are the training rows' (train.py's
    clock, the same as the study's)."""
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines() if x.strip()]
    wall = {row["step"]: row["walltime_s"] for row in rows}
    saved = {int(p.name): p for p in (run_dir / "checkpoints").iterdir() if p.name.isdigit()}
    hit = first_row_at(rows, target)
    checked, verified = [], None
    for step in sorted(s for s in saved if hit and s >= hit[0]):
        checked.append(evaluate_checkpoint(saved[step], episodes))
        if checked[-1]["success_rate"] >= target:
            verified = step
            break
    final = next((c for c in checked if c["step"] == max(saved)), None) if saved else None
    if saved and final is None:
        final = evaluate_checkpoint(saved[max(saved)], episodes)
    return {"checked": checked, "verified_step": verified, "verified_wall_s": wall.get(verified),
            "final": final}


def verify_line(name: str, seed, v: dict, target: float) -> str:
    got = (f"{v['verified_wall_s'] / 60:.1f} min ({v['verified_step']:,} steps)" if v["verified_step"] is not None
           else "not reached")
    f = v["final"]
    final = (f"final ({f['step']:,} steps): success {f['success_rate']:.1%}, median distance "
             f"{f['final_distance_median']:.2f} m, falls {f['fall_rate']:.1%}, feet-only steps "
             f"{f['feet_only_steps']:.1%}, body contact {f['body_contact']:.1f}/episode" if f else "no checkpoint")
    return (f"{name} seed {seed}: eval.py success >= {target:.0%} at {got}; {final}; "
            f"eval.py took {', '.join(str(c['eval_s']) for c in v['checked'])} s")


def summary_line(name: str, results: list[dict]) -> str:
    times = [r["success_wall_s"] for r in results if r["success_wall_s"] is not None]
    steps = [r["success_step"] for r in results if r["success_step"] is not None]
    compiles = [r["first_update_s"] for r in results if r["first_update_s"] is not None]
    first_rows = [r["first_row_s"] for r in results if r.get("first_row_s") is not None]
    shares = [r["evaluation_share"] for r in results if r.get("evaluation_share") is not None]
    fmt = lambda xs, f: (f"{f(statistics.median(xs))} [{f(min(xs))}, {f(max(xs))}]" if xs else "-")  # noqa: E731
    return (f"{name:<12} reached {len(times)}/{len(results)}  wall time to success, median [range] "
            f"{fmt(times, lambda x: f'{x / 60:.1f} min')}  env steps {fmt(steps, lambda x: f'{x / 1e6:.2f}M')}  "
            f"from launch: first update {fmt(compiles, lambda x: f'{x:.0f} s')}, first evaluation row "
            f"{fmt(first_rows, lambda x: f'{x:.0f} s')}, evaluating {fmt(shares, lambda x: f'{x:.0%}')} of a whole run")


def verified_summary_line(name: str, results: list[dict]) -> str:
    times = [r["verify"]["verified_wall_s"] for r in results if r["verify"]["verified_wall_s"] is not None]
    finals = [r["verify"]["final"] for r in results if r["verify"]["final"]]
    med = lambda key: statistics.median(f[key] for f in finals)  # noqa: E731
    return (f"{'':<12} eval.py: reached {len(times)}/{len(results)}  wall time, median [range] "
            + (f"{statistics.median(times) / 60:.1f} min [{min(times) / 60:.1f}, {max(times) / 60:.1f}]" if times else "-")
            + (f"  final policies, median: success {med('success_rate'):.1%}, distance "
               f"{med('final_distance_median'):.2f} m, falls {med('fall_rate'):.1%} (worst "
               f"{max(f['fall_rate'] for f in finals):.1%})" if finals else ""))


def report_runs(run_dirs: list[Path], target: float, verify: int = 0) -> int:
    """Print each finished run's first evaluation at or above `target` and its whole run (and, with
    `verify` episodes, eval.py's check of its checkpoints)."""
    for run_dir in run_dirs:
        metrics = run_dir / "metrics.jsonl"
        if not metrics.is_file():
            print(f"error: {metrics} not found: is {run_dir} a train.py run directory?", file=sys.stderr)
            return 2
        rows = [json.loads(x) for x in metrics.read_text().splitlines() if x.strip()]
        hit = first_row_at(rows, target)
        got = f"{hit[1] / 60:.1f} min, {hit[0]:,} steps" if hit else "not reached"
        print(f"{run_dir}: success >= {target:.1%} at {got}; run {rows[-1]['step']:,} steps in "
              f"{rows[-1]['walltime_s'] / 60:.1f} min; last evaluation success {rows[-1]['success_rate']:.0%}, "
              f"falls {rows[-1]['fall_rate']:.0%}")
        if verify:
            print(verify_line(run_dir.name, "-", verify_run(run_dir, target, verify), target), flush=True)
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.time_to_success", description=__doc__.split("\n\n")[0])
    parser.add_argument("--configs", nargs="+", default=["default", "fast"],
                        help=f"configurations: {sorted(CONFIGS)} or NAME='--flag value ...' (default: default fast)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="seeds (default: 0)")
    parser.add_argument("--target", type=float, default=0.9, help="success rate that counts (default: 0.9)")
    parser.add_argument("--extra", default="", help="flags added to every run, e.g. '--num_timesteps 3000000' "
                        "(a lone flag needs the equals sign: --extra=--no_compile_cache)")
    parser.add_argument("--fixed_start", action="store_true",
                        help="train and evaluate from the report's fixed start instead of random starts")
    parser.add_argument("--full", action="store_true", help="let every run finish its budget")
    parser.add_argument("--timeout_min", type=float, default=60.0, help="stop a run after this long (default: 60)")
    parser.add_argument("--out", default="runs/time_to_success", help="folder for the runs and the JSON")
    parser.add_argument("--verify", type=int, default=0, metavar="EPISODES",
                        help="after training, check the runs with eval.py over this many episodes (needs --full)")
    parser.add_argument("--runs", nargs="+", type=Path, default=None,
                        help="instead of training: read these finished run directories and print the same figures")
    args = parser.parse_args(argv)
    if args.verify < 0:
        parser.error("--verify takes a number of episodes, 0 (off) or more")
    if args.runs:
        return report_runs(args.runs, args.target, args.verify)
    if args.verify and not args.full:
        parser.error("--verify needs --full: a run stopped at its first success has no checkpoint of that step")
    configs = [parse_config(c) for c in args.configs]
    out = Path(args.out)
    if out.exists() and any(out.iterdir()):
        print(f"error: {out} is not empty; choose another --out", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, list[dict]] = {name: [] for name, _ in configs}
    for k, seed in enumerate(args.seeds):
        turn = configs[k % len(configs):] + configs[:k % len(configs)]  # alternate who goes first
        for name, flags in turn:
            run_flags = [*flags, *([] if args.fixed_start else RANDOM_STARTS), *args.extra.split(), "--seed", str(seed)]
            r = run_one(run_flags, out / f"{name}-s{seed}", args.target, args.full, args.timeout_min * 60)
            results[name].append({"seed": seed, **r})
            got = (f"{r['success_wall_s'] / 60:.1f} min, {r['success_step']:,} steps" if r["success_step"] is not None
                   else "not reached")
            share = f"{r['evaluation_share']:.0%}" if r["evaluation_share"] is not None else "-"
            print(f"{name} seed {seed}: success >= {args.target:.0%} at {got}; from launch: first update "
                  f"{r['first_update_s']} s, first evaluation row {r['first_row_s']} s; step-0 to last evaluation "
                  f"{r['trained_s']} s; run {r['wall_s'] / 60:.1f} min, evaluating {share} of it", flush=True)
    (out / "time_to_success.json").write_text(json.dumps(results, indent=1))
    if args.verify:
        print(f"\nverifying with eval.py, {args.verify} episodes per checkpoint")
        for name, _ in configs:
            for r in results[name]:
                r["verify"] = verify_run(out / f"{name}-s{r['seed']}", args.target, args.verify)
                print(verify_line(name, r["seed"], r["verify"], args.target), flush=True)
        (out / "time_to_success.json").write_text(json.dumps(results, indent=1))
    print("\nside by side, seeds " + " ".join(map(str, args.seeds)))
    for name, _ in configs:
        print(summary_line(name, results[name]))
        if args.verify:
            print(verified_summary_line(name, results[name]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
