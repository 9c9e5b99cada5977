"""One writer per run directory: a lock file naming the process that trains in it.

`RUN/.lock` holds the pid, host and start time of the training process (process 0 of a
multi-process run). A second run on the same directory is refused with a line that names the
first. A lock whose process no longer runs on this host (a run killed with SIGKILL) is stale and
taken over, with a note; a lock from another host cannot be checked, so the message says how to
remove it. eval.py only reads a run and writes into its own `eval/` folder, so it takes no lock.
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

LOCK_FILE = ".lock"


class RunLocked(RuntimeError):
    """Another live process trains in this run directory."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: it exists
        return True
    return True


class RunLock:
    """`with RunLock(run_dir):` holds the run directory's lock for this process."""

    def __init__(self, run_dir):
        self.path = Path(run_dir) / LOCK_FILE
        self.me = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.strftime("%Y-%m-%d %H:%M:%S")}

    def acquire(self) -> "RunLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                self._take_over_if_stale()
                continue
            with os.fdopen(fd, "w") as f:
                json.dump(self.me, f)
            return self
        raise RunLocked(f"{self.path.parent} is locked by {self.path} and the lock could not be taken; "
                        "delete it if no run trains there")

    def _take_over_if_stale(self) -> None:
        try:
            other = json.loads(self.path.read_text())
            pid, host = int(other["pid"]), str(other["host"])
        except (OSError, ValueError, KeyError, TypeError):
            other, pid, host = {}, -1, self.me["host"]  # unreadable: a writer killed while writing it
        if host != self.me["host"]:
            raise RunLocked(f"{self.path.parent} is being trained by process {pid} on {host} (since "
                            f"{other.get('since', '?')}); wait for it to finish, or if it is gone, delete {self.path}")
        if pid > 0 and _alive(pid):
            raise RunLocked(f"{self.path.parent} is being trained by process {pid} on {host} (since "
                            f"{other.get('since', '?')}); wait for it to finish or stop it first")
        print(f"note: {self.path} was left by process {pid}, which no longer runs: taking the run over")
        self.path.unlink(missing_ok=True)

    def release(self) -> None:
        try:
            if json.loads(self.path.read_text()).get("pid") == self.me["pid"]:
                self.path.unlink()
        except (OSError, ValueError):
            pass

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
