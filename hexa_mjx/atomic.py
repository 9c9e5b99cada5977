"""Atomic file writes: a reader, or a run stopped mid-write, never sees half a file.

Every file hexa_mjx writes for a user (config, metrics, checkpoint metadata, ONNX, videos, plots'
inputs) goes through here: written beside its destination under a temporary name, then renamed
over it in one step. A failed write leaves the previous file as it was and no temporary behind.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path


@contextlib.contextmanager
def replacing(path: str | Path):
    """A temporary path beside `path` to write; renamed to `path` when the block ends without error,
    removed when it fails. The temporary keeps the suffix, for writers that read it (MP4, PNG)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.tmp-{os.getpid()}{path.suffix}")
    try:
        yield tmp
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write(path: str | Path, data: str | bytes) -> Path:
    """Write `data` (text or bytes) to `path` atomically."""
    with replacing(path) as tmp:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data)
    return Path(path)
