"""How JAX is set up for training on this machine: CPU devices, pmap flavour, compilation cache.

Every entry point (train.py, eval.py, the benchmark, experiments) calls `prepare_jax` before
anything else touches JAX.
"""

from __future__ import annotations

import hashlib
import os
import platform
from pathlib import Path

import jax


def compile_cache_dir() -> Path:
    """Per-user folder for XLA's persistent compilation cache, keyed by CPU and JAX version.

    Executables compiled for one CPU's instruction set must not be loaded on another, so the
    folder name hashes the CPU model and feature flags (/proc/cpuinfo) with the jax version.
    """
    cpu = platform.processor() + platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("model name", "flags", "Features", "CPU part")):
                cpu += line
                if line.startswith(("flags", "Features")):
                    break
    except OSError:
        pass
    key = hashlib.sha1(f"{cpu}|jax {jax.__version__}".encode()).hexdigest()[:12]
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return root / "hexa_mjx" / f"xla-{key}"


def prepare_jax(cpu_devices: int = 0, compile_cache: bool = True) -> None:
    """Set JAX up for brax's PPO: call before anything else touches JAX.

    Asks XLA for `cpu_devices` CPU devices (0: one per core; too late once JAX has started): XLA
    runs one vmapped MJX step on about one core, so one device leaves the other cores idle, and
    brax's PPO splits environments and minibatches over devices with pmap instead. Also selects
    the classic pmap: under jax 0.9's shard_map-based one, brax's training epoch compiles a second
    time on its second call (17 s here).

    With `compile_cache`, compiled programs are kept in `compile_cache_dir()` (or the folder
    JAX_COMPILATION_CACHE_DIR names), so a second run with the same shapes skips most compiling.
    jaxlib 0.9.2 logs a long, harmless "Loading XLA:CPU AOT result" error for every executable it
    loads from there; `hexa_mjx` sets TF_CPP_MIN_LOG_LEVEL=3 on import to keep XLA's C++ log off
    the console (set it yourself, e.g. to 0, to see that log).
    """
    from jax._src import xla_bridge

    if not xla_bridge.backends_are_initialized():
        jax.config.update("jax_num_cpu_devices", cpu_devices or len(os.sched_getaffinity(0)))
    try:
        jax.config.update("jax_pmap_shmap_merge", False)
    except AttributeError:  # jax >= 0.10 has only the shard_map-based pmap (a GPU image's jax, say)
        pass
    if compile_cache:
        folder = os.environ.get("JAX_COMPILATION_CACHE_DIR") or str(compile_cache_dir())
        jax.config.update("jax_compilation_cache_dir", folder)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    else:
        jax.config.update("jax_enable_compilation_cache", False)


def devices_for(cfg) -> int:
    """Devices PPO runs on: every accelerator, or on the CPU cfg.cpu_devices (0: the most that divide
    num_envs and batch_size, up to the CPU devices JAX has)."""
    if jax.default_backend() != "cpu":
        return jax.local_device_count()
    if cfg.cpu_devices:
        return cfg.cpu_devices
    return dividing_devices(cfg, jax.local_device_count())


def dividing_devices(cfg, available: int) -> int:
    """The most devices, up to `available`, that divide both num_envs and batch_size."""
    return max(d for d in range(1, available + 1) if cfg.num_envs % d == 0 and cfg.batch_size % d == 0)
