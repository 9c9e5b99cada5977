"""The task registry: the one place that lists tasks.

Each task is one module here with one `Task` subclass (`hexa_mjx.tasks.base`), run as it is by
both engines, eval.py, play.py, export and Gymnasium. To add a task, write its module (stand.py is
the smallest example) and add its class to TASKS below.
"""

from __future__ import annotations

from hexa_mjx.tasks.base import Task
from hexa_mjx.tasks.drive import DriveTask
from hexa_mjx.tasks.goal import GoalTask
from hexa_mjx.tasks.navigate import NavigateTask
from hexa_mjx.tasks.stand import StandTask
from hexa_mjx.tasks.velocity import VelocityTask

TASKS: dict[str, type[Task]] = {cls.name: cls for cls in (GoalTask, NavigateTask, StandTask, VelocityTask, DriveTask)}
DEFAULT_TASK = GoalTask.name  # the report's task


def task_class(task: str) -> type[Task]:
    """The task registered as `task`; a clear error for an unknown name."""
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {sorted(TASKS)}")
    return TASKS[task]


def default_reward(task: str) -> str:
    """The task's own reward variant (its first)."""
    return next(iter(task_class(task).rewards))


def reward_variants() -> dict[str, dict[str, float]]:
    """Every task's reward variants: name -> scales table."""
    return {name: table for cls in TASKS.values() for name, table in cls.rewards.items()}
