"""Session fixtures: every jitted function is compiled once for the whole suite, and one tiny
training run (`trained`) serves every test that needs a run directory."""

import os
import subprocess
import sys
from pathlib import Path

import jax
import pytest

import hexa_mjx


@pytest.fixture(scope="session")
def env():
    return hexa_mjx.make_env()


@pytest.fixture(scope="session")
def step(env):
    return jax.jit(env.step)


@pytest.fixture(scope="session")
def state0(env):
    return jax.jit(env.reset)(jax.random.PRNGKey(0))


@pytest.fixture(scope="session")
def nav_env():
    return hexa_mjx.make_env(task="navigate")


@pytest.fixture(scope="session")
def nav_step(nav_env):
    return jax.jit(nav_env.step)


@pytest.fixture(scope="session")
def nav_reset(nav_env):
    return jax.jit(jax.vmap(nav_env.reset))


@pytest.fixture(scope="session")
def cache_env(tmp_path_factory):
    """Subprocess environment sharing one fresh XLA compilation cache (later runs reuse compiles)."""
    return {**os.environ, "JAX_COMPILATION_CACHE_DIR": str(tmp_path_factory.mktemp("xla_cache"))}


ROOT = Path(__file__).resolve().parent.parent
# A tiny rollout shape: 8 envs x 4 steps x 2 minibatches = 64 env steps per update.
TINY = ["--num_envs", "8", "--batch_size", "8", "--num_minibatches", "2", "--unroll_length", "4",
        "--num_evals", "2", "--num_eval_envs", "2", "--episode_length", "20"]
# The trained fixture draws start noise per episode (hexa_mjx.engines.wrappers instead of brax's auto-reset),
# and trains on randomized physics with pushes: the whole path of those through brax's PPO.
NOISE = ["--start_joint_noise", "0.05", "--start_yaw_noise", "0.1", "--randomize",
         "--push_speed", "0.3", "--push_interval", "0.1"]


def run(script, *args, env=None, check=True):
    """A repository script in a subprocess; AssertionError with its output if it fails (check)."""
    proc = subprocess.run([sys.executable, str(ROOT / script), *args], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=900)
    if check and proc.returncode != 0:
        raise AssertionError(f"{script} {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return proc


@pytest.fixture(scope="session")
def trained(tmp_path_factory, cache_env):
    """train.py's tiny run (64 steps, seed 3): (run dir, its process, whose stderr logs each compile)."""
    run_dir = tmp_path_factory.mktemp("runs") / "tiny"
    proc = run("train.py", *TINY, *NOISE, "--num_timesteps", "64", "--seed", "3", "--run_dir", str(run_dir),
               env={**cache_env, "JAX_LOG_COMPILES": "1"})
    return run_dir, proc
