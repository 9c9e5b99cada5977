"""hexa_mjx: a JAX-native, massively parallel hexapod trainer on MuJoCo MJX."""

import contextlib
import io

# mujoco.mjx prints a notice on import when the optional (GPU-only) warp backend is absent.
with contextlib.redirect_stdout(io.StringIO()):
    from mujoco import mjx  # noqa: F401

from hexa_mjx.env import EnvConfig, HexapodEnv, make_env  # noqa: E402

__all__ = ["EnvConfig", "HexapodEnv", "make_env"]
