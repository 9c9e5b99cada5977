"""Gymnasium environments: each task on native MuJoCo, and a NumPy vector environment over MJX.

    import gymnasium as gym

    env = gym.make("hexa_mjx.engines.gym_envs:hexa_mjx/HexapodGoal-v0", render_mode="rgb_array")
    env = gym.make("hexa_mjx/HexapodNavigate-v0", goal_max_distance=2.0)  # once this module is imported
    envs = MJXVectorEnv(num_envs=256, task="navigate")                   # for SB3 / CleanRL

One id per task of the registry (`Task.gym_id`). Gymnasium 1.x has no plugin entry point any more,
so an id names its module (the first form) or this module is imported first.

The single environments (`HexapodGymEnv`) run `hexa_mjx.engines.native.NativeEnv`: the MJX environment's
start, observation, action mapping, reward terms and termination on MuJoCo C. An episode ends
terminated on a fall and truncated at `episode_length`; `info["terms"]` holds the unscaled terms.
"""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium import spaces

from hexa_mjx.robot import constants as robot
from hexa_mjx.mdp.config import make_config
from hexa_mjx.engines.native import NativeEnv
from hexa_mjx.tasks import DEFAULT_TASK, TASKS

IDS = {name: cls.gym_id for name, cls in TASKS.items()}  # one Gymnasium id per task


class HexapodGymEnv(gymnasium.Env):
    """A hexa_mjx task on native MuJoCo behind Gymnasium's API; keywords are EnvConfig fields."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 60}

    def __init__(self, task: str = DEFAULT_TASK, render_mode: str | None = None, width: int = 640, height: int = 480,
                 **overrides):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.env = NativeEnv(make_config(task, **overrides))
        self.render_mode, self.size, self._renderer = render_mode, (height, width), None
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.env.dt))}
        self.observation_space = spaces.Box(-np.inf, np.inf, (self.env.observation_size,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (self.env.action_size,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        # Gymnasium's seeded generator draws the start; the same seed gives the same episode.
        self.env.rng = self.np_random
        return self.env.reset(), {"goal": self.env.goal, "distance": self.env.goal_distance()}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "goal": self.env.goal}

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        import mujoco

        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.env.mj_model, *self.size)
        self._renderer.update_scene(self.env.data, camera=robot.TRACKING_CAMERA)
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def register() -> None:
    """Register one Gymnasium id per task (idempotent). Gymnasium calls it on `import gymnasium`
    through the `gymnasium.envs` entry point in pyproject.toml."""
    for task, env_id in IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=HexapodGymEnv, kwargs={"task": task},
                               disable_env_checker=False)


register()


class MJXVectorEnv(gymnasium.vector.VectorEnv):
    """`num_envs` MJX environments of a task stepped as one batch, with NumPy arrays in and out.

    Gymnasium's VectorEnv API with same-step autoreset: a finished environment starts its next
    episode (a fresh start) within the step that ended it; that step's final observation is in
    `info["final_obs"]` where `info["_final_obs"]` is True.
    """

    def __init__(self, num_envs: int = 256, task: str = DEFAULT_TASK, seed: int = 0, **overrides):
        import jax

        from hexa_mjx.engines import make_env

        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        self.env = make_env(task=task, **overrides)
        self.num_envs = num_envs
        self.metadata = {"autoreset_mode": gymnasium.vector.AutoresetMode.SAME_STEP, "render_modes": []}
        n_obs, n_act = self.env.observation_size, self.env.action_size
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (n_obs,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (n_act,), np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, (num_envs, n_obs), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (num_envs, n_act), np.float32)
        self._key = jax.random.PRNGKey(seed)
        self._reset = jax.jit(jax.vmap(self.env.reset))
        self._step = jax.jit(self._step_batch)
        self._state = None

    def _step_batch(self, state, action, key):
        import jax
        import jax.numpy as jp

        nxt = jax.vmap(self.env.step)(state, action)
        terminated = nxt.done > 0
        truncated = (nxt.info["t"] == 0) & ~terminated  # the env restarts its step count at the time limit
        ended = terminated | truncated
        fresh = jax.vmap(self.env.reset)(jax.random.split(key, self.num_envs))
        state = jax.tree.map(lambda new, old: jp.where(ended.reshape(ended.shape + (1,) * (new.ndim - 1)), new, old),
                             fresh, nxt)
        return state, nxt.obs, nxt.reward, terminated, truncated

    def _next_key(self):
        import jax

        self._key, key = jax.random.split(self._key)
        return key

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        import jax

        if seed is not None:
            self._key = jax.random.PRNGKey(seed)
        self._state = self._reset(jax.random.split(self._next_key(), self.num_envs))
        return np.asarray(self._state.obs), {}

    def step(self, actions):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(actions, np.float32).reshape(self.action_space.shape)
        self._state, final_obs, reward, terminated, truncated = self._step(self._state, actions, self._next_key())
        ended = np.asarray(terminated) | np.asarray(truncated)
        info = {"final_obs": np.asarray(final_obs), "_final_obs": ended}
        return (np.asarray(self._state.obs), np.asarray(reward), np.asarray(terminated), np.asarray(truncated), info)
