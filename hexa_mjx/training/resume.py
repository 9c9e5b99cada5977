"""Exact resume and preemption: what a checkpoint keeps so that a resumed run continues bit for bit,
and a stop requested by a signal that ends the run with such a checkpoint.

A checkpoint holds, besides the params and Adam's state, the run's position
(`hexa_mjx.training.ppo.Position`: the keys and the training environments' state, physics,
episode counters, goals, commands, curriculum levels and failure draws included) and the number
of evaluations run, which sets the evaluator's key. In a multi-process run process 0 gathers every
process's position (stacked on a first axis by process index) and writes it; on resume it sends
them back, each process taking its own. A resume from it with the same step budget, evaluation
count and process count continues exactly: the same rows and the same final params as the run
that was never stopped (tests/test_crashes.py), and so does one written by a run resumed with a
longer schedule, which continues that schedule. A checkpoint without it (written by an earlier
version) resumes as before: the same training continued from new keys and new episodes, which the
resume says.

SIGTERM and SIGINT (`Preemption`) stop the run at the next update boundary; the run then writes a
checkpoint with its position and exits with EXIT_CODE (`train.py`). Before the first update
(loading, compiling, the step-0 evaluation) they stop it at once: nothing new would be saved.
"""

from __future__ import annotations

import json
import signal

import jax
import numpy as np

from hexa_mjx.training import distributed

EXIT_CODE = 143  # 128 + SIGTERM: what schedulers expect of a job that stopped when asked
FACTS = "facts_json"  # the facts' JSON, as bytes, among the arrays process 0 sends the others


class Preempted(Exception):
    """The run stopped when asked, with a checkpoint at `step` in `path`."""

    def __init__(self, step: int, path):
        super().__init__(f"stopped at step {step:,}; checkpoint {path}")
        self.step, self.path = step, path


class StoppedBeforeTraining(Exception):
    """Asked to stop before the run's first update had run (loading, compiling, the step-0
    evaluation): there was nothing new to save, so it stopped at once."""


class Preemption:
    """A stop asked for by SIGTERM or SIGINT. Before the run's first update (`trained` not yet
    called) it stops at once, raising `StoppedBeforeTraining`: the compile can take a minute and
    there is nothing to save. After it, at the next update boundary, with a checkpoint. A second
    signal stops at once, keeping the last complete checkpoint."""

    def __init__(self):
        self.asked, self.nothing_to_save = False, True

    def install(self) -> "Preemption":
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self._handle)
        return self

    def trained(self) -> None:
        """An update has run: a stop now waits for the next update boundary and saves."""
        self.nothing_to_save = False

    def _handle(self, signum, frame):
        if self.asked:
            raise KeyboardInterrupt
        self.asked = True
        name = signal.Signals(signum).name
        if self.nothing_to_save:
            raise StoppedBeforeTraining(name)
        print(f"\n{name}: stopping at the next update with a checkpoint "
              "(send it again to stop at once, keeping the last complete checkpoint)", flush=True)

    def __call__(self) -> bool:
        return self.asked


def schedule(cfg) -> dict:
    """The settings an exact resume must share with the run it continues."""
    return {"num_timesteps": cfg.num_timesteps, "num_evals": cfg.num_evals, "num_envs": cfg.num_envs,
            "seed": cfg.seed}


def position_arrays(position) -> dict:
    """The arrays a checkpoint keeps for an exact resume from `position` (a ppo.Position). Every
    process of a multi-process run calls it: their positions are gathered, stacked by process."""
    arrays = {"local_key": np.asarray(position.local_key),
              **({"key": np.asarray(position.key)} if position.key is not None else {}),
              **{f"env_{i:04d}": np.asarray(leaf) for i, leaf in enumerate(jax.tree.leaves(position.env_state))}}
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        arrays = {k: np.asarray(v) for k, v in multihost_utils.process_allgather(arrays).items()}
    return arrays


def position_facts(position, evaluations: int, cfg) -> dict:
    """The facts a checkpoint keeps with `position_arrays`: where the run is, and its schedule."""
    return {"step": position.step, "interval": position.interval, "update": position.update,
            "evaluations": evaluations, "schedule": schedule(cfg), "processes": jax.process_count()}


def shared(saved: tuple[dict, dict] | None) -> tuple[dict, dict] | None:
    """Process 0's saved (arrays, facts) on every process (the others pass None)."""
    packed = None if saved is None else {**saved[0], FACTS: np.frombuffer(json.dumps(saved[1]).encode(), np.uint8)}
    packed = distributed.share_arrays(packed)
    if packed is None:
        return None
    facts = json.loads(packed.pop(FACTS).tobytes())
    return packed, facts


def exact_resume(saved, cfg, step: int, processes: int = 1, process: int = 0) -> tuple[dict | None, str]:
    """(ppo.train's `resume` for process `process` of `processes`, with the evaluations run and
    the step its schedule counts from, or None; why not) from the saved (arrays, facts) of the
    checkpoint at `step` (None: it has none).

    A run resumed with a new schedule (a longer run) counts its position from the step it resumed
    at, so a checkpoint it writes sits that many steps past its position's own count: that origin
    is the checkpoint's step less its position's, and the schedule is rebuilt from it."""
    if saved is None:
        return None, "its checkpoint has no saved keys and environments (written by an earlier version)"
    arrays, facts = saved
    if facts.get("processes", 1) != processes:
        return None, f"it was written by {facts.get('processes', 1)} process(es), this run has {processes}"
    if facts["schedule"] != schedule(cfg):
        changed = [k for k, v in schedule(cfg).items() if facts["schedule"].get(k) != v]
        return None, f"{', '.join(changed)} changed since the checkpoint"
    origin = step - facts["step"]
    if not 0 <= origin < cfg.num_timesteps:
        return None, f"its position (step {facts['step']:,}) does not fit its step {step:,}"
    mine = (lambda a: a[process]) if processes > 1 else (lambda a: a)  # noqa: E731
    return {"step": facts["step"], "origin": origin, "interval": facts["interval"], "update": facts["update"],
            "local_key": mine(arrays["local_key"]), "key": mine(arrays["key"]) if "key" in arrays else None,
            "env_state": env_leaves(arrays, processes, process), "evaluations": facts["evaluations"]}, ""


def env_leaves(arrays: dict, processes: int = 1, process: int = 0) -> list:
    """This process's environment-state leaves among a checkpoint's saved arrays, in leaf order."""
    names = sorted(k for k in arrays if k.startswith("env_"))
    return [arrays[k][process] if processes > 1 else arrays[k] for k in names]


def saved_environments(saved, cfg, processes: int = 1, process: int = 0) -> list | None:
    """The training environments' leaves from a checkpoint's saved (arrays, facts), for a resume
    that is not exact (a longer run, more evaluations, another seed): its episodes and curriculum
    levels carry on. None where it has none, or another count of environments or processes."""
    if saved is None:
        return None
    arrays, facts = saved
    if facts.get("processes", 1) != processes or facts["schedule"].get("num_envs") != cfg.num_envs:
        return None
    return env_leaves(arrays, processes, process)
