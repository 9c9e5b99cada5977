"""Checkpoints: atomic folders of (normalizer, policy, value) params and Adam's state, one per evaluation.

`<run>/checkpoints/<step:012d>/` holds `params/` (orbax), `optimizer.npz` (Adam's moments and
step count as brax's PPO left them, in `jax.tree.leaves` order; see `hexa_mjx.training.optimizer_state`)
`resume.npz` (the keys and the training environments' state, for an exact resume) and
`step.json` (the step and a SHA-256 of each). Each is written to a temporary folder and
renamed when complete, so a crash leaves the last complete one readable. Loading checks the
digests and that every value is finite; `load_latest` falls back to the newest checkpoint that
passes, and says so. Checkpoints from before the optimizer state was saved load as before.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shutil
import sys
from collections.abc import Mapping
from pathlib import Path

import jax
import numpy as np

from hexa_mjx.training import crash_points as faults

OPTIMIZER_FILE = "optimizer.npz"
BEST = "best"  # RUN/best: the checkpoint the run's evaluations chose (hexa_mjx.training.selection)
RESUME_FILE = "resume.npz"  # keys and environment state for an exact resume (hexa_mjx.training.resume)


def checkpoint_dir(run_dir: Path) -> Path:
    return Path(run_dir) / "checkpoints"


def list_checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """Complete checkpoints of a run, oldest first (temporary, half-written ones are ignored)."""
    root = checkpoint_dir(run_dir)
    if not root.is_dir():
        return []
    found = [(int(p.name), p) for p in root.iterdir() if re.fullmatch(r"\d{12}", p.name) and p.is_dir()]
    return sorted(found)


def remove_temporaries(run_dir: Path) -> int:
    """Delete half-written checkpoint folders (`tmp-*`) a killed run left behind; returns how many.
    Only one process trains in a run directory, so none of them is being written now."""
    root = checkpoint_dir(run_dir)
    stale = [p for p in root.glob("tmp-*") if p.is_dir()] if root.is_dir() else []
    for path in stale:
        shutil.rmtree(path, ignore_errors=True)
    return len(stale)


def save_checkpoint(run_dir: Path, step: int, params, optimizer=None, resume: tuple[dict, dict] | None = None) -> Path:
    """Write params (and the optimizer state, and `resume`'s (arrays, facts) for an exact resume,
    if given) for `step` atomically: into a temporary folder, renamed when complete."""
    root = checkpoint_dir(run_dir)
    root.mkdir(parents=True, exist_ok=True)
    final, tmp = root / f"{step:012d}", root / f"tmp-{step:012d}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        write_files(tmp, step, params, optimizer, resume)
    except Exception as e:  # a full disk, a lost mount: the last complete checkpoint stays as it was
        shutil.rmtree(tmp, ignore_errors=True)
        cause = e.strerror if isinstance(e, OSError) and e.strerror else f"{type(e).__name__}: {str(e)[:200]}"
        raise CheckpointWriteError(f"could not write checkpoint {final} ({cause}); the last complete checkpoint "
                                   f"in {root} is kept: make room, then continue with --resume") from e
    if final.exists():
        shutil.rmtree(final)
    tmp.rename(final)
    faults.point("checkpoint-saved")
    return final


class CheckpointWriteError(OSError):
    """A checkpoint could not be written; nothing of it is left behind."""


def write_files(tmp: Path, step: int, params, optimizer=None, resume=None) -> None:
    """A checkpoint's files in folder `tmp` (save_checkpoint renames it when complete)."""
    checkpointer = checkpointer_here()
    checkpointer.save(tmp.resolve() / "params", host_tree(params))
    checkpointer.wait_until_finished()
    meta = {"step": step, "sha256": digest(tmp / "params")}
    if optimizer is not None:
        np.savez(tmp / OPTIMIZER_FILE, *[np.asarray(x) for x in jax.tree.leaves(optimizer)])
        meta["optimizer_sha256"] = digest(tmp / OPTIMIZER_FILE)
    if resume is not None:
        arrays, facts = resume
        np.savez_compressed(tmp / RESUME_FILE, **arrays)
        meta.update(resume=facts, resume_sha256=digest(tmp / RESUME_FILE))
    faults.point("checkpoint-writing")
    (tmp / "step.json").write_text(json.dumps(meta))


def checkpointer_here():
    """An orbax checkpointer that acts for this process alone: in a multi-process run only process 0
    saves and loads, so orbax must not wait for the others at its barriers."""
    import orbax.checkpoint as ocp

    me = jax.process_index()
    return ocp.StandardCheckpointer(multiprocessing_options=ocp.options.MultiprocessingOptions(
        primary_host=me, active_processes={me}))


def host_tree(tree):
    """`tree` with NumPy leaves and dataclasses as dicts (same names on disk). Orbax refuses device
    arrays in a multi-process run, and brax's UInt64 step counter casts its parts back to device
    arrays whenever it is rebuilt, so its fields must leave the dataclass."""
    if isinstance(tree, (tuple, list)):
        return type(tree)(host_tree(x) for x in tree)
    if dataclasses.is_dataclass(tree):
        return {f.name: host_tree(getattr(tree, f.name)) for f in tree_fields(tree)}
    if isinstance(tree, Mapping):
        return {k: host_tree(v) for k, v in tree.items()}
    return np.asarray(tree)


def tree_fields(obj) -> list:
    """A flax dataclass's fields that are pytree nodes (static settings are not saved)."""
    return [f for f in dataclasses.fields(obj) if f.metadata.get("pytree_node", True)]


def like(template, plain):
    """`plain` (as host_tree gives it) rebuilt in `template`'s containers."""
    if isinstance(template, (tuple, list)):
        return type(template)(like(t, p) for t, p in zip(template, plain, strict=True))
    if dataclasses.is_dataclass(template):
        return template.replace(**{f.name: like(getattr(template, f.name), plain[f.name])
                                   for f in tree_fields(template)})
    if isinstance(template, Mapping):
        return type(template)({k: like(v, plain[k]) for k, v in template.items()})
    return plain


def digest(path: Path) -> str:
    """SHA-256 over the relative paths and bytes of every file under the folder `path` (or of one file)."""
    path = Path(path)
    if path.is_file():
        return hashlib.sha256(path.read_bytes()).hexdigest()
    h = hashlib.sha256()
    for f in sorted(p for p in path.rglob("*") if p.is_file()):
        h.update(str(f.relative_to(path)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def load_checkpoint(path: Path, template):
    """Restore (normalizer, policy, value) params saved by save_checkpoint into `template`'s
    structure, after checking the files' digest (checkpoints older than digests skip that); every
    value must be finite. RuntimeError says what is wrong."""
    path = Path(path)
    try:
        meta = json.loads((path / "step.json").read_text())
        if "sha256" in meta and digest(path / "params") != meta["sha256"] or (
                "optimizer_sha256" in meta and digest(path / OPTIMIZER_FILE) != meta["optimizer_sha256"]) or (
                "resume_sha256" in meta and digest(path / RESUME_FILE) != meta["resume_sha256"]):
            raise ValueError("its files do not match the checksum written with them (changed or damaged on disk)")
        params = like(template, checkpointer_here().restore((path / "params").resolve(), host_tree(template)))
    except Exception as e:  # orbax raises many kinds; all mean the same to a user
        raise RuntimeError(f"checkpoint {path} is unreadable ({type(e).__name__}: {str(e)[:200]}); "
                           f"use an earlier checkpoint in {path.parent}") from e
    leaves = [np.asarray(x) for x in jax.tree.leaves(params) if np.issubdtype(np.asarray(x).dtype, np.inexact)]
    if not all(np.isfinite(x).all() for x in leaves):
        raise RuntimeError(f"checkpoint {path} holds non-finite (NaN or inf) parameters; "
                           f"use an earlier checkpoint in {path.parent}")
    return meta["step"], params


def load_optimizer(path: Path, template):
    """The optimizer state saved with checkpoint `path`, in `template`'s structure (NumPy leaves), or
    None for a checkpoint written without one. Call after load_checkpoint, which checks its digest."""
    file = Path(path) / OPTIMIZER_FILE
    if not file.is_file():
        return None
    with np.load(file) as saved:
        leaves = [saved[f"arr_{i}"] for i in range(len(saved.files))]
    expected = jax.tree.leaves(template)
    if len(leaves) != len(expected) or any(a.shape != np.shape(b) for a, b in zip(leaves, expected)):
        raise RuntimeError(f"checkpoint {path}'s optimizer state does not fit this network's sizes")
    if not all(np.isfinite(x).all() for x in leaves if np.issubdtype(x.dtype, np.inexact)):
        raise RuntimeError(f"checkpoint {path} holds a non-finite (NaN or inf) optimizer state")
    return jax.tree.unflatten(jax.tree.structure(template), leaves)


def load_resume(path: Path) -> tuple[dict, dict] | None:
    """(arrays, facts) saved for an exact resume with checkpoint `path`, or None for a checkpoint
    written without them. Call after load_checkpoint, which checks their digest."""
    file = Path(path) / RESUME_FILE
    if not file.is_file():
        return None
    with np.load(file) as saved:
        arrays = {name: saved[name] for name in saved.files}
    return arrays, json.loads((Path(path) / "step.json").read_text())["resume"]


def load_latest(run_dir: Path, template, optimizer_template=None):
    """(step, params, optimizer state, its folder) of the newest checkpoint that loads, warning on
    stderr about each newer one that does not; (0, None, None, None) when there is none. The
    optimizer state is None without `optimizer_template`, or for a checkpoint saved without one."""
    for _, path in reversed(list_checkpoints(run_dir)):
        try:
            step, params = load_checkpoint(path, template)
            return step, params, None if optimizer_template is None else load_optimizer(path, optimizer_template), path
        except RuntimeError as e:
            print(f"warning: {e}; falling back to the checkpoint before it", file=sys.stderr)
    return 0, None, None, None


def resolve_checkpoint(path: Path) -> tuple[Path, Path]:
    """(run dir, checkpoint dir) for a run directory (its latest checkpoint), one checkpoint, or
    `RUN/best`, the checkpoint its evaluations chose (hexa_mjx.training.selection)."""
    path = Path(path)
    if path.name == BEST and not path.exists() and (path.parent / "config.json").is_file():
        from hexa_mjx.training import selection  # reads the run's task: imported only when asked

        step, _ = selection.best_step(path.parent)
        return path.parent, checkpoint_dir(path.parent) / f"{step:012d}"
    if (path / "step.json").is_file():
        return path.parent.parent, path
    if (path / "config.json").is_file():
        found = list_checkpoints(path)
        if not found:
            raise FileNotFoundError(f"run {path} has no complete checkpoint yet")
        return path, found[-1][1]
    raise FileNotFoundError(f"{path} is neither a run directory (with config.json) nor a checkpoint folder")
