"""Multi-process training with JAX's own runtime (`jax.distributed`).

Each process runs train.py with the same flags plus its `--process_id`; PPO (hexa_mjx.training.ppo) splits the
environments over every device of every process, averages gradients across all of them, and
evaluates on process 0 only. Process 0 alone writes the run directory. Under SLURM or Open MPI
JAX finds the coordinator, process count and id itself when the flags are absent.

JAX aborts the whole process (no Python exception) when it cannot reach the coordinator, so the
checks here run first and turn the common mistakes into one `error:` line. For the same reason the
other processes never wait for process 0's solo work (reading the run directory, an evaluation, a
checkpoint) inside a collective, whose transport gives up after 30 s: they wait at a named barrier
of the coordinator (`wait_for_main`) for as long as `--process_wait_timeout` allows.
"""

from __future__ import annotations

import dataclasses
import io
import os
import socket
import time
import zlib

import numpy as np

# Environment variables that mean "this process is one task of a multi-process job" to JAX's
# cluster detection, each with the variable holding the number of tasks.
SCHEDULERS = {"SLURM_JOB_ID": "SLURM_NTASKS", "OMPI_COMM_WORLD_SIZE": "OMPI_COMM_WORLD_SIZE"}


class DistributedError(ValueError):
    """A multi-process setting that cannot work, found before JAX starts."""


def parse_address(address: str) -> tuple[str, int]:
    """(host, port) of "HOST:PORT", or DistributedError."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise DistributedError(f"--coordinator must be HOST:PORT (e.g. node0:12345), got {address!r}")
    return host, int(port)


def scheduled_tasks() -> int:
    """Tasks in the job a scheduler (SLURM, Open MPI) started this process in; 1 outside one."""
    for present, count in SCHEDULERS.items():
        if present in os.environ:
            try:
                return int(os.environ.get(count, "1"))
            except ValueError:
                return 1
    return 1


def check(coordinator: str, num_processes: int, process_id: int, timeout_s: float) -> None:
    """DistributedError for flags that cannot describe a multi-process run."""
    if num_processes < 1:
        raise DistributedError(f"--num_processes must be at least 1, got {num_processes}")
    if not 0 <= process_id < num_processes:
        raise DistributedError(f"--process_id must be in 0..{num_processes - 1} for --num_processes "
                               f"{num_processes}, got {process_id}")
    if not timeout_s > 0:
        raise DistributedError(f"--coordinator_timeout must be positive seconds, got {timeout_s}")
    if num_processes > 1 and not coordinator:
        raise DistributedError("--num_processes above 1 needs --coordinator HOST:PORT (process 0's host and a "
                               "free port)")
    if coordinator:
        parse_address(coordinator)


def wait_for_coordinator(address: str, timeout_s: float) -> None:
    """Return once process 0's coordination service accepts connections, or raise DistributedError
    after `timeout_s` (JAX itself would abort the process with a C++ stack trace)."""
    host, port = parse_address(address)
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with socket.create_connection((host, port), timeout=min(2.0, timeout_s)):
                return
        except OSError as e:
            if time.monotonic() >= deadline:
                raise DistributedError(f"cannot reach the coordinator {address} within {timeout_s:g} s ({e.strerror or e}); "
                                       "start process 0 first, check the host name and port, or raise "
                                       "--coordinator_timeout") from None
            time.sleep(0.25)


def check_port_free(address: str) -> None:
    """Process 0 serves on the coordinator's port: DistributedError if this host cannot bind it."""
    _, port = parse_address(address)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("", port))
        except OSError as e:
            raise DistributedError(f"process 0 cannot serve the coordinator on port {port} ({e.strerror or e}); "
                                   "choose a free port in --coordinator") from None


def initialize(coordinator: str = "", num_processes: int = 1, process_id: int = 0, timeout_s: float = 120.0) -> bool:
    """Join a multi-process run (call before anything else touches JAX's devices). With no flags,
    joins the job a scheduler started, if any. Returns whether this is a multi-process run."""
    import jax

    check(coordinator, num_processes, process_id, timeout_s)
    # Cross-process reductions on CPUs go over gloo (JAX's default here; set so it stays so).
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if num_processes > 1:
        if process_id == 0:
            check_port_free(coordinator)
        else:
            wait_for_coordinator(coordinator, timeout_s)
        print(f"process {process_id} of {num_processes}: joining the coordinator at {coordinator} "
              f"(up to {timeout_s:g} s for all processes to arrive)", flush=True)
        # The coordinator listens on the address named, not on every interface: it has no
        # authentication, so a local run stays on loopback (docs/SCALE_OUT.md, "Security").
        jax.distributed.initialize(coordinator_address=coordinator, num_processes=num_processes,
                                   process_id=process_id, initialization_timeout=int(max(1, timeout_s)),
                                   shutdown_timeout_seconds=int(max(1, timeout_s)),
                                   coordinator_bind_address=coordinator if process_id == 0 else None)
        return True
    if not coordinator and scheduled_tasks() > 1:
        print(f"joining the {scheduled_tasks()}-task job the scheduler started (jax.distributed)", flush=True)
        jax.distributed.initialize(initialization_timeout=int(max(1, timeout_s)),
                                   shutdown_timeout_seconds=int(max(1, timeout_s)))
        return True
    return False


def is_main() -> bool:
    """Whether this process writes the run directory and evaluates (process 0, or the only one)."""
    import jax

    return jax.process_index() == 0


def field_hashes(cfg, local: set[str]) -> np.ndarray:
    """One 31-bit hash per config field (fields in `local` may differ between processes)."""
    values = dataclasses.asdict(cfg)
    return np.array([0 if k in local else zlib.crc32(repr(values[k]).encode()) & 0x7FFFFFFF
                     for k in sorted(values)], np.int64)


def agree(cfg, error: str, local: set[str]) -> str:
    """Compare every process's config and validation outcome; returns the error this process must
    report ('' when all processes hold the same valid config). Every process takes part, so none
    is left waiting for one that quit."""
    import jax
    from jax.experimental import multihost_utils

    if jax.process_count() == 1:
        return error
    mine = np.concatenate([[int(bool(error))], field_hashes(cfg, local)]).astype(np.int32)
    everyone = np.asarray(multihost_utils.process_allgather(mine))
    if error:
        return error
    failed = [p for p in range(len(everyone)) if everyone[p, 0]]
    if failed:
        return f"process {failed[0]} rejected the settings (see its error); fix them for every process"
    names = sorted(dataclasses.asdict(cfg))
    differ = sorted({names[i] for p in range(1, len(everyone)) for i in np.flatnonzero(everyone[p, 1:] != everyone[0, 1:])})
    if differ:
        return (f"the processes were started with different settings ({', '.join('--' + n for n in differ)}); "
                "give every process the same flags except --process_id")
    return ""


def share(tree):
    """Process 0's `tree` on every process (each passes a tree of the same structure and shapes)."""
    import jax
    from jax.experimental import multihost_utils

    if jax.process_count() == 1:
        return tree
    return multihost_utils.broadcast_one_to_all(tree, is_source=is_main())


class WaitedTooLong(RuntimeError):
    """A process waited longer than --process_wait_timeout for process 0's solo work."""


def wait_for_main(what: str, timeout_s: float) -> None:
    """Every process waits here until process 0 has arrived too, after doing `what` alone (its
    evaluation, a checkpoint), for up to `timeout_s`; WaitedTooLong names what it waited for."""
    import jax

    if jax.process_count() == 1:
        return
    from orbax.checkpoint import multihost

    try:
        multihost.get_barrier_sync_fn()(key=f"hexa_mjx: {what}", timeout_ms=int(timeout_s * 1000))
    except Exception as e:  # the coordinator's DEADLINE_EXCEEDED, or a process gone
        raise WaitedTooLong(f"process {jax.process_index()} waited {timeout_s:g} s for process 0's {what} "
                            f"({type(e).__name__}: {str(e).splitlines()[0][:160]}); if process 0 is still "
                            "working, raise --process_wait_timeout") from None


def any_process(flag: bool) -> bool:
    """Whether `flag` is true on any process (every process calls it at the same point)."""
    import jax
    from jax.experimental import multihost_utils

    if jax.process_count() == 1:
        return bool(flag)
    return bool(np.asarray(multihost_utils.process_allgather(np.int32(bool(flag)))).any())


def share_arrays(arrays: dict | None) -> dict | None:
    """Process 0's dict of NumPy arrays (or None) on every process; the others pass anything."""
    import jax

    if jax.process_count() == 1:
        return arrays
    blob = b""
    if is_main() and arrays is not None:
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        blob = buffer.getvalue()
    size = int(share(np.int32(len(blob))))
    if size == 0:
        return None
    data = share(np.frombuffer(blob, np.uint8) if is_main() else np.zeros(size, np.uint8))
    with np.load(io.BytesIO(np.asarray(data).tobytes())) as saved:
        return {name: saved[name] for name in saved.files}
