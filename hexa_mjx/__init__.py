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

# jaxlib 0.9.2 logs a long, harmless "Loading XLA:CPU AOT result" error for every program it loads
# from the compilation cache (jax_setup.prepare_jax turns the cache on): keep XLA's C++ log quiet
# unless the user asks for it. It must be set before jaxlib loads.
os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

# mujoco.mjx prints a notice on import when the optional (GPU-only) warp backend is absent.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx  # noqa: F401

from hexa_mjx.env import EnvConfig, HexapodEnv  # noqa: E402
from hexa_mjx.tasks import TASKS, make_env  # noqa: E402

__all__ = ["EnvConfig", "HexapodEnv", "TASKS", "make_env"]
