"""hexa_mjx: a JAX-native, massively parallel hexapod trainer on MuJoCo MJX."""

import ctypes.util
import importlib.machinery
import importlib.util
import os
import sys

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

# `python -m hexa_mjx.<name>` entry points from before the sub-packages, and where they live now.
MOVED = {"action_noise": "evaluation.action_noise", "benchmark": "studies.benchmark",
         "contact_check": "evaluation.contact_check", "convert": "robot.convert", "experiments": "studies.experiments",
         "export": "deploy.export", "leg_failure": "studies.leg_failure_sweep", "plots": "evaluation.plots",
         "soak": "studies.soak", "sweeps": "studies.robustness", "time_to_success": "studies.time_to_success",
         "video": "evaluation.video"}


class _MovedFinder:
    """Finds `hexa_mjx.<old name>` as the module it moved to, so documented commands keep working."""

    @staticmethod
    def find_spec(fullname, path=None, target=None):
        package, _, name = fullname.rpartition(".")
        if package != __name__ or name not in MOVED:
            return None
        spec = importlib.util.find_spec(f"{__name__}.{MOVED[name]}")
        # Under its old name: `python -m` runs the module's code as __main__ from this spec.
        return importlib.util.spec_from_file_location(fullname, spec.origin)


sys.meta_path.append(_MovedFinder())


class _QuietWarpFinder:
    """Imports mujoco.mjx's optional GPU backend (`mujoco.mjx.warp`) without the two "Failed to
    import warp" lines it prints when Warp is absent: hexa_mjx runs MJX's JAX implementation,
    which needs no Warp, so on a machine without it those lines only look like errors."""

    NAME = "mujoco.mjx.warp"
    NOISE = ("Failed to import warp:", "Failed to import mujoco_warp:")

    def find_spec(self, fullname, path=None, target=None):
        # importlib.machinery is imported at the top: importing it here, on Python 3.12, would call
        # this finder again before it returns, without end.
        if fullname != self.NAME:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is not None and spec.loader is not None:
            spec.loader = _QuietLoader(spec.loader, self.NOISE)
        return spec


class _QuietLoader:
    def __init__(self, loader, noise):
        self.loader, self.noise = loader, noise

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        import contextlib
        import io

        out = io.StringIO()
        try:
            with contextlib.redirect_stdout(out):
                self.loader.exec_module(module)
        finally:  # anything else it printed still reaches the console
            sys.stdout.write("".join(line for line in out.getvalue().splitlines(keepends=True)
                                     if not line.startswith(self.noise)))


sys.meta_path.insert(0, _QuietWarpFinder())


def __getattr__(name):
    # Loaded on first use, so that the native-MuJoCo player (hexa_mjx.engines.native) runs without JAX.
    if name == "HexapodEnv":
        from hexa_mjx.engines.mjx_env import HexapodEnv

        return HexapodEnv
    if name == "make_env":
        from hexa_mjx.engines import make_env

        return make_env
    if name == "TASKS":
        from hexa_mjx.tasks import TASKS

        return TASKS
    if name == "EnvConfig":
        from hexa_mjx.mdp.config import EnvConfig

        return EnvConfig
    raise AttributeError(f"module 'hexa_mjx' has no attribute {name!r}")
