"""Compiled programs kept on disk and loaded without tracing: a warm start in seconds.

XLA's persistent cache (`jax_setup.prepare_jax`) skips XLA's compile, but JAX must still trace
and lower a program before it can look it up: on a 2-core CPU about 3 s for the environments'
reset, 6 s for the training update and 17 s for a run's evaluation (docs/RESULTS.md, "A warm start
without tracing"). `compiled(...)` keeps the compiled executable itself (JAX's
`serialize_executable`), under a key made of what the program depends on besides its inputs'
values:
- the caller's description of its closures (a run's config, PPO's settings);
- the inputs' tree structure, shapes and dtypes;
- hexa_mjx's own sources and models (every file of the package and of models/), the versions of
  Python, JAX, jaxlib, brax, MuJoCo, MJX, flax and optax, JAX's settings, XLA_FLAGS and the devices
  (the folder, beside XLA's cache, is already per CPU and JAX version).
A change to any of them makes a new key, so a stale program is never loaded. A dependency changed
in place without a new version is not seen: remove the folder then (`store_dir()`).

Two things jaxlib 0.9.2 needs (scripts/serialized_program_check.py shows both): a process that
loads a program it did not trace must set up the LAPACK kernels the program calls (tracing does
that as a side effect), and a program is kept only when compiled afresh: one that XLA's cache
loaded serializes into one that fails when run. So a run whose programs XLA's cache already holds
(another seed of the same config, say) loads them from there, traced, and keeps nothing.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import pickle
import platform
import sys
import threading
from importlib import metadata
from pathlib import Path

import jax

from hexa_mjx import atomic

KEEP = 24  # programs kept, the most recently used first (a training update is about 7 MB)
PACKAGES = ("jax", "jaxlib", "brax", "mujoco", "mujoco-mjx", "flax", "optax")
_NOT_PROGRAM = ("jax_compilation_cache", "jax_persistent_cache", "jax_log", "jax_explain", "jax_traceback",
                "jax_enable_compilation_cache", "jax_raise_persistent_cache")  # settings no program depends on
_hits = threading.local()  # XLA cache hits seen by each thread's compiles


@functools.cache
def code_fingerprint() -> str:
    """A hash of hexa_mjx's sources and models and of the versions of what it runs on."""
    package = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted([*package.rglob("*.py"), *(package.parent / "models").rglob("*")]):
        if path.is_file():
            digest.update(str(path.relative_to(package.parent)).encode())
            digest.update(path.read_bytes())
    versions = {name: _version(name) for name in PACKAGES}
    digest.update(json.dumps([versions, sys.version, platform.machine(), os.environ.get("XLA_FLAGS", "")]).encode())
    return digest.hexdigest()


def _version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "none"


def program_key(name: str, describe, args) -> str:
    """The key of program `name`, whose closures `describe` (JSON-able) describes, for `args`."""
    leaves, tree = jax.tree.flatten(args)
    # The structure's static data (MJX keeps numpy arrays there) printed shows object addresses;
    # pickled it shows contents. One round trip first: a structure read back from a kept
    # program's outputs pickles differently from a traced one, and the same after that.
    structure = hashlib.sha256(pickle.dumps(pickle.loads(pickle.dumps(tree)))).hexdigest()
    shapes = [(tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False))) for x in leaves]
    devices = [(d.platform, d.device_kind, d.id) for d in jax.devices()]
    settings = sorted((k, str(v)) for k, v in jax.config.values.items() if not k.startswith(_NOT_PROGRAM))
    text = json.dumps([name, describe, structure, shapes, devices, jax.process_count(), settings, code_fingerprint()],
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def store_dir() -> Path | None:
    """The folder programs are kept in: beside XLA's cache, None when that cache is off."""
    if not jax.config.jax_enable_compilation_cache or not jax.config.jax_compilation_cache_dir:
        return None
    return Path(jax.config.jax_compilation_cache_dir) / "programs"


def compiled(fn, args: tuple, name: str, describe) -> jax.stages.Compiled:
    """`fn` (jitted or pmapped) compiled for `args`: loaded from the store when it holds this
    program, else compiled and kept. Without a description (`describe` None) or a store (the
    compile cache off, or a multi-process run, whose executables name other processes' devices)
    it is `fn.lower(*args).compile()`."""
    return prepare(fn, args, name, describe).result()


class Pending:
    """A program `prepare` traced and lowered (or loaded): its outputs' shapes at once
    (`out_info`); XLA's compile on a worker thread from `begin()`; the compiled program from
    `result()`."""

    def __init__(self, out_info, program=None, work=None):
        self.out_info, self._program, self._work, self._error, self._worker = out_info, program, work, None, None

    def begin(self) -> "Pending":
        """Start XLA's compile on a worker thread (a daemon: a stop need not wait for it)."""
        if self._work is not None and self._worker is None:
            self._worker = threading.Thread(target=self._run, daemon=True)
            self._worker.start()
        return self

    def _run(self) -> None:
        try:
            self._program = self._work()
        except Exception as e:  # noqa: BLE001 - raised again by result(), on the caller's thread
            self._error = e

    def result(self) -> jax.stages.Compiled:
        """The compiled program, waiting for it in short joins: XLA's compile holds the thread
        that runs it for up to a minute, and Python answers a signal (train.py's SIGTERM) only
        between its own bytecodes."""
        self.begin()
        while self._worker is not None and self._worker.is_alive():
            self._worker.join(0.1)
        if self._error is not None:
            raise self._error
        return self._program


def prepare(fn, args: tuple, name: str, describe) -> Pending:
    """`compiled(fn, args, name, describe)` in two steps: traced and lowered now, on this thread
    (or loaded from the store), and compiled on a worker thread from `Pending.begin()`, so that
    this thread can trace the next program meanwhile. `args` may be `jax.ShapeDtypeStruct`s:
    shapes are all a program depends on. (JAX compiles one program at a time: an operation run
    eagerly while a compile is under way waits for it.)"""
    folder = store_dir() if jax.process_count() == 1 and describe is not None else None
    path = None
    if folder is not None:
        try:
            path = folder / f"{name}-{program_key(name, describe, args)}.bin"
        except (pickle.PicklingError, TypeError, AttributeError):  # a structure that cannot be keyed: not kept
            path = None
    if path is not None and path.exists():
        loaded = _load(path, args)
        if loaded is not None:
            return Pending(loaded[1], program=loaded[0])
    lowered = fn.lower(*args)
    shapes = out_shapes(lowered)
    return Pending(shapes, work=lambda: _compile(lowered, path, shapes))


def out_shapes(lowered: jax.stages.Lowered):
    """A lowered program's outputs as `jax.ShapeDtypeStruct`s (strongly typed, no sharding)."""
    try:
        avals = [(a.shape, a.dtype) for a in jax.tree.leaves(lowered.out_info)]
    except KeyError:  # jax 0.9's classic pmap keeps its outputs' shapes per device only
        shards = lowered._lowering.compile_args["shards"]
        avals = [((shards.num_local_shards,) + a.shape[1:], a.dtype) for a in shards.out_sharded_avals]
    return lowered.out_tree.unflatten([jax.ShapeDtypeStruct(shape, dtype) for shape, dtype in avals])


def _load(path: Path, args: tuple):
    """(program, its outputs' shapes) kept at `path`, or None (said on the console) when it cannot
    be loaded."""
    from jax.experimental import serialize_executable

    try:
        data, out_tree, shapes = pickle.loads(path.read_bytes())
        _prepare_kernels()
        program = serialize_executable.deserialize_and_load(data, jax.tree.structure((args, {})), out_tree)
        path.touch()  # most recently used
        return program, out_tree.unflatten([jax.ShapeDtypeStruct(shape, dtype) for shape, dtype in shapes])
    except Exception as e:  # noqa: BLE001 - a damaged or foreign file: compile instead
        print(f"could not load the kept program {path.name} ({type(e).__name__}); compiling it again")
        return None


def _compile(lowered, path: Path | None, shapes) -> jax.stages.Compiled:
    """`lowered` compiled, and kept at `path` (None: not kept) with its outputs' `shapes` when XLA
    compiled it afresh."""
    from jax.experimental import serialize_executable

    if path is None:
        return lowered.compile()
    _listen_for_cache_hits()
    hits = getattr(_hits, "count", 0)
    program = lowered.compile()
    if getattr(_hits, "count", 0) > hits:  # loaded from XLA's cache: it would serialize broken
        return program
    try:
        data, _, out_tree = serialize_executable.serialize(program)
    except (ValueError, NotImplementedError):  # a program JAX cannot serialize: it compiles every run
        return program
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write(path, pickle.dumps((data, out_tree, [(x.shape, str(x.dtype)) for x in jax.tree.leaves(shapes)])))
    for old in sorted(path.parent.glob("*.bin"), key=lambda p: p.stat().st_mtime, reverse=True)[KEEP:]:
        old.unlink(missing_ok=True)
    return program


def _prepare_kernels() -> None:
    """Set up jaxlib's LAPACK kernels (MJX's solver calls them), as lowering a linear-algebra
    operation would: a loaded program that calls them crashes otherwise."""
    from jax._src.lib import lapack

    lapack._lapack.initialize()


def _count_cache_hits(event: str, **_) -> None:
    if event == "/jax/compilation_cache/cache_hits":  # recorded on the thread that compiles
        _hits.count = getattr(_hits, "count", 0) + 1


@functools.cache
def _listen_for_cache_hits() -> None:
    jax.monitoring.register_event_listener(_count_cache_hits)
