"""What a training run tells its user: metrics.jsonl rows, TensorBoard scalars, console lines."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from hexa_mjx.tasks import task_class
from hexa_mjx.training.checks import run_scales
from hexa_mjx import atomic

if TYPE_CHECKING:
    from hexa_mjx.training.config import TrainConfig

PROGRESS_INTERVAL_S = 15.0  # at most this long without a console line while training
RATE_WINDOW = 20  # updates: the ETA's training rate is measured over the latest this many


class Eta:
    """Time left: the steps to go at the recent training rate (the latest RATE_WINDOW updates, no
    compiling or evaluating in it), plus the evaluations still to come at their measured cost."""

    def __init__(self, total_steps: int, num_evals: int):
        self.total, self.num_evals = total_steps, num_evals
        self.updates, self.evaluations = [], []  # (time, step) after each update; s per evaluation

    def update(self, t: float, step: int) -> None:
        self.updates = (self.updates + [(t, step)])[-RATE_WINDOW - 1:]

    def paused(self) -> None:
        """Compiling or an evaluation ran: the next update starts a new rate window."""
        self.updates = []

    def evaluation(self, seconds: float) -> None:
        self.evaluations.append(seconds)

    @property
    def rate(self) -> float:
        """env steps/s over the window (NaN before two updates)."""
        if len(self.updates) < 2:
            return math.nan
        (t0, s0), (t1, s1) = self.updates[0], self.updates[-1]
        return (s1 - s0) / (t1 - t0) if t1 > t0 else math.nan

    def left(self, step: int) -> float:
        """s until the run ends (NaN before a rate)."""
        to_go = max(self.total - step, 0)
        interval = self.total / max(self.num_evals - 1, 1)
        evaluations = math.ceil(to_go / interval - 1e-9) if to_go else 0
        cost = sorted(self.evaluations)[len(self.evaluations) // 2] if self.evaluations else 0.0
        return to_go / self.rate + evaluations * cost if self.rate > 0 else math.nan

def summarize(metrics: dict) -> dict:
    """The figures a user watches, from brax's eval metrics (per-episode sums, averaged)."""
    get = lambda k: float(metrics.get(f"eval/episode_{k}", math.nan))  # noqa: E731
    return {
        "episode_return": get("reward"),
        "final_distance": get("final_distance"),
        "success_rate": get("final_success"),
        "goal_bonus": get("goal_bonus"),
        "fall_rate": get("fell"),
        "nonfinite_rate": get("nonfinite"),
        "goals_per_episode": get("goals_reached"),
        "episode_length": float(metrics.get("eval/avg_episode_length", math.nan)),
    }


def evaluation_figures(metrics: dict) -> dict:
    """An evaluation row's figures: `summarize`'s, each reward term's per-episode sum, and the
    curriculum's and failure schedule's, where `metrics` has them."""
    return {**summarize(metrics), **{k: float(v) for k, v in metrics.items()
                                     if k.startswith(("eval/episode_reward/", "curriculum/", "leg_failure/"))}}


def read_rows(run_dir: Path, name: str = "metrics.jsonl") -> tuple[list[dict], int]:
    """The evaluation rows of the run's `name` (metrics.jsonl) in file order (none without the
    file), and how many other non-empty lines it has (cut short by a crash, or damaged)."""
    path = Path(run_dir) / name
    rows, dropped = [], 0
    for line in path.read_text(errors="replace").splitlines() if path.is_file() else []:
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            row = None
        if isinstance(row, dict) and isinstance(row.get("step"), int):
            rows.append(row)
        else:
            dropped += bool(line.strip())
    return rows, dropped


def keep_rows_up_to(run_dir: Path, step: int) -> set[int]:
    """Rewrite metrics.jsonl with one row per evaluation step up to `step` (the checkpoint a run
    resumes from): rows of a later step, written before a crash lost their checkpoint, would be
    written again, and a duplicate step is kept once. Returns the steps kept."""
    path = Path(run_dir) / "metrics.jsonl"
    if not path.is_file():
        return set()
    kept, lines = set(), []
    rows, dropped = read_rows(run_dir)
    for row in rows:
        if row["step"] <= step and row["step"] not in kept:
            kept.add(row["step"])
            lines.append(json.dumps(row))
    if dropped:
        print(f"note: {path}: dropped {dropped} line(s) that are not evaluation rows (cut short by a crash, or "
              "damaged)")
    atomic.write(path, "".join(line + "\n" for line in lines))
    return kept


class RowWriteError(OSError):
    """An evaluation row could not be written."""


# Row fields that time the run rather than describe the policy: they differ between identical runs.
TIMING_FIELDS = ("walltime_s", "evaluation_s", "env_steps_per_s")


class Logger:
    """metrics.jsonl rows, TensorBoard scalars and one console line per evaluation; between
    evaluations a progress line at least every PROGRESS_INTERVAL_S, and lines that say when the
    programs are compiling."""

    def __init__(self, run_dir: Path, cfg: TrainConfig, start_step: int, interval_s: float = PROGRESS_INTERVAL_S):
        from tensorboardX import SummaryWriter

        self.path = Path(run_dir) / "metrics.jsonl"
        self.tb = SummaryWriter(str(Path(run_dir) / "tb"))
        self.cfg, self.start_step, self.t0 = cfg, start_step, time.time()
        self.task, self.scales = task_class(cfg.task), run_scales(cfg)  # what the rows' figures are read with
        self.interval_s = interval_s
        self.last = {}
        self.phase, self.phase_t0 = "", self.t0
        self.last_line_t, self.last_line_step = self.t0, start_step
        self.first_update_s = None
        self.evaluation_t0, self.evaluation_ran = None, False  # when the first evaluation started; whether it ran
        self.eta, self.this_evaluation_t0 = Eta(cfg.num_timesteps, cfg.num_evals), None
        self.evaluation_s = []  # each evaluation's wall time (the first compiles its program too)

    def compiling(self, evaluation_first: bool = True) -> None:
        """Say that the programs are being compiled (or loaded from cache): the evaluation's first
        when the run evaluates before training, else the training's."""
        self.phase = "evaluation" if evaluation_first else "training"
        self.phase_t0 = time.time()
        print(f"compiling the environment and {self.phase} programs (1-3 min on a 2-core CPU the first time; "
              "seconds when the compile cache has them) ...", flush=True)

    def evaluating(self) -> None:
        """An evaluation starts: the first one compiles its program."""
        if self.evaluation_t0 is None and not self.evaluation_ran:
            self.evaluation_t0 = self.phase_t0 if self.phase == "evaluation" else time.time()
        self.this_evaluation_t0 = time.time()

    def progress(self, step: int, episode_return: Callable[[], float]) -> None:
        """An update has run (`hexa_mjx.training.ppo`): the run is at `step` env steps, and `episode_return()`
        reads the mean of the training environments' latest finished returns. Prints a line at most
        every `interval_s`, and says when the training program has compiled and run once."""
        now = time.time()
        if self.phase == "training":
            self.first_update_s = now - self.phase_t0
            print(f"training compiled and its first update ran in {self.first_update_s:.0f} s "
                  f"({now - self.t0:.0f} s since the start)", flush=True)
            self.phase = ""
            self.last_line_t, self.last_line_step = now, step
            self.eta.update(now, step)
            return
        self.eta.update(now, step)
        if now - self.last_line_t < self.interval_s or step <= self.last_line_step:
            return
        rate = (step - self.last_line_step) / (now - self.last_line_t)
        left = self.eta.left(step)
        print(f"  step {step:>9,}/{self.cfg.num_timesteps:,}  {rate:7.0f} steps/s  left {fmt_time(left)}  "
              f"training episodes' return {episode_return():8.1f}", flush=True)
        self.last_line_t, self.last_line_step = now, step

    def __call__(self, step: int, metrics: dict) -> None:
        elapsed = time.time() - self.t0
        done = step - self.start_step
        rate = done / elapsed if done > 0 and elapsed > 0 else math.nan
        evaluation_s = time.time() - self.this_evaluation_t0 if self.this_evaluation_t0 is not None else math.nan
        row = {"step": step, "walltime_s": round(elapsed, 2), "evaluation_s": round(evaluation_s, 2),
               "env_steps_per_s": rate, **evaluation_figures(metrics)}
        try:
            with open(self.path, "a") as f:
                f.write(json.dumps(row) + "\n")
        except OSError as e:  # a full disk: a row cut short is dropped with a note on resume
            raise RowWriteError(f"could not write an evaluation row to {self.path} ({e.strerror or e}); the last "
                                "complete checkpoint is kept: make room, then continue with --resume") from e
        for key, value in row.items():
            if key != "step" and isinstance(value, float) and math.isfinite(value):
                self.tb.add_scalar(key.replace("eval/episode_", ""), value, step)
        self.tb.flush()
        left = self.eta.left(step)  # before `evaluated` starts a new rate window
        self.evaluated(step)
        goal = (f"distance {row['final_distance']:.2f} m  success {row['success_rate']:.0%}  " if self.task.has_goal
                else "")
        print(f"step {step:>9,}/{self.cfg.num_timesteps:,}  {rate:7.0f} steps/s  left {fmt_time(left)}  "
              f"return {row['episode_return']:8.1f}  {goal}{self.task.progress_figure(row, self.scales)}  falls {row['fall_rate']:.0%}"
              + (f"  non-finite {row['nonfinite_rate']:.0%}" if row["nonfinite_rate"] > 0 else "")
              + (f"  curriculum level {row['curriculum/level_mean']:.1f} (top {row['curriculum/top_level_share']:.0%})"
                 if "curriculum/level_mean" in row else ""), flush=True)
        self.last = row

    def evaluated(self, step: int) -> None:
        """An evaluation has run and its row is written; the first one says that the evaluation
        program is ready (and, before training, that the training one is compiling)."""
        now = time.time()
        if self.this_evaluation_t0 is not None:
            self.evaluation_s.append(now - self.this_evaluation_t0)
            if self.evaluation_ran:  # the first one also compiled: not a guide to the others
                self.eta.evaluation(now - self.this_evaluation_t0)
        self.eta.paused()
        if self.evaluation_t0 is not None:
            before_training = self.phase == "evaluation"
            print(f"evaluation compiled and run in {now - self.evaluation_t0:.0f} s"
                  + ("; compiling the training programs ..." if before_training else ""), flush=True)
            self.evaluation_t0, self.evaluation_ran = None, True
            if before_training:
                self.phase, self.phase_t0 = "training", now
        self.last_line_t, self.last_line_step = now, step

    def close(self):
        """Say what share of the run's wall time went to evaluating, and close TensorBoard."""
        total = time.time() - self.t0
        if self.evaluation_s and total > 0:
            spent = sum(self.evaluation_s)
            print(f"evaluations: {len(self.evaluation_s)} took {spent:.0f} s, {spent / total:.0%} of the run's "
                  f"{total:.0f} s (the first includes compiling its program)", flush=True)
        self.tb.close()


def fmt_time(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "  --:--"
    return f"{int(seconds // 60):4d}:{int(seconds % 60):02d}"
