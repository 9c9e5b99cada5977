"""Multi-process training (jax.distributed, 2 local processes) and study grids and sweeps on Ray."""

import dataclasses
import json
import os
import socket
import subprocess
import sys
import time

import pytest

from hexa_mjx.training import config, distributed, jax_setup
from hexa_mjx.training.progress import TIMING_FIELDS
from hexa_mjx.studies import experiments, ray_runs

from conftest import ROOT

# 8 envs split over 2 processes of 1 CPU device each; 64 env steps per update; tiny networks.
TINY = ["--num_envs", "8", "--batch_size", "8", "--num_minibatches", "2", "--unroll_length", "4",
        "--num_evals", "2", "--num_eval_envs", "2", "--episode_length", "20", "--hidden", "16", "16",
        "--update_epochs", "1", "--cpu_devices", "1"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("", 0))
        return s.getsockname()[1]


def train_processes(args_per_process, env, timeout=600):
    """Start one train.py per argument list; returns their (returncode, stdout, stderr)."""
    procs = [subprocess.Popen([sys.executable, str(ROOT / "train.py"), *args], cwd=ROOT, env=env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE) for args in args_per_process]
    outputs = [p.communicate(timeout=timeout) for p in procs]
    return [(p.returncode, *out) for p, out in zip(procs, outputs)]


def process_flags(port, n=2):
    return [["--coordinator", f"localhost:{port}", "--num_processes", str(n), "--process_id", str(i),
             "--coordinator_timeout", "60"] for i in range(n)]


def rows(run_dir):
    return [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]


# Resuming on two processes after real crashes: tests/test_crashes.py.


def test_processes_with_different_settings_stop_together(tmp_path, cache_env):
    args = [[*TINY, "--seed", str(i), "--run_dir", str(tmp_path / "r"), *d]
            for i, d in enumerate(process_flags(free_port()))]
    for code, out, err in train_processes(args, cache_env, timeout=120):
        assert code == 2 and "error: the processes were started with different settings (--seed)" in err, err
    assert not (tmp_path / "r" / "config.json").exists()
    # 3 environments cannot split over 2 processes' devices: every process says so and stops.
    odd = ["--num_envs", "3", "--batch_size", "3", "--num_minibatches", "2"]
    args = [[*TINY, *odd, "--run_dir", str(tmp_path / "r"), *d] for d in process_flags(free_port())]
    for code, out, err in train_processes(args, cache_env, timeout=120):
        assert code == 2 and "2 devices (2 processes) must divide --num_envs (3)" in err, err


def test_a_scheduler_job_is_joined_without_flags(monkeypatch):
    for name in ("SLURM_JOB_ID", "SLURM_NTASKS", "OMPI_COMM_WORLD_SIZE"):
        monkeypatch.delenv(name, raising=False)
    assert distributed.scheduled_tasks() == 1
    monkeypatch.setenv("SLURM_JOB_ID", "42")
    monkeypatch.setenv("SLURM_NTASKS", "4")
    assert distributed.scheduled_tasks() == 4
    monkeypatch.setenv("SLURM_NTASKS", "1")
    assert distributed.scheduled_tasks() == 1  # a one-task job is a plain run


@pytest.mark.parametrize("flags, message", [
    (["--num_processes", "2", "--process_id", "2", "--coordinator", "localhost:1234"], "--process_id must be in 0..1"),
    (["--num_processes", "2", "--process_id", "1"], "needs --coordinator HOST:PORT"),
    (["--num_processes", "2", "--coordinator", "nohost"], "--coordinator must be HOST:PORT"),
    (["--num_processes", "0"], "--num_processes must be at least 1"),
])
def test_bad_process_flags_are_one_line(tmp_path, flags, message):
    proc = subprocess.run([sys.executable, str(ROOT / "train.py"), "--run_dir", str(tmp_path / "r"), *flags],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [f"error: {proc.stderr.split('error: ')[1].strip()}"]
    assert message in proc.stderr and not (tmp_path / "r").exists()


def test_an_unreachable_coordinator_fails_within_its_timeout(tmp_path):
    t0 = time.time()
    proc = subprocess.run([sys.executable, str(ROOT / "train.py"), "--run_dir", str(tmp_path / "r"),
                           "--coordinator", f"localhost:{free_port()}", "--num_processes", "2", "--process_id", "1",
                           "--coordinator_timeout", "2"], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2 and "error: cannot reach the coordinator" in proc.stderr
    assert time.time() - t0 < 30 and not (tmp_path / "r").exists()


# ---------------------------------------------------------------------------
# Ray


@pytest.fixture(scope="module")
def local_ray(cache_env):
    """A local Ray instance whose workers share the suite's compilation cache."""
    import ray

    before = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = cache_env["JAX_COMPILATION_CACHE_DIR"]  # workers inherit it
    ray_runs.start("local")
    yield
    ray.shutdown()
    if before is None:
        os.environ.pop("JAX_COMPILATION_CACHE_DIR")
    else:
        os.environ["JAX_COMPILATION_CACHE_DIR"] = before


def test_a_grid_on_ray_gives_the_sequential_runs_results(trained, tmp_path, local_ray):
    """Seed 3 of the tiny run as a grid on Ray: the `trained` run train.py made, it must give the
    same evaluations; the finished run is then skipped. (One run: each costs ~45 s of tracing.)"""
    run_dir, _ = trained
    settings = {k: v for k, v in dataclasses.asdict(config.load_config(run_dir)).items()
                if k not in ("seed", "run_dir", "lr", "num_envs", "num_timesteps", "resume", "reward", "task")}
    # As many devices as train.py gave the run (one per core, dividing its 8 environments).
    devices = jax_setup.dividing_devices(config.load_config(run_dir), len(os.sched_getaffinity(0)))

    def grid():
        runs = experiments.grid("lr", tmp_path, timesteps=64, seeds=4, num_envs=8, **settings)
        return [run for run in runs if run.condition == "lr_0.0003" and run.seed == 3]

    todo, counts = experiments.plan(grid())
    assert counts == {"done": 0, "reused": 0, "partial": 0, "new": 1}
    ray_runs.run_grid(todo, run_cpus=devices, run_gpus=0)
    drop = lambda row: {k: v for k, v in row.items() if k not in TIMING_FIELDS}  # noqa: E731
    on_ray = tmp_path / "lr" / "lr_0.0003-s3"
    assert [drop(r) for r in rows(on_ray)] == [drop(r) for r in rows(run_dir)]
    assert experiments.plan(grid()) == ([], {"done": 1, "reused": 0, "partial": 0, "new": 0})


def test_sweep_spaces_are_checked_before_ray_starts(tmp_path):
    def space(obj):
        path = tmp_path / "space.json"
        path.write_text(json.dumps(obj))
        return path

    good = ray_runs.load_space(space({"lr": {"loguniform": [1e-4, 1e-3]}, "update_epochs": {"choice": [2, 4]}}))
    assert set(good) == {"lr", "update_epochs"}
    for bad, message in [({"learning_rate": 1e-3}, "unknown flags: learning_rate"),
                         ({"lr": {"loguniform": [1e-3, 1e-4]}}, "low <= high"),
                         ({"lr": {"loguniform": [0, 1e-3]}}, "low > 0"),
                         ({"lr": {"gaussian": [0, 1]}}, "must be a value or one of"),
                         ({"discount": {"choice": [0.9, 1.5]}}, "discount=1.5 is not a valid setting"),
                         ([], "must be a JSON object")]:
        with pytest.raises(ValueError, match=message):
            ray_runs.load_space(space(bad))
    with pytest.raises(ValueError, match="no Ray cluster answers"):
        ray_runs.check_address(f"localhost:{free_port()}", timeout_s=1)


def test_the_best_trial_is_printed_as_a_train_command():
    cfg = config.TrainConfig(lr=0.0005, hidden=[64, 64], update_epochs=4, compile_cache=False, run_dir="runs/x")
    line = ray_runs.command_line(cfg)
    assert line == "python train.py --lr 0.0005 --update_epochs 4 --hidden 64 64 --run_dir runs/x --no_compile_cache"
    assert config.parse_args(line.split()[2:]) == dataclasses.replace(cfg, reward="goal_directed")
    rows_ = [{"steps": 100, "episode_return": 5.0, "success_rate": 0.5}, {"steps": 40, "episode_return": 9.0,
             "success_rate": 1.0}, {"steps": 100, "episode_return": 7.0, "success_rate": 0.5}]
    assert ray_runs.best(rows_, "success_rate", 100) is rows_[2]  # stopped trials never win; ties by return
