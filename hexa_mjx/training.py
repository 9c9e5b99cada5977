"""Brax PPO over the hexapod environment: config, run directories, checkpoints, logging.

`train.py` is the command-line face of `train(config)`. One run directory holds
`config.json`, `metrics.jsonl` (one row per evaluation), TensorBoard events in
`tb/`, and `checkpoints/<step>/` (orbax: normalizer, policy, value), each written
to a temporary name and renamed when complete.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import re
import shutil
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jp
from flax import linen

import hexa_mjx
from hexa_mjx import rewards


@dataclasses.dataclass
class TrainConfig:
    """PPO on the hexapod. Defaults follow the report's Table 1 except the rollout shape."""

    num_envs: int = dataclasses.field(default=256, metadata={"help": "parallel environments"})
    num_timesteps: int = dataclasses.field(default=2_000_000, metadata={"help": "environment steps in total"})
    seed: int = dataclasses.field(default=0, metadata={"help": "random seed"})
    lr: float = dataclasses.field(default=3e-4, metadata={"help": "Adam learning rate"})
    reward: str = dataclasses.field(default="goal_directed", metadata={
        "help": "reward variant", "choices": sorted(rewards.VARIANTS)})
    ablate: list = dataclasses.field(default_factory=list, metadata={
        "help": "reward ablations (any of these, space-separated)", "choices": sorted(rewards.ABLATIONS),
        "nargs": "*"})
    ctrl_hz: float = dataclasses.field(default=60.0, metadata={"help": "control rate, Hz (240 / whole number)"})
    run_dir: str = dataclasses.field(default="", metadata={
        "help": "run directory (default runs/<reward>[-no_<ablation>]-s<seed>)"})
    num_evals: int = dataclasses.field(default=10, metadata={"help": "evaluations (and checkpoints) over the run"})
    resume: bool = dataclasses.field(default=False, metadata={"help": "continue the run in --run_dir"})
    preset: str = dataclasses.field(default="", metadata={
        "help": "named rollout shape: 'paper' = the report's 8 envs x 2048 steps, minibatch 64",
        "choices": ["paper"]})
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
    episode_length: int = dataclasses.field(default=1000, metadata={"help": "control steps per episode"})
    start_joint_noise: float = dataclasses.field(default=0.0, metadata={
        "help": "rad, uniform noise on each joint's start angle, drawn per episode (0: the report's fixed start)"})
    start_yaw_noise: float = dataclasses.field(default=0.0, metadata={
        "help": "rad, uniform noise on the start heading, drawn per episode"})
    max_contact_points: int = dataclasses.field(default=0, metadata={
        "help": "MJX keeps only this many deepest robot-floor contacts per step (0: all 40 slots)"})
    num_eval_envs: int = dataclasses.field(default=32, metadata={
        "help": "episodes per evaluation (deterministic policy)"})
    cpu_devices: int = dataclasses.field(default=0, metadata={
        "help": "on the CPU: XLA host devices that split environments and minibatches, one core each "
                "(0: one per core, as many as divide num_envs and batch_size; 1: a single device)"})

    @property
    def steps_per_update(self) -> int:
        return self.batch_size * self.num_minibatches * self.unroll_length


PRESETS: dict[str, dict[str, Any]] = {
    # The report: 8 envs x 2048 steps per rollout, minibatch 64. brax's minibatches are made of
    # whole trajectory segments, so 64-sample minibatches need 8-step segments: 8 envs each run
    # 256 segments of 8 steps (= 2048 steps) per update, split into 256 minibatches of 8 x 8.
    "paper": {"num_envs": 8, "unroll_length": 8, "batch_size": 8, "num_minibatches": 256},
}

# Settings that may change on --resume without making it a different run.
RESUMABLE = {"num_timesteps", "num_evals", "resume", "run_dir", "cpu_devices"}


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
        if f.type == "bool":
            parser.add_argument(f"--{f.name}", action="store_true", **meta)
        else:
            kind = meta.pop("type", None) or {"int": int, "float": float, "str": str, "list": str}[f.type]
            parser.add_argument(f"--{f.name}", type=kind, **meta)
    explicit = vars(parser.parse_args(argv))
    preset = PRESETS.get(explicit.get("preset", ""), {})
    return dataclasses.replace(TrainConfig(), **{**preset, **explicit})


def default_run_dir(cfg: TrainConfig) -> Path:
    ablations = "".join(f"-no_{a}" for a in sorted(cfg.ablate))
    return Path("runs") / f"{cfg.reward}{ablations}-s{cfg.seed}"


def prepare_jax(cpu_devices: int = 0) -> None:
    """Set JAX up for brax's PPO: call before anything else touches JAX.

    Asks XLA for `cpu_devices` CPU devices (0: one per core; too late once JAX has started): XLA
    runs one vmapped MJX step on about one core, so one device leaves the other cores idle, and
    brax's PPO splits environments and minibatches over devices with pmap instead. Also selects
    the classic pmap: under jax 0.9's shard_map-based one, brax's training epoch compiles a second
    time on its second call (17 s here).
    """
    from jax._src import xla_bridge

    if not xla_bridge.backends_are_initialized():
        jax.config.update("jax_num_cpu_devices", cpu_devices or len(os.sched_getaffinity(0)))
    jax.config.update("jax_pmap_shmap_merge", False)


def devices_for(cfg: TrainConfig) -> int:
    """Devices PPO runs on: every accelerator, or on the CPU cfg.cpu_devices (0: the most that divide
    num_envs and batch_size, up to the CPU devices JAX has)."""
    if jax.default_backend() != "cpu":
        return jax.local_device_count()
    available = jax.local_device_count()
    if cfg.cpu_devices:
        return cfg.cpu_devices
    return max(d for d in range(1, available + 1) if cfg.num_envs % d == 0 and cfg.batch_size % d == 0)


def validate(cfg: TrainConfig) -> TrainConfig:
    """Fail fast, before any compile, on settings that cannot work; returns cfg with run_dir set."""
    rewards.make_scales(cfg.reward, cfg.ablate)  # unknown names raise ValueError
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
                          "hexa_mjx.training.prepare_jax() before anything else touches JAX")
    if cfg.num_envs % devices or cfg.batch_size % devices:
        raise ConfigError(f"{devices} devices must divide --num_envs ({cfg.num_envs}) and --batch_size "
                          f"({cfg.batch_size}); change them or --cpu_devices")
    for name in ("num_timesteps", "num_evals", "unroll_length", "update_epochs", "episode_length", "num_eval_envs"):
        if getattr(cfg, name) < 1:
            raise ConfigError(f"--{name} must be at least 1, got {getattr(cfg, name)}")
    run_dir = Path(cfg.run_dir) if cfg.run_dir else default_run_dir(cfg)
    cfg = dataclasses.replace(cfg, run_dir=str(run_dir))
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
    make_env_for(cfg)  # a bad ctrl_hz raises here, before compiling
    return cfg


# ---------------------------------------------------------------------------
# Networks and checkpoints


def network_factory(cfg: TrainConfig):
    """brax's PPO network factory with the config's layer sizes and tanh activations."""
    from brax.training.agents.ppo import networks as ppo_networks

    # CleanRL's actor: state-independent log std starting at std 1, a small output layer for the mean.
    return functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=tuple(cfg.hidden),
                             value_hidden_layer_sizes=tuple(cfg.hidden), activation=linen.tanh,
                             distribution_type=cfg.policy_dist, noise_std_type="log", init_noise_std=1.0,
                             mean_kernel_init_fn=jax.nn.initializers.variance_scaling,
                             mean_kernel_init_kwargs={"scale": cfg.mean_init_scale ** 2, "mode": "fan_in",
                                                      "distribution": "uniform"})


def make_networks(cfg: TrainConfig, env):
    """Networks as PPO trained them: observations normalized by the saved running statistics."""
    from brax.training.acme import running_statistics

    return network_factory(cfg)(env.observation_size, env.action_size,
                                preprocess_observations_fn=running_statistics.normalize)


def init_params(cfg: TrainConfig, env):
    """Fresh (normalizer, policy, value) params: the structure checkpoints restore into."""
    from brax.training.acme import running_statistics, specs

    nets = make_networks(cfg, env)
    key_policy, key_value = jax.random.split(jax.random.PRNGKey(cfg.seed))
    normalizer = running_statistics.init_state(specs.Array((env.observation_size,), jp.dtype("float32")))
    return normalizer, nets.policy_network.init(key_policy), nets.value_network.init(key_value)


def checkpoint_dir(run_dir: Path) -> Path:
    return Path(run_dir) / "checkpoints"


def list_checkpoints(run_dir: Path) -> list[tuple[int, Path]]:
    """Complete checkpoints of a run, oldest first (temporary, half-written ones are ignored)."""
    root = checkpoint_dir(run_dir)
    if not root.is_dir():
        return []
    found = [(int(p.name), p) for p in root.iterdir() if re.fullmatch(r"\d{12}", p.name) and p.is_dir()]
    return sorted(found)


def save_checkpoint(run_dir: Path, step: int, params) -> Path:
    """Write params for `step` atomically: into a temporary folder, renamed when complete."""
    import orbax.checkpoint as ocp

    root = checkpoint_dir(run_dir)
    root.mkdir(parents=True, exist_ok=True)
    final, tmp = root / f"{step:012d}", root / f"tmp-{step:012d}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    checkpointer = ocp.StandardCheckpointer()
    checkpointer.save(tmp.resolve() / "params", jax.device_get(params))
    checkpointer.wait_until_finished()
    (tmp / "step.json").write_text(json.dumps({"step": step}))
    if final.exists():
        shutil.rmtree(final)
    tmp.rename(final)
    return final


def load_checkpoint(path: Path, template):
    """Restore (normalizer, policy, value) params saved by save_checkpoint into `template`'s structure."""
    import orbax.checkpoint as ocp

    path = Path(path)
    try:
        step = json.loads((path / "step.json").read_text())["step"]
        params = ocp.StandardCheckpointer().restore((path / "params").resolve(), template)
    except Exception as e:  # orbax raises many kinds; all mean the same to a user
        raise RuntimeError(f"checkpoint {path} is unreadable ({type(e).__name__}: {str(e)[:200]}); "
                           f"use an earlier checkpoint in {path.parent}") from e
    return step, params


def resolve_checkpoint(path: Path) -> tuple[Path, Path]:
    """(run dir, checkpoint dir) for a run directory (its latest checkpoint) or one checkpoint."""
    path = Path(path)
    if (path / "step.json").is_file():
        return path.parent.parent, path
    if (path / "config.json").is_file():
        found = list_checkpoints(path)
        if not found:
            raise FileNotFoundError(f"run {path} has no complete checkpoint yet")
        return path, found[-1][1]
    raise FileNotFoundError(f"{path} is neither a run directory (with config.json) nor a checkpoint folder")


def load_config(run_dir: Path) -> TrainConfig:
    data = json.loads((Path(run_dir) / "config.json").read_text())
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    return TrainConfig(**{k: v for k, v in data.items() if k in known})


def make_env_for(cfg: TrainConfig, **overrides):
    """The run's environment; keyword overrides set `EnvConfig` fields (eval's start noise, contact cap)."""
    settings = dict(ablate=tuple(cfg.ablate), ctrl_hz=cfg.ctrl_hz, episode_length=cfg.episode_length,
                    start_joint_noise=cfg.start_joint_noise, start_yaw_noise=cfg.start_yaw_noise,
                    max_contact_points=cfg.max_contact_points)
    return hexa_mjx.make_env(cfg.reward, **{**settings, **overrides})


def make_inference(cfg: TrainConfig, env, params, deterministic=True):
    """A policy function obs -> action from saved params."""
    from brax.training.agents.ppo import networks as ppo_networks

    make_policy = ppo_networks.make_inference_fn(make_networks(cfg, env))
    policy = make_policy(params, deterministic=deterministic)
    return lambda obs, key: policy(obs, key)[0]


# ---------------------------------------------------------------------------
# Logging


def summarize(metrics: dict) -> dict:
    """The figures a user watches, from brax's eval metrics (per-episode sums, averaged)."""
    get = lambda k: float(metrics.get(f"eval/episode_{k}", math.nan))  # noqa: E731
    return {
        "episode_return": get("reward"),
        "final_distance": get("final_distance"),
        "success_rate": get("final_success"),
        "goal_bonus": get("goal_bonus"),
        "fall_rate": get("fell"),
        "episode_length": float(metrics.get("eval/avg_episode_length", math.nan)),
    }


class Logger:
    """metrics.jsonl rows, TensorBoard scalars and one console line per evaluation."""

    def __init__(self, run_dir: Path, cfg: TrainConfig, start_step: int):
        from tensorboardX import SummaryWriter

        self.path = Path(run_dir) / "metrics.jsonl"
        self.tb = SummaryWriter(str(Path(run_dir) / "tb"))
        self.cfg, self.start_step, self.t0 = cfg, start_step, time.time()
        self.last = {}

    def __call__(self, step: int, metrics: dict) -> None:
        elapsed = time.time() - self.t0
        done = step - self.start_step
        rate = done / elapsed if done > 0 and elapsed > 0 else math.nan
        row = {"step": step, "walltime_s": round(elapsed, 2), "env_steps_per_s": rate, **summarize(metrics),
               **{k: float(v) for k, v in metrics.items() if k.startswith("eval/episode_reward/")}}
        with open(self.path, "a") as f:
            f.write(json.dumps(row) + "\n")
        for key, value in row.items():
            if key != "step" and isinstance(value, float) and math.isfinite(value):
                self.tb.add_scalar(key.replace("eval/episode_", ""), value, step)
        self.tb.flush()
        left = max(self.cfg.num_timesteps - step, 0) / rate if math.isfinite(rate) and rate > 0 else math.nan
        print(f"step {step:>9,}/{self.cfg.num_timesteps:,}  {rate:7.0f} steps/s  left {_fmt_time(left)}  "
              f"return {row['episode_return']:8.1f}  distance {row['final_distance']:.2f} m  "
              f"success {row['success_rate']:.0%}  goal bonus {row['goal_bonus']:7.1f}  "
              f"falls {row['fall_rate']:.0%}", flush=True)
        self.last = row

    def close(self):
        self.tb.close()


def _fmt_time(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "  --:--"
    return f"{int(seconds // 60):4d}:{int(seconds % 60):02d}"


# ---------------------------------------------------------------------------
# Training


def ppo_settings(cfg: TrainConfig) -> dict:
    """brax ppo.train's keyword arguments for the algorithm and rollout shape of `cfg`."""
    return dict(num_envs=cfg.num_envs, episode_length=cfg.episode_length, learning_rate=cfg.lr,
                entropy_cost=cfg.ent_coef, discounting=cfg.discount, unroll_length=cfg.unroll_length,
                batch_size=cfg.batch_size, num_minibatches=cfg.num_minibatches,
                num_updates_per_batch=cfg.update_epochs, normalize_observations=True,
                reward_scaling=cfg.reward_scaling, clipping_epsilon=cfg.clip, gae_lambda=cfg.gae_lambda,
                max_grad_norm=cfg.max_grad_norm, vf_loss_coefficient=cfg.vf_coef,
                network_factory=network_factory(cfg))


def evals_for(cfg: TrainConfig, remaining: int) -> int:
    """brax's num_evals for `remaining` of the run's steps, at least as dense as the run's own
    spacing: a resumed run must not crowd all of its evaluations into the steps it has left (brax
    counts the evaluation before training as one of them)."""
    return 1 + max(1, math.ceil((cfg.num_evals - 1) * remaining / cfg.num_timesteps))


def wrap_env_fn(cfg: TrainConfig):
    """brax's training wrappers, or ours that redraw the start noise every episode."""
    from hexa_mjx import wrappers

    return wrappers.wrap_for_training if cfg.start_joint_noise or cfg.start_yaw_noise else None


def train(cfg: TrainConfig) -> dict:
    """Run (or resume) PPO for `cfg`; returns the last evaluation row."""
    from brax.training.agents.ppo import train as ppo

    prepare_jax(cpu_devices=cfg.cpu_devices)
    cfg = validate(cfg)
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    env = make_env_for(cfg)

    start_step, restore = 0, None
    if cfg.resume and list_checkpoints(run_dir):
        start_step, restore = load_checkpoint(list_checkpoints(run_dir)[-1][1], init_params(cfg, env))
        print(f"resuming {run_dir} from step {start_step:,}")
    tmp = run_dir / "config.json.tmp"
    tmp.write_text(json.dumps(dataclasses.asdict(cfg), indent=2))
    tmp.replace(run_dir / "config.json")
    remaining = cfg.num_timesteps - start_step
    if remaining <= 0:
        print(f"{run_dir} already has {start_step:,} of {cfg.num_timesteps:,} steps; nothing to do")
        return {}

    logger = Logger(run_dir, cfg, start_step)

    def on_progress(step, metrics):
        if step > 0 or start_step == 0:  # a resumed run has already logged its step-0 evaluation
            logger(start_step + step, metrics)

    def on_params(step, make_policy, params):
        if step > 0:
            save_checkpoint(run_dir, start_step + step, params)

    t0 = time.time()
    devices = devices_for(cfg)
    print(f"training {cfg.reward} (ablate {cfg.ablate or 'none'}) seed {cfg.seed}: {remaining:,} steps on "
          f"{cfg.num_envs} envs ({devices} {jax.default_backend()} device{'s' * (devices > 1)}), "
          f"{cfg.steps_per_update:,} steps per update -> {run_dir}", flush=True)
    ppo.train(environment=env, num_timesteps=remaining, **ppo_settings(cfg), seed=cfg.seed + start_step,
              max_devices_per_host=devices, wrap_env_fn=wrap_env_fn(cfg),
              num_evals=evals_for(cfg, remaining), num_eval_envs=cfg.num_eval_envs, deterministic_eval=True,
              progress_fn=on_progress, policy_params_fn=on_params, restore_params=restore)
    logger.close()
    total = time.time() - t0
    last = logger.last
    print(f"done: {cfg.num_timesteps:,} steps in {total / 60:.1f} min; last evaluation: "
          f"success {last.get('success_rate', math.nan):.0%}, distance {last.get('final_distance', math.nan):.2f} m, "
          f"return {last.get('episode_return', math.nan):.1f}; checkpoints in {checkpoint_dir(run_dir)}")
    return last
