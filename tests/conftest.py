"""Session fixtures: every jitted function is compiled once for the whole suite."""

import os

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
