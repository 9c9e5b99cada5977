"""Crashes at chosen moments (a real SIGKILL through hexa_mjx.training.crash_points), each resumed: every
evaluation row exactly once, every checkpoint readable, no temporary folder left, and Adam's state
carried across (the last resume runs on 2 processes: process 0 reads and shares it)."""

import dataclasses
import json
import shutil
import signal
import socket

import jax
import numpy as np
import optax
import pytest

from hexa_mjx.training import checkpoints, config, crash_points as faults, networks, optimizer_state
from hexa_mjx.training.progress import TIMING_FIELDS

from conftest import NOISE, TINY, run
from test_scale_out import free_port, process_flags, rows as metric_rows, train_processes

# The shared tiny run's settings (8 envs, 64 env steps and 10 epochs x 2 minibatches per update),
# with an evaluation and a checkpoint every 64 steps.
SETTINGS = [*TINY, *NOISE, "--seed", "3", "--num_timesteps", "256", "--num_evals", "5"]
ADAM_STEPS_PER_UPDATE = 10 * 2


def rows(run_dir):
    return [row["step"] for row in metric_rows(run_dir)]


def killed_at(point, run_dir, cache_env, resume=True):
    proc = run("train.py", *SETTINGS, "--run_dir", str(run_dir), *(["--resume"] if resume else []),
               env={**cache_env, faults.VARIABLE: point}, check=False)
    assert proc.returncode == -signal.SIGKILL, (proc.returncode, proc.stdout, proc.stderr)
    return proc


def test_kills_at_chosen_moments_resume_with_every_row_once(tmp_path, cache_env):
    run_dir = tmp_path / "run"
    killed_at("training-started", run_dir, cache_env, resume=False)  # after step 0's row
    assert rows(run_dir) == [0] and not checkpoints.list_checkpoints(run_dir)

    proc = killed_at("row-written", run_dir, cache_env)  # row 64 written, its checkpoint not
    assert "no complete checkpoint yet" in proc.stdout and "starting again from step 0" in proc.stdout
    assert rows(run_dir) == [0, 64] and not checkpoints.list_checkpoints(run_dir)

    killed_at("checkpoint-writing@2", run_dir, cache_env)  # checkpoint 64 done, 128 half-written
    assert rows(run_dir) == [0, 64, 128]
    assert [s for s, _ in checkpoints.list_checkpoints(run_dir)] == [64]
    assert list((run_dir / "checkpoints").glob("tmp-*"))

    results = train_processes([[*SETTINGS, "--run_dir", str(run_dir), "--resume", "--cpu_devices", "1", *flags]
                               for flags in process_flags(free_port())], cache_env)
    assert [r[0] for r in results] == [0, 0], results
    out = results[0][1]
    assert "removed half-written" in out and "from step 64" in out and "x 2 processes" in out, out
    # Step 64's row was logged before the crash; the compile lines are printed all the same.
    assert "evaluation compiled and run in" in out and "training compiled and its first update" in out, out
    assert "process 1 done" in results[1][1]
    assert rows(run_dir) == [0, 64, 128, 192, 256]  # each evaluation exactly once
    assert [s for s, _ in checkpoints.list_checkpoints(run_dir)] == [64, 128, 192, 256]
    assert not list((run_dir / "checkpoints").glob("tmp-*"))
    cfg = config.load_config(run_dir)
    template = networks.init_params(cfg, config.make_env_for(cfg))
    for step, path in checkpoints.list_checkpoints(run_dir):
        assert checkpoints.load_checkpoint(path, template)[0] == step
        adam = checkpoints.load_optimizer(path, optimizer_state.adam_template(template))
        # Adam's step count goes on from the checkpoint it resumed: a fresh Adam would restart it.
        assert int(adam[0].count) == step // 64 * ADAM_STEPS_PER_UPDATE


def test_a_restored_adam_continues_as_the_uninterrupted_one():
    """PPO's optimizer (Adam after gradient clipping), restored mid-run from the Adam state a
    checkpoint keeps (`optimizer_state.adam_of`, as host arrays), takes the same steps as an uninterrupted one."""
    grad = lambda p, i: jax.tree.map(lambda x: jax.numpy.sin(x * (i + 1)), p)  # noqa: E731
    params = {"w": jax.numpy.arange(6.0).reshape(2, 3), "b": jax.numpy.ones(3)}
    opt = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(learning_rate=0.1))
    update = jax.jit(opt.update)

    def run_adam(p, state, start, stop):
        for i in range(start, stop):
            updates, state = update(grad(p, i), state)
            p = optax.apply_updates(p, updates)
        return p, state

    whole, _ = run_adam(params, opt.init(params), 0, 8)
    half, state = run_adam(params, opt.init(params), 0, 4)
    saved = jax.tree.map(np.asarray, optimizer_state.adam_of(state))
    assert int(saved[0].count) == 4
    resumed, _ = run_adam(half, optimizer_state.with_adam(opt.init(half), saved), 4, 8)
    jax.tree.map(np.testing.assert_array_equal, resumed, whole)
    fresh, _ = run_adam(half, opt.init(half), 4, 8)  # Adam started afresh on resume
    assert not np.allclose(fresh["w"], whole["w"])


# Three updates per evaluation interval, so that a stop can come between evaluations.
EXACT = ["--num_envs", "8", "--batch_size", "8", "--num_minibatches", "2", "--unroll_length", "4", "--num_evals", "3",
         "--num_eval_envs", "2", "--episode_length", "20", *NOISE, "--seed", "5", "--num_timesteps", "384"]


def comparable(run_dir):
    """metrics.jsonl rows without their clock figures."""
    return [{k: v for k, v in row.items() if k not in TIMING_FIELDS} for row in metric_rows(run_dir)]


def assert_same_run(stopped, whole):
    """The resumed run's rows (but for their clock figures) and final params equal the uninterrupted
    run's, bit for bit."""
    assert comparable(stopped) == comparable(whole)  # every row, bit for bit
    cfg = config.load_config(whole)
    template = networks.init_params(cfg, config.make_env_for(cfg))
    (_, a), (_, b) = (checkpoints.load_checkpoint(checkpoints.list_checkpoints(r)[-1][1], template)
                      for r in (whole, stopped))
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(x, y)  # the final params, bit for bit


def test_kills_and_sigterms_resume_bit_for_bit(tmp_path, cache_env):
    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    run("train.py", *EXACT, "--run_dir", str(whole), env=cache_env)

    proc = run("train.py", *EXACT, "--run_dir", str(stopped), env={**cache_env, faults.VARIABLE: "update-done@2:TERM"},
               check=False)  # SIGTERM between two evaluations: a checkpoint there
    assert proc.returncode == 143 and "--resume" in proc.stderr, (proc.returncode, proc.stderr)
    assert [s for s, _ in checkpoints.list_checkpoints(stopped)] == [128]
    proc = run("train.py", *EXACT, "--run_dir", str(stopped), "--resume",
               env={**cache_env, faults.VARIABLE: "row-written@1"}, check=False)  # SIGKILL: the row, no checkpoint
    assert proc.returncode == -signal.SIGKILL and "exactly" in proc.stdout, proc.stdout
    proc = run("train.py", *EXACT, "--run_dir", str(stopped), "--resume", env=cache_env)
    assert "from step 128: exactly" in proc.stdout, proc.stdout

    assert_same_run(stopped, whole)


def test_a_longer_run_stopped_between_evaluations_resumes_bit_for_bit(tmp_path, cache_env):
    """A run continued with a longer schedule (`--resume --num_timesteps`) counts that schedule
    from where it resumed; stopped between two of its evaluations and resumed again, it goes on
    exactly, with the rows, checkpoint steps and final params of the same continuation never stopped."""

    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    run("train.py", *EXACT, "--run_dir", str(whole), env=cache_env)  # 384 steps
    shutil.copytree(whole, stopped)
    longer = ["--resume", "--num_timesteps", "768"]
    proc = run("train.py", *EXACT, "--run_dir", str(whole), *longer, env=cache_env)
    assert "from step 384, not exactly" in proc.stdout, proc.stdout

    proc = run("train.py", *EXACT, "--run_dir", str(stopped), *longer,
               env={**cache_env, faults.VARIABLE: "update-done@2:TERM"}, check=False)  # 2 updates past 384
    assert proc.returncode == 143, (proc.returncode, proc.stderr)
    assert [s for s, _ in checkpoints.list_checkpoints(stopped)][-1] == 512
    proc = run("train.py", *EXACT, "--run_dir", str(stopped), *longer, env=cache_env)
    assert "from step 512: exactly" in proc.stdout, proc.stdout

    assert_same_run(stopped, whole)
    assert checkpoints.list_checkpoints(stopped)[-1][0] == checkpoints.list_checkpoints(whole)[-1][0] == 768


def test_two_processes_wait_for_a_slow_evaluation_and_resume_bit_for_bit(tmp_path, cache_env):
    """Process 0's step-192 evaluation made 40 s slow, longer than the 30 s a collective's transport
    waits: the other process waits at a barrier instead. A SIGTERM to process 0 alone stops both at
    the same update with one checkpoint of both processes' positions; the resume continues exactly."""
    whole, stopped = tmp_path / "whole", tmp_path / "stopped"

    def both(run_dir, point=None, *extra):
        env = {**cache_env, **({faults.VARIABLE: point} if point else {})}
        return train_processes([[*EXACT, "--run_dir", str(run_dir), "--cpu_devices", "1", *extra, *flags]
                                for flags in process_flags(free_port())], env)

    results = both(whole, "evaluated@2:SLEEP40")  # the second evaluation: step 192
    assert [r[0] for r in results] == [0, 0], results
    results = both(stopped, "update-done@2:TERM")  # SIGTERM to process 0 only (it alone reports progress)
    assert [r[0] for r in results] == [143, 143], results
    assert [s for s, _ in checkpoints.list_checkpoints(stopped)] == [128]
    results = both(stopped, None, "--resume")
    assert [r[0] for r in results] == [0, 0], results
    assert "from step 128: exactly" in results[0][1], results[0][1]

    assert_same_run(stopped, whole)


def test_a_stop_before_the_first_update_is_at_once(tmp_path, cache_env):
    """SIGTERM as the training programs start compiling: nothing to save, so no wait for the compile."""
    run_dir = tmp_path / "run"
    proc = run("train.py", *SETTINGS, "--run_dir", str(run_dir), env={**cache_env, faults.VARIABLE: "compiling:TERM"},
               check=False)
    assert proc.returncode == 143, (proc.returncode, proc.stderr)
    assert "SIGTERM: stopped before the first update, with nothing new to save; it has no checkpoint yet" in proc.stderr
    assert "training compiled" not in proc.stdout and not checkpoints.list_checkpoints(run_dir)


def test_a_second_writer_is_refused_and_a_stale_lock_taken_over(tmp_path, cache_env, capsys):
    import os
    import subprocess
    import time

    from hexa_mjx.training.run_lock import RunLock, RunLocked

    run_dir = tmp_path / "run"
    holder = subprocess.Popen(["sleep", "60"])
    try:
        cfg = config.validate(config.parse_args([*EXACT, "--run_dir", str(run_dir)]))
        (run_dir / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))  # a run that trains now
        (run_dir / ".lock").write_text(json.dumps({"pid": holder.pid, "host": socket.gethostname(), "since": "now"}))
        start = time.time()
        proc = run("train.py", *EXACT, "--run_dir", str(run_dir), "--resume", env=cache_env, check=False)
        assert proc.returncode == 2 and f"process {holder.pid} on {socket.gethostname()}" in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stderr and time.time() - start < 60
        with pytest.raises(RunLocked, match="stop it first"):
            RunLock(run_dir).acquire()
    finally:
        holder.kill()
        holder.wait()
    with RunLock(run_dir):  # its process is gone: the lock is stale and taken over
        assert json.loads((run_dir / ".lock").read_text())["pid"] == os.getpid()
    assert "no longer runs: taking the run over" in capsys.readouterr().out
    assert not (run_dir / ".lock").exists()  # released on the way out


def test_a_full_disk_stops_the_run_with_one_line(tmp_path, cache_env):
    run_dir = tmp_path / "run"
    proc = run("train.py", *EXACT, "--run_dir", str(run_dir), env={**cache_env, faults.VARIABLE: "checkpoint-writing:ENOSPC"},
               check=False)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "could not write checkpoint" in proc.stderr and "No space left on device" in proc.stderr
    assert not checkpoints.list_checkpoints(run_dir) and not list((run_dir / "checkpoints").glob("tmp-*"))
