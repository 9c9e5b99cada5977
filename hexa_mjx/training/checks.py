"""Validation of a TrainConfig before anything compiles: ranges, batch shape, devices, the run directory.

Each failure is one ConfigError line that names the flag or file and says what to do.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax

from hexa_mjx.mdp import rewards
from hexa_mjx.robot import constants as robot
from hexa_mjx.tasks import default_reward, task_class
from hexa_mjx.training import distributed, symmetry, warm_start
from hexa_mjx.training.checkpoints import list_checkpoints, resolve_checkpoint
from hexa_mjx.training.config import RESUMABLE, ConfigError, TrainConfig, default_run_dir, load_config, \
    make_env_for, saved_settings
from hexa_mjx.training.jax_setup import devices_for


# Valid ranges of numeric flags: (low, high, low included, high included); NaN is never valid.
RANGES = {
    "lr": (0.0, math.inf, False, False), "discount": (0.0, 1.0, False, True), "gae_lambda": (0.0, 1.0, True, True),
    "clip": (0.0, math.inf, False, False), "vf_coef": (0.0, math.inf, True, False),
    "ent_coef": (0.0, math.inf, True, False), "max_grad_norm": (0.0, math.inf, False, False),
    "reward_scaling": (0.0, math.inf, False, False), "mean_init_scale": (0.0, math.inf, False, False),
    "init_noise_std": (0.0, math.inf, False, False), "symmetry_loss": (0.0, math.inf, True, False),
    "ctrl_hz": (0.0, math.inf, False, False), "batch_size": (1, math.inf, True, False),
    "num_minibatches": (1, math.inf, True, False), "num_envs": (1, math.inf, True, False),
}


def check_ranges(cfg: TrainConfig) -> None:
    """ConfigError for a numeric flag outside its range (RANGES) or a hidden layer size below 1."""
    for name, (low, high, low_ok, high_ok) in RANGES.items():
        value = getattr(cfg, name)
        inside = (low < value or (low_ok and value == low)) and (value < high or (high_ok and value == high))
        if not (math.isfinite(value) and inside):
            lo, hi = ("[" if low_ok else "("), ("]" if high_ok else ")")
            raise ConfigError(f"--{name} must be a finite number in {lo}{low:g}, {high:g}{hi}, got {value}")
    if not cfg.hidden or min(cfg.hidden) < 1:
        raise ConfigError(f"--hidden sizes must each be at least 1, got {cfg.hidden}")


def run_scales(cfg: TrainConfig) -> dict[str, float]:
    """The reward scales a run trains with, as its rows are read: its task's table for --reward,
    ablations and --reward_scale overrides applied, each term at the weight it is paid at
    (`Task.paid_scales`); ConfigError on a malformed or unknown override."""
    task = task_class(cfg.task)
    return task.paid_scales(rewards.make_scales(task.rewards[cfg.reward or default_reward(cfg.task)], cfg.ablate,
                                                reward_overrides(cfg), task.terms), cfg)


def reward_overrides(cfg: TrainConfig) -> dict[str, float]:
    """--reward_scale's TERM=VALUE pairs as a dict; ConfigError on a malformed pair or an unknown term."""
    overrides = {}
    for pair in cfg.reward_scale:
        term, sep, value = pair.partition("=")
        try:
            overrides[term] = float(value) if sep else math.nan
        except ValueError:
            overrides[term] = math.nan
        if not math.isfinite(overrides[term]):
            raise ConfigError(f"--reward_scale {pair!r}: write TERM=VALUE with a finite number, e.g. body_contact=-30")
        known = [*rewards.TERMS, *task_class(cfg.task).terms]
        if term not in known:
            raise ConfigError(f"--reward_scale {pair!r}: unknown reward term {term!r}; terms are {sorted(known)}")
    return overrides


def validate(cfg: TrainConfig, writes: bool = True) -> TrainConfig:
    """Fail fast, before any compile, on settings that cannot work; returns cfg with reward and run_dir set.
    With `writes` (process 0 of a multi-process run, or the only one) also checks the run directory."""
    cfg = dataclasses.replace(cfg, reward=cfg.reward or default_reward(cfg.task))
    task = task_class(cfg.task)
    if cfg.reward not in task.rewards:
        raise ConfigError(f"--reward {cfg.reward} is not one of the {cfg.task} task's: {', '.join(task.rewards)}")
    run_scales(cfg)
    check_ranges(cfg)
    distributed.check(cfg.coordinator, cfg.num_processes, cfg.process_id, cfg.coordinator_timeout)
    if not cfg.process_wait_timeout > 0:
        raise ConfigError(f"--process_wait_timeout must be positive seconds, got {cfg.process_wait_timeout}")
    trajectories = cfg.batch_size * cfg.num_minibatches
    if cfg.num_envs < 1 or trajectories % cfg.num_envs:
        fits = [n for n in (8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096) if trajectories % n == 0]
        raise ConfigError(
            f"--num_envs {cfg.num_envs} does not fit the batch shape: batch_size x num_minibatches = "
            f"{cfg.batch_size} x {cfg.num_minibatches} = {trajectories} trajectory segments per update must be "
            f"a multiple of num_envs. Use one of {fits}, or change --batch_size/--num_minibatches.")
    if cfg.cpu_devices < 0:
        raise ConfigError(f"--cpu_devices must be 0 (one per core) or more, got {cfg.cpu_devices}")
    devices = devices_for(cfg)
    if jax.default_backend() == "cpu" and devices > jax.local_device_count():
        raise ConfigError(f"--cpu_devices {devices} but JAX has {jax.local_device_count()} CPU devices: it had "
                          "started before train() could ask for more; use train.py, or call "
                          "hexa_mjx.training.jax_setup.prepare_jax() before anything else touches JAX")
    devices *= jax.process_count()  # brax splits both over every device of every process
    if cfg.num_envs % devices or cfg.batch_size % devices:
        where = f" ({jax.process_count()} processes)" if jax.process_count() > 1 else ""
        raise ConfigError(f"{devices} devices{where} must divide --num_envs ({cfg.num_envs}) and --batch_size "
                          f"({cfg.batch_size}); change them or --cpu_devices")
    for name in ("num_timesteps", "num_evals", "unroll_length", "update_epochs", "episode_length", "num_eval_envs"):
        if getattr(cfg, name) < 1:
            raise ConfigError(f"--{name} must be at least 1, got {getattr(cfg, name)}")
    if cfg.leg_failure_weights and cfg.leg_failure != "random":
        raise ConfigError("--leg_failure_weights weigh the legs of --leg_failure random; add it or drop the weights")
    if (cfg.leg_failure_after or cfg.leg_failure_adaptive) and cfg.leg_failure != "random":
        raise ConfigError("--leg_failure_after and --leg_failure_adaptive schedule --leg_failure random; add it or "
                          "drop them")
    if cfg.leg_failure_adaptive and cfg.leg_failure_weights:
        raise ConfigError("--leg_failure_adaptive draws the failed leg by its cost; it replaces "
                          "--leg_failure_weights: keep one of the two")
    if cfg.leg_failure_adaptive and not (task.has_goal or task.uses_command):
        raise ConfigError(f"--leg_failure_adaptive weighs each leg by the goals reached or the commanded metres "
                          f"walked without it; the {cfg.task} task has neither goals nor commands: drop it")
    if cfg.leg_failure_after < 0:
        raise ConfigError(f"--leg_failure_after is a number of env steps, 0 or more, got {cfg.leg_failure_after}")
    run_dir = Path(cfg.run_dir) if cfg.run_dir else default_run_dir(cfg)
    cfg = dataclasses.replace(cfg, run_dir=str(run_dir))
    if cfg.model and not Path(cfg.model).is_file():
        raise ConfigError(f"--model {cfg.model} is not a file; convert a URDF with "
                          f"`python -m hexa_mjx.robot.convert URDF -o {cfg.model}`")
    env = make_env_for(cfg, curriculum_levels=cfg.curriculum_levels)  # a bad ctrl_hz, task or reward raises here
    if cfg.symmetry_loss:
        if cfg.symmetry_turns < 2:
            raise ConfigError(f"--symmetry_turns must be at least 2 (a half turn), got {cfg.symmetry_turns}")
        try:
            symmetry.maps_for(env, cfg.symmetry_turns)
        except ValueError as e:
            raise ConfigError(str(e)) from None
    if cfg.init_from and not (cfg.resume and list_checkpoints(run_dir)):  # a resume needs only its own
        init_checkpoint(cfg)
    if writes:
        check_run_dir(cfg, run_dir)
    return cfg


# What fixes the shapes of a run's params: a fine-tuning run must match its source in these.
PARAM_SHAPE = ("model", "hidden", "policy_dist")
NOTED: set[tuple[str, str]] = set()  # (--init_from, task) pairs already noted: said once per run


def init_checkpoint(cfg: TrainConfig) -> Path:
    """The checkpoint folder --init_from names; ConfigError if there is none or its networks differ."""
    source = Path(cfg.init_from)
    if not source.exists() and (robot.REPO_ROOT / source).exists():  # a recipe's shipped policy, from anywhere
        source = robot.REPO_ROOT / source
    try:
        source_dir, checkpoint = resolve_checkpoint(source)
    except FileNotFoundError as e:
        raise ConfigError(f"--init_from: {e}; give a run directory or one of its checkpoints/<step> folders") from None
    source = load_config(source_dir)
    differ = [f"{k} {getattr(source, k)!r} there, {getattr(cfg, k)!r} here" for k in PARAM_SHAPE
              if getattr(source, k) != getattr(cfg, k)]
    if source.task != cfg.task:  # another task's policy fits if it observes as many values, or a prefix
        joints = robot_joints(cfg.model)
        layouts = [task_class(t).layout(joints) for t in (source.task, cfg.task)]
        sizes = [layout[-1][1] for layout in layouts]
        noted = (cfg.init_from, cfg.task) in NOTED  # validated more than once per run: said once
        if sizes[0] == sizes[1]:
            if not differ and not noted:
                NOTED.add((cfg.init_from, cfg.task))
                print(f"note: --init_from {cfg.init_from} is a {source.task}-task policy; its first inputs mean other "
                      f"things in the {cfg.task} task, and training adapts it from there")
        elif not warm_start.extends(*layouts):
            differ.append(f"task {source.task!r} there, observing {sizes[0]} values, {cfg.task!r} here, {sizes[1]}")
        elif cfg.privileged_critic or source.privileged_critic:
            differ.append(f"a {cfg.task}-task run widens a {source.task}-task policy only without privileged_critic")
        elif not noted:
            NOTED.add((cfg.init_from, cfg.task))
            print(f"note: --init_from {cfg.init_from} is a {source.task}-task policy; the {cfg.task} task observes "
                  f"{sizes[1] - sizes[0]} more value(s), which its networks start with zero weights on, and its "
                  "first inputs may mean other things there (docs/TASKS.md)")
    if source.privileged_critic and not cfg.privileged_critic:
        differ.append("privileged_critic True there, False here")
    if differ:
        raise ConfigError(f"--init_from {cfg.init_from}: its params do not fit this run ({'; '.join(differ)}); "
                          "set the same values or train from scratch")
    return checkpoint


def robot_joints(model: str = "") -> int:
    """Actuated joints of the run's robot (`model`: its MJCF, "" the report's hexapod)."""
    import mujoco

    return mujoco.MjModel.from_xml_path(str(model or robot.MODEL_XML)).nu


def observation_size(task: str, model: str = "") -> int:
    """Values the policy of `task` observes on the run's robot."""
    return task_class(task).layout(robot_joints(model))[-1][1]


def check_run_dir(cfg: TrainConfig, run_dir: Path) -> None:
    """ConfigError unless `run_dir` is new, or holds this run and --resume is given; creates it."""
    saved = run_dir / "config.json"
    if saved.is_file():
        if not cfg.resume:
            raise ConfigError(f"{run_dir} already holds a run; pass --resume to continue it, "
                              "or choose another --run_dir")
        # A setting added after the run was made has its default there.
        old = {**dataclasses.asdict(TrainConfig()), **saved_settings(run_dir)}
        changed = sorted(k for k, v in dataclasses.asdict(cfg).items()
                         if k not in RESUMABLE and old.get(k) != v)
        if changed:
            there = ", ".join(f"{k}={old.get(k)!r}" for k in changed)
            here = " ".join(f"--{k}" for k in changed)
            raise ConfigError(f"{run_dir} holds a different run: {there} there; --resume continues a run with its "
                              f"own settings (config.json), so drop {here} (on resume only --num_timesteps, "
                              "--num_evals and the run and scale-out flags may change), or choose another --run_dir")
    elif cfg.resume and run_dir.exists() and any(run_dir.iterdir()):
        raise ConfigError(f"{run_dir} has no config.json, so it is not a run this tool can resume")
    writable_folder(run_dir, "--run_dir")  # made only once every setting is known to be good


def writable_folder(folder: Path, flag: str) -> None:
    """Create `folder` and check that it can be written, or raise ConfigError naming `flag`."""
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{flag} {folder} is a file, not a folder; choose another {flag}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise ConfigError(f"cannot write to {flag} {folder} ({e.strerror or e}); choose another") from None


