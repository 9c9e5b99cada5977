"""Training configuration: the typed config whose fields are train.py's flags, grouped; recipes;
resume from a run's own config.json.

Everything here runs before anything is compiled, so bad input fails in a second with one line.
The config is flat (one field per flag, as config.json stores it, so every run directory made
before still loads), and each field names its group: --help shows "task and environment", "PPO",
"run" and "scale-out". Environment settings are EnvConfig's own fields (hexa_mjx.mdp.config): one
definition of their default and help serves train.py, eval.py and play.py (hexa_mjx.cli).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from hexa_mjx.engines import make_env
from hexa_mjx.mdp import rewards
from hexa_mjx.mdp.config import EnvConfig
from hexa_mjx.tasks import DEFAULT_TASK, TASKS, default_reward, reward_variants
from hexa_mjx.training import recipes

ENV, PPO, RUN, SCALE_OUT = "task and environment", "PPO", "run", "scale-out"
GROUPS = (ENV, PPO, RUN, SCALE_OUT)
GROUP_HELP = {ENV: "what the robot learns and the world it learns in: the task, its reward, perturbations, terrain",
              PPO: "the learner: rollout shape, epochs, networks, learning rate, action noise",
              RUN: "where the run lives and how it reports: run directory, seed, evaluations, resume, checkpoints",
              SCALE_OUT: "more cores, processes and machines for one run"}
ENV_FIELDS = {f.name: f for f in dataclasses.fields(EnvConfig)}


def field(group: str, default, help: str, **meta):
    """A TrainConfig field: its default, its help and its --help group (and argparse metadata)."""
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata={"help": help, "group": group, **meta})
    return dataclasses.field(default=default, metadata={"help": help, "group": group, **meta})


def env_field(name: str):
    """TrainConfig's copy of the EnvConfig setting `name`: the same default and help, passed to the
    environment as it is (make_env_for)."""
    f = ENV_FIELDS[name]
    default = f.default if f.default is not dataclasses.MISSING else list(f.default_factory())
    return field(ENV, default, **{**f.metadata, "env": True})


@dataclasses.dataclass
class TrainConfig:
    """PPO on the hexapod. Defaults follow the report's Table 1 except the rollout shape."""

    # -- task and environment ------------------------------------------------------------
    task: str = field(ENV, DEFAULT_TASK, "; ".join(f"'{name}': {cls.summary}" for name, cls in TASKS.items()),
                      choices=sorted(TASKS))
    reward: str = field(ENV, "", "reward variant of the task (default: the task's own: "
                        + ", ".join(default_reward(t) for t in TASKS) + ")", choices=sorted(reward_variants()))
    ablate: list = field(ENV, [], "reward ablations (any of these, space-separated)",
                         choices=sorted(rewards.ABLATIONS), nargs="*")
    reward_scale: list = field(ENV, [], "reward term weights to override, TERM=VALUE each (e.g. body_contact=-30); "
                               "the terms are hexa_mjx.mdp.rewards.TERMS and the task's own", nargs="*")
    model: str = field(ENV, "", "MJCF robot to train (default: models/hexapod.xml); convert one with "
                       "python -m hexa_mjx.robot.convert")
    ctrl_hz: float = env_field("ctrl_hz")
    episode_length: int = env_field("episode_length")
    start_joint_noise: float = env_field("start_joint_noise")
    start_yaw_noise: float = env_field("start_yaw_noise")
    goal_min_distance: float = env_field("goal_min_distance")
    goal_max_distance: float = env_field("goal_max_distance")
    goal_speed_cap: float = env_field("goal_speed_cap")
    goal_stay_share: float = env_field("goal_stay_share")
    curriculum_levels: int = field(ENV, 0, ENV_FIELDS["curriculum_levels"].metadata["help"])  # training only
    command_vx: list = env_field("command_vx")
    command_vy: list = env_field("command_vy")
    command_yaw_rate: list = env_field("command_yaw_rate")
    command_interval: float = env_field("command_interval")
    command_zero_share: float = env_field("command_zero_share")
    tracking_sigma: float = env_field("tracking_sigma")
    yaw_tracking_sigma: float = env_field("yaw_tracking_sigma")
    command_heading_share: float = env_field("command_heading_share")
    goal_mode_share: float = env_field("goal_mode_share")
    command_mode_gain: float = env_field("command_mode_gain")
    leg_failure: str = env_field("leg_failure")
    leg_failure_rate: float = env_field("leg_failure_rate")
    leg_failure_weights: list = env_field("leg_failure_weights")
    leg_failure_after: int = field(ENV, 0, "training with --leg_failure random: no leg fails in the first this many "
                                   "env steps, so the policy first learns to walk intact (hexa_mjx.mdp.failure_schedule)")
    leg_failure_adaptive: bool = field(ENV, False, "training with --leg_failure random: draw the failed leg by what "
                                       "losing it costs the policy now (goals, or metres walked along the commands, "
                                       "per episode against intact episodes, over the batch) instead of uniformly "
                                       "(hexa_mjx.mdp.failure_schedule)")
    failure_mode: str = env_field("failure_mode")
    leg_failure_pairs: float = env_field("leg_failure_pairs")
    randomize: bool = field(ENV, False, "domain randomization: each environment its own friction, link masses, torso "
                            "payload, servo gain and force limit, joint damping and armature (ranges: "
                            "hexa_mjx.mdp.randomization.Ranges)")
    push_speed: float = env_field("push_speed")
    push_interval: float = env_field("push_interval")
    action_latency: float = env_field("action_latency")
    obs_noise: float = env_field("obs_noise")
    terrain: str = env_field("terrain")
    terrain_difficulty: float = env_field("terrain_difficulty")
    max_contact_points: int = env_field("max_contact_points")

    # -- PPO -------------------------------------------------------------------------------
    num_envs: int = field(PPO, 256, "parallel environments")
    num_timesteps: int = field(PPO, 2_000_000, "environment steps in total")
    lr: float = field(PPO, 3e-4, "Adam learning rate")
    anneal_lr: bool = field(PPO, False, "CleanRL's schedule: the learning rate falls linearly to 0 at "
                            "--num_timesteps (default: constant, the report's Table 1; on the fast recipe it did "
                            "worse, docs/RESULTS.md)")
    # Rollout shape: brax collects batch_size * num_minibatches trajectories of unroll_length steps
    # per update (here 16 * 32 * 32 = 16384 = the report's 8 x 2048) and splits them into
    # num_minibatches minibatches of batch_size * unroll_length samples.
    unroll_length: int = field(PPO, 32, "steps per trajectory segment")
    batch_size: int = field(PPO, 16, "trajectory segments per minibatch")
    num_minibatches: int = field(PPO, 32, "minibatches per update epoch")
    update_epochs: int = field(PPO, 10, "passes over each rollout")
    discount: float = field(PPO, 0.99, "discount factor gamma")
    gae_lambda: float = field(PPO, 0.95, "GAE lambda")
    clip: float = field(PPO, 0.2, "PPO clip range")
    vf_coef: float = field(PPO, 0.5, "value-loss coefficient")
    ent_coef: float = field(PPO, 0.0, "entropy coefficient")
    max_grad_norm: float = field(PPO, 0.5, "gradient clipping norm")
    hidden: list = field(PPO, [256, 256], "hidden layer sizes of actor and critic", nargs="+", type=int)
    reward_scaling: float = field(PPO, 0.01, "constant reward factor (stands in for the report's reward "
                                  "normalization)")
    policy_dist: str = field(PPO, "normal", "action distribution: 'normal' (CleanRL's Gaussian, clipped by the env) "
                             "or brax's 'tanh_normal'", choices=["normal", "tanh_normal"])
    mean_init_scale: float = field(PPO, 0.01, "init scale of the policy mean's output layer (CleanRL: 0.01, so early "
                                   "actions are near 0)")
    privileged_critic: bool = field(PPO, False, "asymmetric actor-critic: the value network also reads the "
                                    "observation without its noise and which legs failed and how; the policy, "
                                    "its ONNX file and evaluations are unchanged (hexa_mjx.training.critic)")
    symmetry_loss: float = field(PPO, 0.0, "weight of a loss asking the policy to act alike when its legs are "
                                 "relabelled by a turn of the torso, so that it treats every leg alike (the mirror loss "
                                 "of Isaac Lab's rsl_rl; hexa_mjx.training.symmetry); 0: off")
    symmetry_turns: int = field(PPO, 6, "equal turns of a full circle that --symmetry_loss relabels the legs by: 6 on "
                                "the hexapod (every leg); 2, the half turn alone, under which its torso box repeats too")
    init_noise_std: float = field(PPO, 1.0, "initial std of the policy's action noise, in action units (CleanRL: 1); "
                                  "learned after that")

    # -- run -------------------------------------------------------------------------------
    recipe: str = field(RUN, "", "named settings from recipes/ (" + ", ".join(recipes.names()) + ") or a .toml "
                        "file; flags given here override it (--preset is the old spelling)")
    seed: int = field(RUN, 0, "random seed")
    run_dir: str = field(RUN, "", "run directory (default runs/<reward>[-no_<ablation>]-s<seed>)")
    resume: bool = field(RUN, False, "continue the run in --run_dir with its own settings (config.json); flags "
                         "may change only what can change on resume, e.g. --num_timesteps")
    init_from: str = field(RUN, "", "fine-tune: start from the params of this run directory's latest checkpoint (or "
                           "of one checkpoint folder), with Adam afresh and step 0; its task, model and network sizes "
                           "must match")
    num_evals: int = field(RUN, 10, "evaluations (and checkpoints) over the run")
    num_eval_envs: int = field(RUN, 32, "episodes per evaluation (deterministic policy)")
    eval_at_start: bool = field(RUN, True, "evaluate the untrained params before the first update, as brax does "
                                "(--no_eval_at_start: skip it; with its compile it takes about a minute on a 2-core CPU)")
    progress: bool = field(RUN, True, "a console line every 15 s between evaluations and one when training has "
                           "compiled (--no_progress: off; it costs under 1%% of training time in the median, "
                           "docs/RESULTS.md)")
    record_optimizer: bool = field(RUN, True, "save Adam's state in each checkpoint, so a resume continues it "
                                   "(--no_record_optimizer: Adam starts afresh on resume)")
    compile_cache: bool = field(RUN, True, "keep compiled programs in a per-user cache folder (--no_compile_cache: "
                                "off)")

    # -- scale-out -------------------------------------------------------------------------
    cpu_devices: int = field(SCALE_OUT, 0, "on the CPU: XLA host devices that split environments and minibatches, "
                             "one core each (0: one per core, as many as divide num_envs and batch_size; 1: a single "
                             "device)")
    coordinator: str = field(SCALE_OUT, "", "multi-process training: HOST:PORT where process 0 serves "
                             "jax.distributed's coordinator (empty: one process, or the job SLURM / Open MPI started)")
    num_processes: int = field(SCALE_OUT, 1, "multi-process training: processes in the run, each with its own "
                               "--process_id")
    process_id: int = field(SCALE_OUT, 0, "multi-process training: this process's index; 0 evaluates and writes the "
                            "run directory")
    coordinator_timeout: float = field(SCALE_OUT, 120.0, "multi-process training: s to wait for the coordinator and "
                                       "for every process to join")
    process_wait_timeout: float = field(SCALE_OUT, 3600.0, "multi-process training: s the other processes wait "
                                        "for what process 0 does alone (reading the run directory, an evaluation, "
                                        "a checkpoint) before giving up")

    @property
    def steps_per_update(self) -> int:
        return self.batch_size * self.num_minibatches * self.unroll_length


# Settings that may change on --resume without making it a different run.
RESUMABLE = {"num_timesteps", "num_evals", "resume", "run_dir", "cpu_devices", "compile_cache", "progress",
             "eval_at_start", "record_optimizer", "coordinator", "num_processes", "process_id", "coordinator_timeout",
             "process_wait_timeout"}
# Settings that may differ between the processes of one multi-process run.
PER_PROCESS = {"process_id", "compile_cache", "progress"}
FIELDS = {f.name for f in dataclasses.fields(TrainConfig)}


class ConfigError(ValueError):
    """Bad command-line input, found before anything is compiled."""


def build_parser() -> argparse.ArgumentParser:
    """train.py's flags, one per TrainConfig field, in their groups."""
    parser = argparse.ArgumentParser(prog="train.py", description=TrainConfig.__doc__,
                                     argument_default=argparse.SUPPRESS)
    groups = {name: parser.add_argument_group(name, GROUP_HELP[name]) for name in GROUPS}
    for f in dataclasses.fields(TrainConfig):
        meta = {k: v for k, v in f.metadata.items() if k not in ("group", "env")}
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        meta["help"] = f"{meta['help']} (default: {default})"
        group = groups[f.metadata["group"]]
        if f.type == "bool" and default:
            group.add_argument(f"--no_{f.name}", dest=f.name, action="store_false", **meta)
        elif f.type == "bool":
            group.add_argument(f"--{f.name}", action="store_true", **meta)
        else:
            kind = meta.pop("type", None) or {"int": int, "float": float, "str": str, "list": str}[f.type]
            flags = [f"--{f.name}"] + (["--preset"] if f.name == "recipe" else [])
            group.add_argument(*flags, dest=f.name, type=kind, **meta)
    return parser


def parse_args(argv=None) -> TrainConfig:
    """TrainConfig from the command line: a recipe fills what the flags leave unset; with --resume,
    the run's own config.json does, and a recipe never replaces what may change on resume."""
    parser = build_parser()
    explicit = vars(parser.parse_args(argv))
    try:
        recipe = recipes.load(explicit["recipe"], FIELDS) if explicit.get("recipe") else {}
        saved = Path(explicit.get("run_dir", "")) / "config.json"
        if explicit.get("resume") and explicit.get("run_dir") and saved.is_file():
            base = load_config(saved.parent)
            recipe = {k: v for k, v in recipe.items() if k not in RESUMABLE}
        else:
            base = TrainConfig()
    except (recipes.RecipeError, ConfigError) as e:
        parser.error(str(e))
    cfg = dataclasses.replace(base, **{**recipe, **explicit})
    return dataclasses.replace(cfg, reward=cfg.reward or default_reward(cfg.task))


def default_run_dir(cfg: TrainConfig) -> Path:
    ablations = "".join(f"-no_{a}" for a in sorted(cfg.ablate))
    return Path("runs") / f"{cfg.reward}{ablations}-s{cfg.seed}"


def saved_settings(run_dir: Path) -> dict:
    """The settings in a run's config.json; ConfigError naming the file if it cannot be read. A run
    from before recipes keeps its preset as its recipe."""
    path = Path(run_dir) / "config.json"
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError(f"{path} cannot be read ({e}); restore it from a copy, or start a new run in another "
                          "--run_dir") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path} holds no settings; restore it from a copy, or start a new run in another --run_dir")
    if "preset" in data:
        data.setdefault("recipe", data.pop("preset"))
    return data


def load_config(run_dir: Path) -> TrainConfig:
    """The TrainConfig a run was made with (settings added since then take their defaults)."""
    return TrainConfig(**{k: v for k, v in saved_settings(run_dir).items() if k in FIELDS})


def make_env_for(cfg: TrainConfig, task: str = "", **overrides):
    """The run's environment; keyword overrides set `EnvConfig` fields (eval's start noise, contact cap).

    `task` runs the run's policy on another task's goals, seeing its own task's observation (the
    report's policy on navigation goals).
    """
    from hexa_mjx.training.checks import reward_overrides

    if cfg.model:
        overrides = {"model_path": cfg.model, **overrides}
    if task and task != cfg.task:
        task_settings = dict(goal_min_distance=cfg.goal_min_distance, goal_max_distance=cfg.goal_max_distance)
        return make_env("", task, observe_as=cfg.task, ctrl_hz=cfg.ctrl_hz, episode_length=cfg.episode_length,
                        max_contact_points=cfg.max_contact_points, **{**task_settings, **overrides})
    settings = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(TrainConfig) if f.metadata.get("env")}
    settings = {k: tuple(v) if isinstance(v, list) else v for k, v in settings.items()}
    settings.update(ablate=tuple(cfg.ablate), reward_scales=reward_overrides(cfg),
                    goal_distance_cap=cfg.goal_max_distance)
    return make_env(cfg.reward, cfg.task, **{**settings, **overrides})


# Validation lives in hexa_mjx.training.checks, which reads this module; its names are also
# reachable from here (`config.validate`), loaded on first use.
CHECKS = ("PARAM_SHAPE", "RANGES", "check_ranges", "check_run_dir", "init_checkpoint", "reward_overrides",
          "validate", "writable_folder")


def __getattr__(name):
    if name in CHECKS:
        from hexa_mjx.training import checks

        return getattr(checks, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
