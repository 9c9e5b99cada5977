"""Tasks: what the hexapod is asked to do. Each is a small `HexapodEnv` subclass in its own module.

    make_env()                    # the report's task: one goal 1.5 m ahead
    make_env(task="navigate")     # goals in every direction at 0.5 to 3 m, chained
"""

from __future__ import annotations

from hexa_mjx.env import HexapodEnv
from hexa_mjx.env_config import make_config
from hexa_mjx.tasks.goal import GoalEnv
from hexa_mjx.tasks.navigate import NavigateEnv

TASKS: dict[str, type[HexapodEnv]] = {cls.name: cls for cls in (GoalEnv, NavigateEnv)}


def task_class(task: str) -> type[HexapodEnv]:
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {sorted(TASKS)}")
    return TASKS[task]


def make_env(reward: str = "", task: str = "goal", observe_as: str = "", **overrides) -> HexapodEnv:
    """Build a task's environment; `reward` picks one of its reward variants ("": its own), keyword
    overrides set `EnvConfig` fields. `observe_as` names another task whose observation the policy
    sees, to run that task's policy on these goals (the report's policy on navigation goals)."""
    config = make_config(task, reward, **overrides)
    cls = task_class(task)
    if observe_as and observe_as != task:
        cls = type(f"{cls.__name__}Observed{task_class(observe_as).__name__}", (cls,),
                   {"observe": task_class(observe_as).observe, "observe_task": observe_as})
    return cls(config)
