"""hexa_mjx.training.program_store: a kept program loads in a new process without tracing, computes
what the traced one computes, and a change to what it depends on makes a new one."""

import json
import subprocess
import sys
import textwrap

import pytest

# A pmapped program that calls LAPACK (MJX's solver does; a loaded program needs its kernels set
# up) and counts how often its Python body is traced.
PROGRAM = textwrap.dedent("""
    import sys
    from hexa_mjx.training.jax_setup import prepare_jax
    prepare_jax(cpu_devices=2)
    import jax, jax.numpy as jp, numpy as np
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    from hexa_mjx.training import program_store

    traced = []

    def f(x):
        traced.append(1)
        return jp.linalg.cholesky(x @ jp.swapaxes(x, -1, -2) + 4.0 * jp.eye(x.shape[-1])).sum()

    x = jp.arange(2 * 8 * 8, dtype=jp.float32).reshape(2, 8, 8) / 100.0
    pending = program_store.prepare(jax.pmap(f), (x,), "test", {"size": 8, "tag": sys.argv[2]})
    program = pending.begin().result()
    out = program(x)
    print(f"shapes as run: {(pending.out_info.shape, pending.out_info.dtype) == (out.shape, out.dtype)}")
    a = np.asarray(x, dtype=np.float64)
    direct = np.linalg.cholesky(a @ np.swapaxes(a, -1, -2) + 4.0 * np.eye(8)).sum(axis=(1, 2))  # NumPy's, in float64
    print(f"traced {len(traced)} result {np.asarray(program(x)).tolist()} direct {direct.tolist()}")
""")


def run(folder, tag="a"):
    out = subprocess.run([sys.executable, "-c", PROGRAM, str(folder), tag], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    line = [s for s in out.stdout.splitlines() if s.startswith("traced")][-1]
    traced, rest = line.split(" result ")
    result, direct = (json.loads(part) for part in rest.split(" direct "))
    return int(traced.split()[1]), result, direct, out.stdout


@pytest.fixture(scope="module")
def kept(tmp_path_factory):
    folder = tmp_path_factory.mktemp("xla")
    return folder, run(folder)


def test_a_kept_program_loads_in_a_new_process_without_tracing(kept):
    folder, (traced_first, result_first, direct_first, _) = kept
    assert traced_first == 1
    assert result_first == pytest.approx(direct_first, rel=1e-5)
    assert len(list((folder / "programs").glob("test-*.bin"))) == 1
    traced, result, _, _ = run(folder)
    assert traced == 0  # loaded, not traced
    assert result == result_first  # to the bit


def test_what_the_program_depends_on_makes_a_new_one(kept):
    folder, _ = kept
    traced, result, direct, _ = run(folder, tag="b")
    assert traced == 1 and result == pytest.approx(direct, rel=1e-5)
    assert len(list((folder / "programs").glob("test-*.bin"))) == 2


def test_a_damaged_program_is_compiled_again(tmp_path):
    run(tmp_path)
    (path,) = (tmp_path / "programs").glob("test-*.bin")
    path.write_bytes(b"not a program")
    traced, result, direct, stdout = run(tmp_path)
    assert "could not load the kept program" in stdout
    assert traced == 1 and result == pytest.approx(direct, rel=1e-5)


# Training traces its update from the shapes the reset will return, while the reset compiles.
ABSTRACT = textwrap.dedent("""
    from hexa_mjx.training.jax_setup import prepare_jax
    prepare_jax(cpu_devices=2, compile_cache=False)
    import jax, jax.numpy as jp
    from hexa_mjx.training import program_store
    from hexa_mjx.training.ppo import strong_types

    def reset(key):  # several leaves, one of them weakly typed, as an environment state has
        return {"obs": jax.random.normal(key, (4, 3)), "done": 0.0 * jp.sum(key), "steps": jp.zeros(4, jp.int32)}

    def step(state, scale):
        return {"obs": state["obs"] * scale, "done": state["done"] + 1.0, "steps": state["steps"] + 1}

    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    pending = program_store.prepare(jax.pmap(reset), (keys,), "reset", None)
    state = pending.result()(keys)
    shapes = [(x.shape, x.dtype) for x in jax.tree.leaves(pending.out_info)]
    print("shapes", shapes == [(x.shape, x.dtype) for x in jax.tree.leaves(state)])
    scale = jp.ones(2)
    state = strong_types(state)  # as training holds it
    text = jax.pmap(step).lower(pending.out_info, scale).as_text()
    print("program", text == jax.pmap(step).lower(state, scale).as_text())
""")


def test_a_program_traced_from_the_shapes_a_program_returns_is_the_same_program():
    out = subprocess.run([sys.executable, "-c", ABSTRACT], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "shapes True" in out.stdout and "program True" in out.stdout, out.stdout
