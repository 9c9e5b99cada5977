"""hexa_mjx: a JAX-native, massively parallel hexapod trainer on MuJoCo MJX."""

import ctypes.util
import os

# Off-screen rendering: MuJoCo reads MUJOCO_GL when first imported. Unless the user chose, take
# EGL, else OSMesa, whichever library is installed (evaluation explains what to install if neither).
GL_BACKENDS = ("egl", "osmesa", "glfw")  # the values of MUJOCO_GL that MuJoCo accepts
if os.environ.get("MUJOCO_GL") and os.environ["MUJOCO_GL"].lower() not in GL_BACKENDS:
    # MuJoCo's own import would fail with a traceback; say what to do instead.
    raise ImportError(f"MUJOCO_GL={os.environ['MUJOCO_GL']} is not one of {', '.join(GL_BACKENDS)}: unset it to let "
                      "hexa_mjx choose, or set one of those")
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

__all__ = ["EnvConfig", "HexapodEnv", "TASKS", "make_env"]


def __getattr__(name):
    # Loaded on first use, so that the native-MuJoCo player (hexa_mjx.native) runs without JAX.
    if name in ("HexapodEnv", "TASKS", "make_env"):
        from hexa_mjx import env, tasks

        return {"HexapodEnv": env.HexapodEnv, "TASKS": tasks.TASKS, "make_env": tasks.make_env}[name]
    if name == "EnvConfig":
        from hexa_mjx.env_config import EnvConfig

        return EnvConfig
    raise AttributeError(f"module 'hexa_mjx' has no attribute {name!r}")
