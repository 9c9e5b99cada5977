"""The engines that run a task: MJX (`mjx_env`, for training and evaluation), native MuJoCo
(`native`, for play.py and deployment) and Gymnasium (`gym_envs`, over either). Each supplies only
its physics step, its contact arrays and its random draws; the task and the episode's events come
from `hexa_mjx.tasks` and `hexa_mjx.mdp`.

    make_env()                    # the report's task on MJX: one goal 1.5 m ahead
    make_env(task="navigate")     # goals in every direction at 0.5 to 3 m, chained
"""

from __future__ import annotations

from hexa_mjx.mdp.config import make_config
from hexa_mjx.tasks import DEFAULT_TASK


def make_env(reward: str = "", task: str = DEFAULT_TASK, observe_as: str = "", **overrides):
    """A task's MJX environment; `reward` picks one of its reward variants ("": its own), keyword
    overrides set `EnvConfig` fields. `observe_as` names another task whose observation the policy
    sees, to run that task's policy on these goals (the report's policy on navigation goals)."""
    from hexa_mjx.engines.mjx_env import HexapodEnv  # JAX only here: the native engine runs without it

    return HexapodEnv(make_config(task, reward, **overrides), observe_as)
