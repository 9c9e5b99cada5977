"""Training configuration: the typed config whose fields are train.py's flags, presets, validation.

Everything here runs before anything is compiled, so bad input fails in a second with one line.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import jax

from hexa_mjx.training import distributed
from hexa_mjx.mdp import rewards, terrain
from hexa_mjx.training.checkpoints import list_checkpoints, resolve_checkpoint
from hexa_mjx.training.jax_setup import devices_for
from hexa_mjx.engines import make_env
from hexa_mjx.tasks import DEFAULT_TASK, TASKS, default_reward, reward_variants, task_class


@dataclasses.dataclass
class TrainConfig:
    """PPO on the hexapod. Defaults follow the report's Table 1 except the rollout shape."""

    num_envs: int = dataclasses.field(default=256, metadata={"help": "parallel environments"})
    num_timesteps: int = dataclasses.field(default=2_000_000, metadata={"help": "environment steps in total"})
    seed: int = dataclasses.field(default=0, metadata={"help": "random seed"})
    lr: float = dataclasses.field(default=3e-4, metadata={"help": "Adam learning rate"})
    anneal_lr: bool = dataclasses.field(default=False, metadata={
        "help": "CleanRL's schedule: the learning rate falls linearly to 0 at --num_timesteps (default: constant, "
                "the report's Table 1; on the fast preset it did worse, docs/RESULTS.md)"})
    task: str = dataclasses.field(default=DEFAULT_TASK, metadata={
        "help": "; ".join(f"'{name}': {cls.summary}" for name, cls in TASKS.items()),
        "choices": sorted(TASKS)})
    reward: str = dataclasses.field(default="", metadata={
        "help": "reward variant of the task (default: the task's own: goal_directed, navigate)",
        "choices": sorted(reward_variants())})
    ablate: list = dataclasses.field(default_factory=list, metadata={
        "help": "reward ablations (any of these, space-separated)", "choices": sorted(rewards.ABLATIONS),
        "nargs": "*"})
    reward_scale: list = dataclasses.field(default_factory=list, metadata={
        "help": "reward term weights to override, TERM=VALUE each (e.g. body_contact=-30); the terms are "
                "hexa_mjx.mdp.rewards.TERMS", "nargs": "*"})
    ctrl_hz: float = dataclasses.field(default=60.0, metadata={"help": "control rate, Hz (240 / whole number)"})
    model: str = dataclasses.field(default="", metadata={
        "help": "MJCF robot to train (default: models/hexapod.xml); convert one with python -m hexa_mjx.robot.convert"})
    run_dir: str = dataclasses.field(default="", metadata={
        "help": "run directory (default runs/<reward>[-no_<ablation>]-s<seed>)"})
    num_evals: int = dataclasses.field(default=10, metadata={"help": "evaluations (and checkpoints) over the run"})
    resume: bool = dataclasses.field(default=False, metadata={"help": "continue the run in --run_dir"})
    init_from: str = dataclasses.field(default="", metadata={
        "help": "fine-tune: start from the params of this run directory's latest checkpoint (or of one checkpoint "
                "folder), with Adam afresh and step 0; its task, model and network sizes must match"})
    preset: str = dataclasses.field(default="", metadata={
        "help": "named settings: 'paper' = the report's 8 envs x 2048 steps, minibatch 64; 'fast' = 4 epochs, "
                "[128, 128] networks, action noise from std 0.5 and 3M steps: the quickest to a walking policy "
                "on a CPU", "choices": ["fast", "paper"]})
    # Rollout shape: brax collects batch_size * num_minibatches trajectories of unroll_length steps
    # per update (here 16 * 32 * 32 = 16384 = the report's 8 x 2048) and splits them into
    # num_minibatches minibatches of batch_size * unroll_length samples.
    unroll_length: int = dataclasses.field(default=32, metadata={"help": "steps per trajectory segment"})
    batch_size: int = dataclasses.field(default=16, metadata={"help": "trajectory segments per minibatch"})
    num_minibatches: int = dataclasses.field(default=32, metadata={"help": "minibatches per update epoch"})
    update_epochs: int = dataclasses.field(default=10, metadata={"help": "passes over each rollout"})
    discount: float = dataclasses.field(default=0.99, metadata={"help": "discount factor gamma"})
    gae_lambda: float = dataclasses.field(default=0.95, metadata={"help": "GAE lambda"})
    clip: float = dataclasses.field(default=0.2, metadata={"help": "PPO clip range"})
    vf_coef: float = dataclasses.field(default=0.5, metadata={"help": "value-loss coefficient"})
    ent_coef: float = dataclasses.field(default=0.0, metadata={"help": "entropy coefficient"})
    max_grad_norm: float = dataclasses.field(default=0.5, metadata={"help": "gradient clipping norm"})
    hidden: list = dataclasses.field(default_factory=lambda: [256, 256], metadata={
        "help": "hidden layer sizes of actor and critic", "nargs": "+", "type": int})
    reward_scaling: float = dataclasses.field(default=0.01, metadata={
        "help": "constant reward factor (stands in for the report's reward normalization)"})
    policy_dist: str = dataclasses.field(default="normal", metadata={
        "help": "action distribution: 'normal' (CleanRL's Gaussian, clipped by the env) or brax's 'tanh_normal'",
        "choices": ["normal", "tanh_normal"]})
    mean_init_scale: float = dataclasses.field(default=0.01, metadata={
        "help": "init scale of the policy mean's output layer (CleanRL: 0.01, so early actions are near 0)"})
    init_noise_std: float = dataclasses.field(default=1.0, metadata={
        "help": "initial std of the policy's action noise, in action units (CleanRL: 1); learned after that"})
    episode_length: int = dataclasses.field(default=1000, metadata={"help": "control steps per episode"})
    start_joint_noise: float = dataclasses.field(default=0.0, metadata={
        "help": "rad, uniform noise on each joint's start angle, drawn per episode (0: the report's fixed start)"})
    start_yaw_noise: float = dataclasses.field(default=0.0, metadata={
        "help": "rad, uniform noise on the start heading, drawn per episode"})
    goal_min_distance: float = dataclasses.field(default=0.5, metadata={
        "help": "navigate: m, nearest goal distance drawn"})
    goal_max_distance: float = dataclasses.field(default=3.0, metadata={
        "help": "navigate: m, farthest goal distance drawn"})
    curriculum_levels: int = dataclasses.field(default=0, metadata={
        "help": "navigate: a curriculum of this many levels (0: none); each environment's goals start near and "
                "ahead, and the bearing and distance ranges open as it reaches goals (hexa_mjx.mdp.curriculum)"})
    leg_failure: str = dataclasses.field(default="none", metadata={
        "help": "'random': each episode one random leg's servos fail (with --leg_failure_rate); the policy is "
                "not told which", "choices": ["none", "random"]})
    leg_failure_rate: float = dataclasses.field(default=0.5, metadata={
        "help": "probability that an episode has a failed leg (--leg_failure random)"})
    leg_failure_weights: list = dataclasses.field(default_factory=list, metadata={
        "help": "relative chance of each leg (1, 2, ...) being the failed one (--leg_failure random), e.g. "
                "1 1 3 3 1 1 to train more on legs 3 and 4 (default: uniform)", "nargs": "+", "type": float})
    leg_failure_after: int = dataclasses.field(default=0, metadata={
        "help": "training with --leg_failure random: no leg fails in the first this many env steps, so the "
                "policy first learns to walk intact (hexa_mjx.mdp.failure_schedule)"})
    leg_failure_adaptive: bool = dataclasses.field(default=False, metadata={
        "help": "training with --leg_failure random: draw the failed leg by what losing it costs the policy now "
                "(goals per episode against intact episodes, over the batch) instead of uniformly "
                "(hexa_mjx.mdp.failure_schedule)"})
    failure_mode: str = dataclasses.field(default="limp", metadata={
        "help": "a failed leg's servos give no torque (limp) or hold the start angles (locked)",
        "choices": ["limp", "locked"]})
    randomize: bool = dataclasses.field(default=False, metadata={
        "help": "domain randomization: each environment its own friction, link masses, torso payload, servo gain "
                "and force limit, joint damping and armature (ranges: hexa_mjx.mdp.randomization.Ranges)"})
    push_speed: float = dataclasses.field(default=0.0, metadata={
        "help": "m/s, pushes: the torso's planar velocity is kicked by up to this every --push_interval (0: none)"})
    push_interval: float = dataclasses.field(default=3.0, metadata={"help": "s between pushes"})
    action_latency: float = dataclasses.field(default=0.0, metadata={
        "help": "control steps (0 to 1): each episode's commands arrive up to this late"})
    obs_noise: float = dataclasses.field(default=0.0, metadata={
        "help": "observation noise, a multiple of hexa_mjx.mdp.observations.NOISE_SCALES (1: Playground's levels)"})
    terrain: str = dataclasses.field(default="flat", metadata={
        "help": "ground to train on: the flat floor, or a heightfield (hexa_mjx.mdp.terrain: 4 cm bumps, 10-degree "
                "slopes, 3 cm steps, or patches of each)", "choices": list(terrain.KINDS)})
    terrain_difficulty: float = dataclasses.field(default=1.0, metadata={
        "help": "the terrain's heights and slopes as a fraction of the full sizes (0 to 1)"})
    max_contact_points: int = dataclasses.field(default=0, metadata={
        "help": "MJX keeps only this many deepest robot-floor contacts per step (0: all 40 slots)"})
    num_eval_envs: int = dataclasses.field(default=32, metadata={
        "help": "episodes per evaluation (deterministic policy)"})
    compile_cache: bool = dataclasses.field(default=True, metadata={
        "help": "keep compiled programs in a per-user cache folder (--no_compile_cache: off)"})
    record_optimizer: bool = dataclasses.field(default=True, metadata={
        "help": "save Adam's state in each checkpoint, so a resume continues it (--no_record_optimizer: Adam "
                "starts afresh on resume)"})
    eval_at_start: bool = dataclasses.field(default=True, metadata={
        "help": "evaluate the untrained params before the first update, as brax does (--no_eval_at_start: skip "
                "it; it runs about 30 s on a 2-core CPU)"})
    progress: bool = dataclasses.field(default=True, metadata={
        "help": "a console line every 15 s between evaluations and one when training has compiled "
                "(--no_progress: off; it costs under 1%% of training time in the median, docs/RESULTS.md)"})
    cpu_devices: int = dataclasses.field(default=0, metadata={
        "help": "on the CPU: XLA host devices that split environments and minibatches, one core each "
                "(0: one per core, as many as divide num_envs and batch_size; 1: a single device)"})
    coordinator: str = dataclasses.field(default="", metadata={
        "help": "multi-process training: HOST:PORT where process 0 serves jax.distributed's coordinator (empty: "
                "one process, or the job SLURM / Open MPI started)"})
    num_processes: int = dataclasses.field(default=1, metadata={
        "help": "multi-process training: processes in the run, each with its own --process_id"})
    process_id: int = dataclasses.field(default=0, metadata={
        "help": "multi-process training: this process's index; 0 evaluates and writes the run directory"})
    coordinator_timeout: float = dataclasses.field(default=120.0, metadata={
        "help": "multi-process training: s to wait for the coordinator and for every process to join"})

    @property
    def steps_per_update(self) -> int:
        return self.batch_size * self.num_minibatches * self.unroll_length


PRESETS: dict[str, dict[str, Any]] = {
    # The report: 8 envs x 2048 steps per rollout, minibatch 64. brax's minibatches are made of
    # whole trajectory segments, so 64-sample minibatches need 8-step segments: 8 envs each run
    # 256 segments of 8 steps (= 2048 steps) per update, split into 256 minibatches of 8 x 8.
    "paper": {"num_envs": 8, "unroll_length": 8, "batch_size": 8, "num_minibatches": 256},
    # Chosen for wall time to a walking policy on a 2-core CPU (docs/RESULTS.md, "Time to success"):
    # 4 epochs per update (Playground's number) and [128, 128] networks cut the learner's matmuls
    # about 8x, the environment is then most of the time, and the policy still learns in as few steps.
    # Action noise starting at std 0.5 instead of 1: with std 1 these settings reach the goal as soon
    # but keep falling and walking past it (session 18). 3M steps (3.11M: 19 evaluations 10 updates
    # apart) let the policy learn to stop at the goal. No evaluation of the untrained params: it costs
    # about 30 s and says nothing.
    "fast": {"update_epochs": 4, "hidden": [128, 128], "init_noise_std": 0.5, "num_timesteps": 3_000_000,
             "num_evals": 20, "eval_at_start": False},
}

# Settings that may change on --resume without making it a different run.
RESUMABLE = {"num_timesteps", "num_evals", "resume", "run_dir", "cpu_devices", "compile_cache", "progress",
             "eval_at_start", "record_optimizer", "coordinator", "num_processes", "process_id", "coordinator_timeout"}
# Settings that may differ between the processes of one multi-process run.
PER_PROCESS = {"process_id", "compile_cache", "progress"}


class ConfigError(ValueError):
    """Bad command-line input, found before anything is compiled."""


def parse_args(argv=None) -> TrainConfig:
    """Flags from TrainConfig's fields; a preset fills fields the command line leaves unset."""
    parser = argparse.ArgumentParser(prog="train.py", description=TrainConfig.__doc__,
                                     argument_default=argparse.SUPPRESS)
    for f in dataclasses.fields(TrainConfig):
        meta = dict(f.metadata)
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        meta["help"] = f"{meta['help']} (default: {default})"
        if f.type == "bool" and default:
            parser.add_argument(f"--no_{f.name}", dest=f.name, action="store_false", **meta)
        elif f.type == "bool":
            parser.add_argument(f"--{f.name}", action="store_true", **meta)
        else:
            kind = meta.pop("type", None) or {"int": int, "float": float, "str": str, "list": str}[f.type]
            parser.add_argument(f"--{f.name}", type=kind, **meta)
    explicit = vars(parser.parse_args(argv))
    preset = PRESETS.get(explicit.get("preset", ""), {})
    cfg = dataclasses.replace(TrainConfig(), **{**preset, **explicit})
    return dataclasses.replace(cfg, reward=cfg.reward or default_reward(cfg.task))


def default_run_dir(cfg: TrainConfig) -> Path:
    ablations = "".join(f"-no_{a}" for a in sorted(cfg.ablate))
    return Path("runs") / f"{cfg.reward}{ablations}-s{cfg.seed}"



# Valid ranges of numeric flags: (low, high, low included, high included); NaN is never valid.
RANGES = {
    "lr": (0.0, math.inf, False, False), "discount": (0.0, 1.0, False, True), "gae_lambda": (0.0, 1.0, True, True),
    "clip": (0.0, math.inf, False, False), "vf_coef": (0.0, math.inf, True, False),
    "ent_coef": (0.0, math.inf, True, False), "max_grad_norm": (0.0, math.inf, False, False),
    "reward_scaling": (0.0, math.inf, False, False), "mean_init_scale": (0.0, math.inf, False, False),
    "init_noise_std": (0.0, math.inf, False, False),
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
    rewards.make_scales(task.rewards[cfg.reward], cfg.ablate, reward_overrides(cfg), task.terms)
    check_ranges(cfg)
    distributed.check(cfg.coordinator, cfg.num_processes, cfg.process_id, cfg.coordinator_timeout)
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
    if cfg.leg_failure_after < 0:
        raise ConfigError(f"--leg_failure_after is a number of env steps, 0 or more, got {cfg.leg_failure_after}")
    run_dir = Path(cfg.run_dir) if cfg.run_dir else default_run_dir(cfg)
    cfg = dataclasses.replace(cfg, run_dir=str(run_dir))
    if cfg.model and not Path(cfg.model).is_file():
        raise ConfigError(f"--model {cfg.model} is not a file; convert a URDF with "
                          f"`python -m hexa_mjx.robot.convert URDF -o {cfg.model}`")
    make_env_for(cfg, curriculum_levels=cfg.curriculum_levels)  # a bad ctrl_hz, task or reward raises here
    if cfg.init_from and not (cfg.resume and list_checkpoints(run_dir)):  # a resume needs only its own
        init_checkpoint(cfg)
    if writes:
        check_run_dir(cfg, run_dir)
    return cfg


# What fixes the shapes of a run's params: a fine-tuning run must match its source in these.
PARAM_SHAPE = ("task", "model", "hidden", "policy_dist")


def init_checkpoint(cfg: TrainConfig) -> Path:
    """The checkpoint folder --init_from names; ConfigError if there is none or its networks differ."""
    try:
        source_dir, checkpoint = resolve_checkpoint(Path(cfg.init_from))
    except FileNotFoundError as e:
        raise ConfigError(f"--init_from: {e}; give a run directory or one of its checkpoints/<step> folders") from None
    source = load_config(source_dir)
    differ = [f"{k} {getattr(source, k)!r} there, {getattr(cfg, k)!r} here" for k in PARAM_SHAPE
              if getattr(source, k) != getattr(cfg, k)]
    if differ:
        raise ConfigError(f"--init_from {cfg.init_from}: its params do not fit this run ({'; '.join(differ)}); "
                          "set the same values or train from scratch")
    return checkpoint


def check_run_dir(cfg: TrainConfig, run_dir: Path) -> None:
    """ConfigError unless `run_dir` is new, or holds this run and --resume is given; creates it."""
    saved = run_dir / "config.json"
    if saved.is_file():
        if not cfg.resume:
            raise ConfigError(f"{run_dir} already holds a run; pass --resume to continue it, "
                              "or choose another --run_dir")
        # A setting added after the run was made has its default there.
        old = {**dataclasses.asdict(TrainConfig()), **json.loads(saved.read_text())}
        changed = sorted(k for k, v in dataclasses.asdict(cfg).items()
                         if k not in RESUMABLE and old.get(k) != v)
        if changed:
            raise ConfigError(f"{run_dir} holds a different run: {', '.join(f'{k}={old.get(k)!r}' for k in changed)}"
                              f" there; resume with the same settings or choose another --run_dir")
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


def load_config(run_dir: Path) -> TrainConfig:
    data = json.loads((Path(run_dir) / "config.json").read_text())
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    # Runs made before tasks existed are the report's task ("goal", the default).
    return TrainConfig(**{k: v for k, v in data.items() if k in known})


def make_env_for(cfg: TrainConfig, task: str = "", **overrides):
    """The run's environment; keyword overrides set `EnvConfig` fields (eval's start noise, contact cap).

    `task` runs the run's policy on another task's goals, seeing its own task's observation (the
    report's policy on navigation goals).
    """
    if cfg.model:
        overrides = {"model_path": cfg.model, **overrides}
    if task and task != cfg.task:  # the policy's own observation, computed on the other task's goals
        task_settings = dict(goal_min_distance=cfg.goal_min_distance, goal_max_distance=cfg.goal_max_distance)
        return make_env("", task, observe_as=cfg.task, ctrl_hz=cfg.ctrl_hz, episode_length=cfg.episode_length,
                        max_contact_points=cfg.max_contact_points, **{**task_settings, **overrides})
    settings = dict(ablate=tuple(cfg.ablate), reward_scales=reward_overrides(cfg), ctrl_hz=cfg.ctrl_hz,
                    episode_length=cfg.episode_length,
                    start_joint_noise=cfg.start_joint_noise, start_yaw_noise=cfg.start_yaw_noise,
                    max_contact_points=cfg.max_contact_points, goal_min_distance=cfg.goal_min_distance,
                    goal_max_distance=cfg.goal_max_distance, goal_distance_cap=cfg.goal_max_distance,
                    leg_failure=cfg.leg_failure, leg_failure_rate=cfg.leg_failure_rate,
                    leg_failure_weights=tuple(cfg.leg_failure_weights), failure_mode=cfg.failure_mode,
                    push_speed=cfg.push_speed, push_interval=cfg.push_interval,
                    action_latency=cfg.action_latency, obs_noise=cfg.obs_noise, terrain=cfg.terrain,
                    terrain_difficulty=cfg.terrain_difficulty)
    return make_env(cfg.reward, cfg.task, **{**settings, **overrides})
