"""Crash points for reliability tests: kill this process (SIGKILL, as `kill -9` would) at a chosen
moment of a training run.

    HEXA_MJX_KILL_AT=NAME[@N][:TERM] python train.py ...

kills the run the N-th time (default 1st) it reaches the point NAME (with `:TERM`, sends it
SIGTERM instead, as a scheduler preempting it would; with `:ENOSPC`, fails there as a full disk
would, with OSError 28; with `:SLEEP<s>`, only waits there for s seconds, as a slow evaluation on a
busy machine would):

- `compiling`: the training programs are about to compile (before the first update);
- `evaluated`: process 0 has run an evaluation, its row not yet written;
- `training-started`: after the step-0 evaluation, before the first checkpoint;
- `row-written`: an evaluation's row written to metrics.jsonl, its checkpoint not yet saved;
- `checkpoint-writing`: a checkpoint's files written into its temporary folder, not yet renamed;
- `checkpoint-saved`: a checkpoint complete (`hexa_mjx.training.loop` writes the evaluation's row first);
- `update-done`: a PPO update has run (between two evaluations, when there are several per interval).

Unset (the normal case), `point` does nothing but compare a string.
"""

from __future__ import annotations

import errno
import os
import signal
import time

VARIABLE = "HEXA_MJX_KILL_AT"
POINTS = ("compiling", "evaluated", "training-started", "row-written", "checkpoint-writing", "checkpoint-saved", "update-done")
_reached: dict[str, int] = {}


def point(name: str) -> None:
    """Count one arrival at crash point `name`; SIGKILL this process if HEXA_MJX_KILL_AT names it."""
    assert name in POINTS, name
    wanted = os.environ.get(VARIABLE)
    if not wanted:
        return
    wanted, _, how = wanted.partition(":")
    target, _, nth = wanted.partition("@")
    if target != name:
        return
    _reached[name] = _reached.get(name, 0) + 1
    if _reached[name] == int(nth or 1):
        if how.startswith("SLEEP"):
            time.sleep(float(how[len("SLEEP"):]))
            return
        if how == "ENOSPC":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        os.kill(os.getpid(), signal.SIGTERM if how == "TERM" else signal.SIGKILL)
