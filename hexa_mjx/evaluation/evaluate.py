"""Evaluate a checkpoint: batched deterministic episodes on MJX, a metrics table, off-screen video.

`eval.py` is the command-line face of `evaluate(...)`; videos come from `hexa_mjx.evaluation.video`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import jax.numpy as jp
import numpy as np

from brax.envs.wrappers import training as brax_training

from hexa_mjx.training import checkpoints, config, networks
from hexa_mjx.evaluation import gait, plots
from hexa_mjx.mdp import randomization
from hexa_mjx.engines import wrappers
from hexa_mjx.robot.model import servo_power
from hexa_mjx.evaluation.video import render_video
from hexa_mjx.tasks import task_class
from hexa_mjx import atomic


CONTACT_GROUPS = ("torso", "hip and knee links", "shins", "feet")


def contact_groups(env) -> np.ndarray:
    """Index into CONTACT_GROUPS for every geom of the model (the torso group includes the world)."""
    m = env.mj_model
    leg = env.geom_leg
    shin = np.isin(m.geom_bodyid, m.geom_bodyid[env.feet])  # the feet's own bodies: the last leg links
    group = np.where(leg < 0, 0, np.where(shin, 2, 1))
    group[env.feet] = 3
    return group


def group_contacts(env, data, groups) -> jax.Array:
    """Floor contact points of one physics state, counted per CONTACT_GROUPS entry."""
    on_floor, geom = env.floor_contact_geoms(data)
    group = jp.asarray(groups)[geom]
    return jp.stack([(on_floor & (group == g)).sum() for g in range(len(CONTACT_GROUPS))])


def rollout(env, policy, num_episodes: int, seed: int = 0, ranges=None):
    """Run `num_episodes` episodes in parallel to their end; returns per-step arrays (time first)
    of qpos, the goal each step is scored against, reward, done, distance, floor contacts per
    CONTACT_GROUPS entry, foot stance, actuator power and the env's metrics, with `alive` marking
    steps in an episode. With `ranges` (a `randomization.Ranges`) each episode runs on its own
    randomized physics model, drawn from `seed`.

    The episodes are split over as many of JAX's devices as divide them (one per core on the CPU
    after `prepare_jax`), in order, so episode i is the same whatever the split.
    """
    steps = env.config.episode_length
    groups = contact_groups(env)
    devices = max(d for d in range(1, jax.local_device_count() + 1) if num_episodes % d == 0)
    keys = jax.random.split(jax.random.PRNGKey(seed), num_episodes)
    step_keys = jax.random.split(keys[0], steps)  # the deterministic policy ignores them

    models, model_axes = None, None
    if ranges is not None:
        model_keys = jax.random.split(jax.random.fold_in(jax.random.PRNGKey(seed), 11), num_episodes)
        models, model_axes = randomization.randomization_fn(env, ranges)(env.mjx_model, model_keys)

    def run(keys, models=None):
        batched = (wrappers.RandomizedVmap(env, lambda _: (models, model_axes)) if models is not None
                   else brax_training.VmapWrapper(env))
        state = batched.reset(keys)

        def body(carry, key):
            state, alive = carry
            action = policy(state.obs, key)
            nxt = batched.step(state, action)
            out = {"qpos": nxt.pipeline_state.qpos, "goal": jax.vmap(env.goal)(state.pipeline_state),
                   "reward": nxt.reward, "done": nxt.done, "alive": alive,
                   "contacts": jax.vmap(lambda d: group_contacts(env, d, groups))(nxt.pipeline_state),
                   "stance": jax.vmap(env.foot_stance)(nxt.pipeline_state),
                   "power": jax.vmap(lambda d: servo_power(d.actuator_force, d.qvel, env.robot.actuator_dof))(
                       nxt.pipeline_state),
                   **{k: v for k, v in nxt.metrics.items()
                      if k.startswith("reward/") or k in ("distance", "success", "fell", "goal_bonus", "nonfinite",
                                                          "goals_reached")}}
            if env.task.uses_command:  # the command each step answers, and the velocity it reached
                out.update(command=jax.vmap(env.command)(state.pipeline_state),
                           commanded=jax.vmap(lambda d: env.task.commanded(env.command(d), d.qpos, env.heading(d)))(
                               state.pipeline_state),
                           velocity=jax.vmap(lambda d: env.task.measured(d.qpos, d.qvel))(nxt.pipeline_state))
            return (nxt, alive * (1.0 - nxt.done)), out

        start_qpos = state.pipeline_state.qpos
        _, traj = jax.lax.scan(body, (state, jp.ones(keys.shape[0])), step_keys)
        return start_qpos, traj

    if devices == 1:
        start, traj = jax.jit(run)(keys, models)
        return np.asarray(start), jax.tree.map(np.asarray, traj)
    split = lambda x: x.reshape(devices, -1, *x.shape[1:])  # noqa: E731
    if models is None:
        start, traj = jax.pmap(run)(split(keys))
    else:  # each device gets its episodes' models; the fields that are not randomized are shared
        start, traj = jax.pmap(run, in_axes=(0, model_axes))(split(keys), randomization.per_device(models, model_axes,
                                                                                                  devices))
    merge = lambda x: np.moveaxis(np.asarray(x), 0, 1).reshape(x.shape[1], num_episodes, *x.shape[3:])  # noqa: E731
    return np.asarray(start).reshape(num_episodes, -1), jax.tree.map(merge, traj)


def contact_figures(contacts, alive, phases: dict, cap: int) -> dict:
    """Per episode: mean floor contact points per step by link group in each phase (before and after
    first reaching the goal), the most points at once, and the steps at the physics' contact cap."""
    out = {}
    for phase, mask in phases.items():
        steps = np.maximum(mask.sum(0), 1)[:, None]
        out[f"contacts_{phase}"] = (contacts * mask[..., None]).sum(0) / steps
    points = contacts.sum(-1) * alive  # floor contact points at once, every group
    out["contact_points_max"] = points.max(0)
    # Steps at which the physics had as many contact points as it keeps (more may have been dropped).
    out["steps_at_contact_cap"] = (points >= cap).sum(0) if cap else np.zeros(alive.shape[1], int)
    return out


# Long by design: one entry per figure of eval.py's table, each a line or two.
def episode_table(env, start_qpos, traj) -> dict:
    """Per-episode figures and their summary (means over episodes; median final distance too)."""
    alive = traj["alive"]  # 1 for steps taken inside the episode, terminal step included
    length = alive.sum(0)
    last = np.maximum(length.astype(int) - 1, 0)
    idx = np.arange(alive.shape[1])
    final_xy = traj["qpos"][last, idx, :2]
    dist = np.where(alive > 0, traj["distance"], np.inf)
    per_episode = {
        "success": (traj["success"] * alive).max(0) > 0,  # the task's own criterion, at any step
        "final_distance": traj["distance"][last, idx],
        "min_distance": dist.min(0),
        "goal_bonus": (traj["goal_bonus"] * alive).sum(0),
        "return": (traj["reward"] * alive).sum(0),
        "fell": traj["fell"][last, idx] > 0,
        "nonfinite": traj["nonfinite"][last, idx] > 0,
        "mean_speed": np.linalg.norm(final_xy - start_qpos[:, :2], axis=1) / (length * env.dt),
        "length": length,
    }
    # Steps before the goal radius is first reached; the rest of the episode is "after the goal".
    walking = alive * (np.minimum.accumulate(dist, axis=0) >= env.config.success_radius)
    per_episode["steps_to_goal"] = walking.sum(0)
    if "reward/body_contact" in traj:
        # Crawling shows on the way to the goal: body contacts before the goal radius is first reached.
        per_episode["body_contact_before_goal"] = (traj["reward/body_contact"] * walking).sum(0)
    phases = {"before_goal": walking, "after_goal": alive - walking}
    if "contacts" in traj:
        per_episode.update(contact_figures(traj["contacts"], alive, phases, env.config.max_contact_points))

    # Per-phase figures average over the episodes that have that phase: an episode that never
    # reaches the goal has no steps to it and no steps after it (None when no episode has any).
    has = {phase: mask.sum(0) > 0 for phase, mask in phases.items()}
    reached = has["after_goal"]  # the step that first enters the goal radius is already "after"

    summary = {
        "episodes": int(alive.shape[1]),
        "success_rate": float(per_episode["success"].mean()),
        "final_distance_mean": float(per_episode["final_distance"].mean()),
        "final_distance_median": float(np.median(per_episode["final_distance"])),
        "min_distance_mean": float(per_episode["min_distance"].mean()),
        "goal_bonus_mean": float(per_episode["goal_bonus"].mean()),
        "return_mean": float(per_episode["return"].mean()),
        "return_std": float(per_episode["return"].std()),
        "fall_rate": float(per_episode["fell"].mean()),
        "nonfinite_rate": float(per_episode["nonfinite"].mean()),
        "mean_speed": float(per_episode["mean_speed"].mean()),
        "episode_length_mean": float(per_episode["length"].mean()),
        "steps_to_goal_mean": float(per_episode["steps_to_goal"][reached].mean()) if reached.any() else None,
        **({"body_contact_before_goal_mean": float(per_episode["body_contact_before_goal"].mean())}
           if "body_contact_before_goal" in per_episode else {}),
        **{f"contacts_{phase}": dict(zip(CONTACT_GROUPS, np.round(per_episode[f"contacts_{phase}"][has[phase]].mean(0),
                                                                  3).tolist())) if has[phase].any() else None
           for phase in phases if f"contacts_{phase}" in per_episode},
        **({"contact_points_max": int(per_episode["contact_points_max"].max()),
            "contact_cap": env.config.max_contact_points,
            "steps_at_contact_cap": int(per_episode["steps_at_contact_cap"].sum()),
            "steps": int(length.sum())} if "contacts" in traj else {}),
        # Per-episode sums of each scaled reward term, averaged: e.g. body_contact near 0 means no crawling.
        "reward_terms": {k[len("reward/"):]: float((traj[k] * alive).sum(0).mean())
                         for k in traj if k.startswith("reward/")},
    }
    if "contacts" in traj:
        non_foot = traj["contacts"][..., :CONTACT_GROUPS.index("feet")].sum(-1)
        summary["feet_only_steps"] = float(((non_foot == 0) * alive).sum() / max(alive.sum(), 1))
    if "stance" in traj:
        # The walk to the first goal (report's task), or the whole episode (navigation).
        window = alive if env.task.gait_window == "alive" else walking
        records = gait.of_episodes(traj["stance"], traj["power"], traj["qpos"][..., :2], window, env.dt,
                                   env.robot.mass, env.robot.leg_length)
        summary["gait"] = gait.summarize(records)
        per_episode["gait_class"] = np.array([r["class"] for r in records])
        per_episode["cost_of_transport"] = np.array([r.get("cost_of_transport") if np.isfinite(
            r.get("cost_of_transport", np.nan)) else None for r in records], dtype=object)
    per_episode = {k: v.tolist() for k, v in per_episode.items()}
    task_summary, task_episodes = env.task.evaluation(env, start_qpos, traj, alive, per_episode["fell"])
    summary.update(task_summary)
    per_episode.update(task_episodes)
    return {"summary": summary, "per_episode": per_episode}


def evaluate(ckpt: str | Path, episodes: int = 128, videos: int = 1, out: str | Path | None = None,
             seed: int = 0, video: bool = True, task: str | None = None, shadows: bool = False,
             randomize: bool = False, **env_overrides) -> dict:
    """Load a checkpoint, run `episodes` deterministic episodes, write metrics JSON and videos.

    Keywords that are `EnvConfig` fields (start noise, contact cap, goal range, waypoints, episode
    length) replace the run's own setting (None keeps it). `task="navigate"` runs a report-task
    policy on the navigation task's goals. Without start noise (report task) every episode starts
    from the same state and the episodes differ only by numerics. `randomize` runs each episode
    on its own randomized physics (`randomization.Ranges`, as train.py --randomize draws them).
    """
    run_dir, ckpt_dir = checkpoints.resolve_checkpoint(Path(ckpt))
    cfg = config.load_config(run_dir)
    overrides = {k: v for k, v in env_overrides.items() if v is not None}
    if overrides.get("waypoints") and not task_class(task or cfg.task).follows_waypoints:
        raise ValueError(f"--waypoints need a task that follows a path; the {task or cfg.task} task does not "
                         "(add --task navigate to try this policy on a path)")
    env = config.make_env_for(cfg, task=task or "", **overrides)
    out = Path(out) if out else run_dir / "eval"
    check_writable(out)
    step, params = checkpoints.load_checkpoint(ckpt_dir, networks.init_params(cfg, env))
    policy = networks.make_inference(cfg, env, params, deterministic=True)
    clock = [time.perf_counter()]  # where eval.py's time goes: rollout (compiling included), figures, plots, video
    start, traj = rollout(env, policy, episodes, seed, ranges=randomization.Ranges() if randomize else None)
    clock.append(time.perf_counter())
    table = episode_table(env, start, traj)
    clock.append(time.perf_counter())
    run = {"task": env.name, "policy_task": cfg.task, "reward": cfg.reward, "ablate": cfg.ablate, "seed": cfg.seed,
           "start_joint_noise": env.config.start_joint_noise, "start_yaw_noise": env.start_yaw_range,
           "max_contact_points": env.config.max_contact_points, "episode_length": env.config.episode_length,
           "randomized_physics": randomize, "terrain": env.config.terrain}
    run.update(env.task.evaluation_settings())
    result = {"checkpoint": str(ckpt_dir), "step": step, "config": run, **table, "videos": []}
    paths = env.task.plot(env, start, traj, out)
    if paths is not None:
        result["paths"] = str(paths)
    result["gait_diagram"] = str(plot_gait(env, traj, table, out / "gait.png"))
    clock.append(time.perf_counter())
    if video:
        for i in range(min(videos, episodes)):
            n = int(traj["alive"][:, i].sum())
            frames = np.concatenate([start[i:i + 1], traj["qpos"][:n, i]])
            goals = traj["goal"][np.minimum(np.arange(n + 1), n - 1), i]  # each frame: the goal walked to next
            path = out / f"episode_{i}.mp4"
            commands = traj["commanded"][np.minimum(np.arange(n + 1), n - 1), i] if "commanded" in traj else None
            render_video(env, frames, path, goals if env.task.has_goal else None, env.config.waypoints,
                         shadows=shadows, commands=commands)
            result["videos"].append(str(path))
    clock.append(time.perf_counter())
    result["time_s"] = dict(zip(("rollout", "figures", "plots", "video"), np.round(np.diff(clock), 1).tolist()))
    atomic.write(out / "metrics.json", json.dumps(result, indent=1))
    return result


def plot_gait(env, traj, table, out: Path, seconds: float = 4.0) -> Path:
    """Episode 0's foot-contact diagram: its first `seconds` after the settling steps."""
    steps = int(traj["alive"][:, 0].sum())
    first = min(gait.SETTLE_STEPS, steps)
    last = min(steps, first + int(round(seconds / env.dt)))
    cls = table["per_episode"]["gait_class"][0]
    return plots.plot_contact_diagram(traj["stance"][first:last, 0], env.dt, out, env.robot.legs,
                                      title=f"episode 0 from {first * env.dt:.1f} s: {cls}")


def check_writable(folder: Path) -> None:
    """Create `folder` or fail now, not after the rollout, with what to do."""
    config.writable_folder(folder, "--out")
