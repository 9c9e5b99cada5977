"""Whether a compiled program kept with JAX's `serialize_executable` runs in another process
(docs/RESULTS.md, "A warm start without tracing"), as hexa_mjx.training.program_store keeps them.

    python scripts/serialized_program_check.py save   # compile the environments' reset, keep it, run it
    python scripts/serialized_program_check.py load   # a new process: load the kept program, run it
    python scripts/serialized_program_check.py load --lapack   # the same, LAPACK's kernels set up first
    python scripts/serialized_program_check.py tiny-save; python scripts/serialized_program_check.py tiny-load
    python scripts/serialized_program_check.py same   # keep the reset and load it again in one process

Each mode prints the sum of the observations (or of the tiny program's output) it computed. MJX's
solver calls LAPACK (a Cholesky factorization); jaxlib sets LAPACK's kernels up when it lowers such
an operation, which a process that only loads a program never does.
"""

import pickle
import sys
from pathlib import Path

import numpy as np

from hexa_mjx.training.jax_setup import prepare_jax

prepare_jax(compile_cache=False)  # a fresh compile: nothing comes from XLA's cache

import jax  # noqa: E402
import jax.numpy as jp  # noqa: E402
from jax.experimental import serialize_executable  # noqa: E402

KEPT = Path("/tmp/serialized_program_check.bin")
if "--lapack" in sys.argv:
    from jax._src.lib import lapack

    lapack._lapack.initialize()


def program(tiny: bool):
    """(pmapped function, its inputs): the training environments' reset over the CPU devices, or a
    few matrix operations."""
    devices = jax.local_device_count()
    if tiny:
        def f(x):
            return jp.sin(x) @ jp.cos(x) + jp.tanh(x).sum()
        return jax.pmap(f), (jp.ones((devices, 64, 64)),)
    from brax import envs

    from hexa_mjx.training.config import TrainConfig, make_env_for

    env = envs.training.wrap(make_env_for(TrainConfig(num_envs=8)), episode_length=1000, action_repeat=1)
    keys = jax.random.split(jax.random.PRNGKey(0), 8)
    return jax.pmap(env.reset), (keys.reshape((devices, -1) + keys.shape[1:]),)


def total(out) -> float:
    return float(np.asarray(getattr(out, "obs", out)).sum())


MODES = ("save", "load", "tiny-save", "tiny-load", "same")


def main(mode: str) -> None:
    if mode not in MODES:
        sys.exit(f"mode {mode!r}: choose one of {', '.join(MODES)}")
    fn, args = program(tiny=mode.startswith("tiny"))
    if mode in ("save", "tiny-save", "same"):
        compiled = fn.lower(*args).compile()
        data, _, out_tree = serialize_executable.serialize(compiled)
        KEPT.write_bytes(pickle.dumps((data, out_tree)))
        print(f"{mode}: kept {len(data):,} bytes; computed {total(compiled(*args)):.5f}", flush=True)
    if mode in ("load", "tiny-load", "same"):
        data, out_tree = pickle.loads(KEPT.read_bytes())
        loaded = serialize_executable.deserialize_and_load(data, jax.tree.structure((args, {})), out_tree)
        print(f"{mode}: loaded; running it", flush=True)
        print(f"{mode}: computed {total(loaded(*args)):.5f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "save")
