"""hexa_mjx: a JAX-native, massively parallel hexapod trainer on MuJoCo MJX."""

import contextlib
import ctypes.util
import io
import os

# Off-screen rendering: MuJoCo reads MUJOCO_GL when first imported. Unless the user chose, take
# EGL, else OSMesa, whichever library is installed (evaluation explains what to install if neither).
if not os.environ.get("MUJOCO_GL"):
    for _backend, _lib in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if ctypes.util.find_library(_lib):
            os.environ["MUJOCO_GL"] = _backend
            if _backend == "osmesa":
                os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
            break

# mujoco.mjx prints a notice on import when the optional (GPU-only) warp backend is absent.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx  # noqa: F401

from hexa_mjx.env import EnvConfig, HexapodEnv, make_env  # noqa: E402

__all__ = ["EnvConfig", "HexapodEnv", "make_env"]
