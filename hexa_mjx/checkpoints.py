"""Checkpoints: atomic orbax folders of (normalizer, policy, value) params, one per evaluation.

`<run>/checkpoints/<step:012d>/` holds `params/` (orbax) and `step.json` (the step and a SHA-256
of every file under params/); each is written to a temporary folder and renamed when complete, so
a crash leaves the last complete one readable. Loading checks the digest and that every value is
finite; `load_latest` falls back to the newest checkpoint that passes, and says so.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
from pathlib import Path

import jax
import numpy as np


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


def save_checkpoint(run_dir: Path, step: int, params) -> Path:
    """Write params for `step` atomically: into a temporary folder, renamed when complete."""
    import orbax.checkpoint as ocp

    root = checkpoint_dir(run_dir)
    root.mkdir(parents=True, exist_ok=True)
    final, tmp = root / f"{step:012d}", root / f"tmp-{step:012d}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    checkpointer = ocp.StandardCheckpointer()
    checkpointer.save(tmp.resolve() / "params", jax.device_get(params))
    checkpointer.wait_until_finished()
    (tmp / "step.json").write_text(json.dumps({"step": step, "sha256": digest(tmp / "params")}))
    if final.exists():
        shutil.rmtree(final)
    tmp.rename(final)
    return final


def digest(folder: Path) -> str:
    """SHA-256 over the relative paths and bytes of every file under `folder`."""
    h = hashlib.sha256()
    for f in sorted(p for p in Path(folder).rglob("*") if p.is_file()):
        h.update(str(f.relative_to(folder)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def load_checkpoint(path: Path, template):
    """Restore (normalizer, policy, value) params saved by save_checkpoint into `template`'s
    structure, after checking the files' digest (checkpoints older than digests skip that); every
    value must be finite. RuntimeError says what is wrong."""
    import orbax.checkpoint as ocp

    path = Path(path)
    try:
        meta = json.loads((path / "step.json").read_text())
        if "sha256" in meta and digest(path / "params") != meta["sha256"]:
            raise ValueError("its files do not match the checksum written with them (changed or damaged on disk)")
        params = ocp.StandardCheckpointer().restore((path / "params").resolve(), template)
    except Exception as e:  # orbax raises many kinds; all mean the same to a user
        raise RuntimeError(f"checkpoint {path} is unreadable ({type(e).__name__}: {str(e)[:200]}); "
                           f"use an earlier checkpoint in {path.parent}") from e
    leaves = [np.asarray(x) for x in jax.tree.leaves(params) if np.issubdtype(np.asarray(x).dtype, np.inexact)]
    if not all(np.isfinite(x).all() for x in leaves):
        raise RuntimeError(f"checkpoint {path} holds non-finite (NaN or inf) parameters; "
                           f"use an earlier checkpoint in {path.parent}")
    return meta["step"], params


def load_latest(run_dir: Path, template):
    """(step, params) of the newest checkpoint that loads, warning on stderr about each newer one
    that does not; (0, None) when there is none."""
    for _, path in reversed(list_checkpoints(run_dir)):
        try:
            return load_checkpoint(path, template)
        except RuntimeError as e:
            print(f"warning: {e}; falling back to the checkpoint before it", file=sys.stderr)
    return 0, None


def resolve_checkpoint(path: Path) -> tuple[Path, Path]:
    """(run dir, checkpoint dir) for a run directory (its latest checkpoint) or one checkpoint."""
    path = Path(path)
    if (path / "step.json").is_file():
        return path.parent.parent, path
    if (path / "config.json").is_file():
        found = list_checkpoints(path)
        if not found:
            raise FileNotFoundError(f"run {path} has no complete checkpoint yet")
        return path, found[-1][1]
    raise FileNotFoundError(f"{path} is neither a run directory (with config.json) nor a checkpoint folder")
