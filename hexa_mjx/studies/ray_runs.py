"""Study grids and hyperparameter sweeps on Ray: each run a Ray task, each sweep trial a Tune trial.

    python -m hexa_mjx.studies.experiments main --ray                 # a local Ray instance on this machine
    python -m hexa_mjx.studies.experiments main --ray HOST:6379 --run_cpus 4 --run_gpus 0.5
    python -m hexa_mjx.studies.experiments sweep --space space.json --samples 8 [--ray ADDRESS]

Ray schedules; this module only says what one run is. A run is `training.train` in a fresh Ray
worker process (`max_calls=1`: JAX must be set up before it starts, once per process). A worker
that dies is retried by Ray (`max_retries`), and the retry resumes the run from its last
checkpoint, so nothing is lost and no evaluation row is written twice (hexa_mjx.training.checkpoints,
hexa_mjx.training.progress). Runs write into the shared output folder: on a cluster it must be a shared
filesystem, as for any Ray job that writes files.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import socket
from pathlib import Path

from hexa_mjx.training import config, jax_setup

RETRIES = 3  # times Ray re-runs a run whose worker died; each retry resumes from the last checkpoint
GPU_MEMORY_SHARE = 0.9  # of a fractional GPU's share, for JAX's preallocation (its default is 75% of the GPU)


def check_address(address: str, timeout_s: float = 5.0) -> None:
    """ValueError unless a Ray cluster answers at `address` ("local": none needed; "auto": the
    cluster this machine belongs to, which Ray itself finds)."""
    if address in ("local", "auto"):
        return
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--ray must be HOST:PORT, ray://HOST:PORT or auto, got {address!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as e:
        raise ValueError(f"no Ray cluster answers at {address} ({e.strerror or e}); start one with "
                         f"`ray start --head` or leave out the address for a local instance") from None


def start(address: str) -> None:
    """Connect to the Ray cluster at `address`, or start a local instance ("local")."""
    import ray

    check_address(address)
    # "local" makes Ray start a new instance even when another one runs on this machine.
    ray.init(address=address, include_dashboard=False,
             log_to_driver=True, configure_logging=False)


def worker_env(run_gpus: float) -> dict:
    """Environment of a run's worker: a run on a fraction of a GPU preallocates only its share."""
    if 0 < run_gpus < 1:
        return {"XLA_PYTHON_CLIENT_MEM_FRACTION": f"{GPU_MEMORY_SHARE * run_gpus:.3f}"}
    return {}


def train_in_worker(cfg_dict: dict, run_gpus: float = 0.0, on_eval=None) -> dict:
    """One run, in a fresh process: JAX set up (a GPU share limits its memory), resumed if the run
    dir already holds a checkpoint (a retried task after its worker died), trained to the end."""
    from hexa_mjx.training import checkpoints, jax_setup, loop as training

    os.environ.update(worker_env(run_gpus))  # read when JAX starts its backend, below
    cfg = config.TrainConfig(**cfg_dict)
    jax_setup.prepare_jax(cfg.cpu_devices, cfg.compile_cache)
    run_dir = Path(cfg.run_dir)
    cfg = dataclasses.replace(cfg, resume=(run_dir / "config.json").is_file())
    if cfg.resume and checkpoints.list_checkpoints(run_dir):
        print(f"{run_dir}: resuming after an interruption")
    return training.train(cfg, on_eval=on_eval)


def run_grid(todo: list[config.TrainConfig], run_cpus: int, run_gpus: float) -> list[dict]:
    """Train `todo` as Ray tasks, as many at a time as the cluster's resources allow; returns each
    run's last evaluation row, in order."""
    import ray

    remote = ray.remote(num_cpus=run_cpus, num_gpus=run_gpus, max_calls=1, max_retries=RETRIES,
                        retry_exceptions=False)(train_in_worker)
    refs = [remote.remote(dataclasses.asdict(dataclasses.replace(cfg, cpu_devices=cpu_devices(cfg, run_cpus, run_gpus))),
                          run_gpus) for cfg in todo]
    results, failed = [], []
    for cfg, ref in zip(todo, refs):
        try:
            results.append(ray.get(ref))
        except ray.exceptions.RayError as e:  # the run raised, or its worker died RETRIES + 1 times
            failed.append(f"{cfg.run_dir} ({type(e).__name__}: {str(e).strip().splitlines()[-1][:200]})")
    if failed:
        raise RuntimeError(f"{len(failed)} of {len(todo)} runs failed: {'; '.join(failed)}. Run the same command "
                           "again to resume them")
    return results


def cpu_devices(cfg: config.TrainConfig, run_cpus: int, run_gpus: float) -> int:
    """CPU devices a run may split into: the cores Ray gave it (none to split on a GPU)."""
    if run_gpus > 0:
        return cfg.cpu_devices
    return jax_setup.dividing_devices(cfg, run_cpus)


# ---------------------------------------------------------------------------
# Sweeps


def load_space(path: Path) -> dict:
    """A search space from JSON: {"flag": {"loguniform": [lo, hi]} | {"uniform": [lo, hi]} |
    {"choice": [values]} | value}. Keys are train.py flags (TrainConfig fields); ValueError names
    an unknown one or a malformed entry."""
    try:
        space = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"--space {path}: cannot read a JSON search space ({e})") from None
    if not isinstance(space, dict) or not space:
        raise ValueError(f"--space {path} must be a JSON object of train.py flags, e.g. "
                         '{"lr": {"loguniform": [1e-4, 1e-3]}, "update_epochs": {"choice": [2, 4, 8]}}')
    known = {f.name for f in dataclasses.fields(config.TrainConfig)}
    unknown = sorted(set(space) - known)
    if unknown:
        raise ValueError(f"--space {path} names unknown flags: {', '.join(unknown)} (train.py --help lists them)")
    for name, spec in space.items():
        values = [spec]
        if isinstance(spec, dict):
            (kind, values), = spec.items() if len(spec) == 1 else ((None, None),)
            if kind not in ("loguniform", "uniform", "choice") or not isinstance(values, list) or not values:
                raise ValueError(f"--space {path}: {name} must be a value or one of {{\"loguniform\": [low, high]}}, "
                                 f"{{\"uniform\": [low, high]}}, {{\"choice\": [values]}}; got {spec}")
            if kind != "choice" and not (len(values) == 2 and values[0] <= values[1]
                                         and (kind == "uniform" or values[0] > 0)):
                raise ValueError(f"--space {path}: {name}'s {kind} needs [low, high] with low <= high"
                                 f"{' and low > 0' if kind == 'loguniform' else ''}, got {values}")
        for value in values:  # every end of the range must be a valid setting, checked before Ray starts
            try:
                config.check_ranges(dataclasses.replace(config.TrainConfig(), **{name: value}))
            except (config.ConfigError, TypeError) as e:
                raise ValueError(f"--space {path}: {name}={value!r} is not a valid setting ({e})") from None
    return space


def tune_space(space: dict) -> dict:
    """Ray Tune's search space for load_space()'s dictionary."""
    from ray import tune

    kinds = {"loguniform": lambda v: tune.loguniform(*v), "uniform": lambda v: tune.uniform(*v),
             "choice": tune.choice}
    return {name: kinds[next(iter(spec))](next(iter(spec.values()))) if isinstance(spec, dict) else spec
            for name, spec in space.items()}


def command_line(cfg: config.TrainConfig) -> str:
    """The train.py command that repeats a run: every setting that differs from the default."""
    default = config.TrainConfig()
    parts = ["python train.py"]
    for f in dataclasses.fields(config.TrainConfig):
        value = getattr(cfg, f.name)
        if value == getattr(default, f.name) or f.name == "resume":
            continue
        if isinstance(value, bool):
            parts.append(f"--{f.name}" if value else f"--no_{f.name}")
        elif isinstance(value, list):
            parts.append(f"--{f.name} " + " ".join(str(v) for v in value))
        else:
            parts.append(f"--{f.name} {value}")
    return " ".join(parts)


def sweep(base: config.TrainConfig, space: dict, samples: int, out: Path, metric: str, run_cpus: int,
          run_gpus: float, grace_evals: int = 2) -> list[dict]:
    """Ray Tune over `space` around `base`, ASHA stopping trials whose evaluation `metric` lags
    (a rung every `grace_evals` evaluations). Each trial is a run under <out>/trials/. Returns one
    row per trial: its settings, steps reached and last evaluation."""
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler

    trials_dir = (Path(out) / "trials").resolve()
    per_eval = base.num_timesteps / max(1, base.num_evals - 1)

    def trainable(params: dict) -> None:
        name = "-".join(f"{k}_{params[k]:.3g}" if isinstance(params[k], float) else f"{k}_{params[k]}"
                        for k in sorted(space)) + f"-{tune.get_context().get_trial_id()}"
        cfg = dataclasses.replace(base, **params, run_dir=str(trials_dir / name))
        train_in_worker(dataclasses.asdict(cfg), run_gpus, on_eval=lambda row: tune.report(
            {**row, "evaluation": round(row["step"] / per_eval), "run_dir": cfg.run_dir}))

    scheduler = ASHAScheduler(time_attr="evaluation", max_t=base.num_evals - 1, grace_period=grace_evals,
                              reduction_factor=2)
    tuner = tune.Tuner(
        tune.with_resources(trainable, {"cpu": run_cpus, "gpu": run_gpus}),
        param_space=tune_space(space),
        tune_config=tune.TuneConfig(metric=metric, mode="max", scheduler=scheduler, num_samples=samples,
                                    reuse_actors=False),  # a fresh process per trial: JAX set up per run
        run_config=tune.RunConfig(name="tune", storage_path=str((Path(out) / "ray").resolve()), verbose=1))
    results = tuner.fit()
    rows = []
    for result in results:
        last = result.metrics or {}
        params = {k: result.config[k] for k in space}
        rows.append({**params, "steps": last.get("step", 0), "success_rate": last.get("success_rate", math.nan),
                     "episode_return": last.get("episode_return", math.nan),
                     "final_distance": last.get("final_distance", math.nan), "run_dir": last.get("run_dir", ""),
                     "error": str(result.error)[:200] if result.error else ""})
    return rows


def best(rows: list[dict], metric: str, budget: int) -> dict:
    """The trial that trained the whole budget with the highest `metric` (ties: higher return)."""
    finished = [r for r in rows if r["steps"] >= budget and math.isfinite(r[metric])]
    if not finished:
        raise RuntimeError("no trial trained its whole budget; raise --samples or the budget")
    return max(finished, key=lambda r: (r[metric], r["episode_return"]))


def write_sweep(rows: list[dict], space: dict, metric: str, out: Path) -> list[Path]:
    """results.md / results.csv (one row per trial, best first) and a plot of the metric over the
    first two searched flags."""
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(rows, key=lambda r: (-(r[metric] if math.isfinite(r[metric]) else -math.inf), -r["steps"]))
    names = list(space)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    fmt = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)  # noqa: E731
    lines = ["| " + " | ".join(names) + " | steps | success | return | distance (m) |",
             "|" + "---|" * (len(names) + 4)]
    lines += ["| " + " | ".join(fmt(r[n]) for n in names) + f" | {r['steps']:,} | {r['success_rate']:.0%} | "
              f"{r['episode_return']:.1f} | {r['final_distance']:.2f} |" for r in rows]
    (out / "results.md").write_text("\n".join(lines) + "\n")
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    x = [r[names[0]] for r in rows]
    y = [r[names[1]] for r in rows] if len(names) > 1 else [0] * len(rows)
    shown = ax.scatter(x, y, c=[r[metric] for r in rows], s=[30 + 60 * (r["steps"] > 0) for r in rows], cmap="viridis")
    if all(isinstance(v, (int, float)) and v > 0 for v in x) and max(x) / min(x) > 10:
        ax.set_xscale("log")
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1] if len(names) > 1 else "")
    fig.colorbar(shown, label=metric)
    fig.savefig(out / "sweep.png", dpi=110)
    plt.close(fig)
    return [out / "results.md", out / "results.csv", out / "sweep.png"]
