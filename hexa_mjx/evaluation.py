"""Evaluate a checkpoint: batched deterministic episodes on MJX, a metrics table, off-screen video.

`eval.py` is the command-line face of `evaluate(...)` and `render_video(...)`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax
import jax.numpy as jp
import numpy as np

from hexa_mjx import robot, training

GL_PACKAGES = "libegl1 libegl-mesa0 libosmesa6"  # Debian/Ubuntu


CONTACT_GROUPS = ("torso", "hip and knee links", "shins", "feet")


def contact_groups(env) -> np.ndarray:
    """Index into CONTACT_GROUPS for every geom of the model (the torso group includes the world)."""
    m = env.mj_model
    leg = np.asarray(env._geom_leg)
    shin = np.isin(m.geom_bodyid, m.geom_bodyid[env._feet])  # the feet's own bodies: the last leg links
    group = np.where(leg < 0, 0, np.where(shin, 2, 1))
    group[env._feet] = 3
    return group


def group_contacts(env, data, groups) -> jax.Array:
    """Floor contact points of one physics state, counted per CONTACT_GROUPS entry."""
    on_floor, geom = env.floor_contact_geoms(data)
    group = jp.asarray(groups)[geom]
    return jp.stack([(on_floor & (group == g)).sum() for g in range(len(CONTACT_GROUPS))])


def rollout(env, policy, num_episodes: int, seed: int = 0):
    """Run `num_episodes` episodes in parallel to their end; returns per-step arrays (time first)
    of qpos, reward, done, distance, floor contacts per CONTACT_GROUPS entry and the env's metrics,
    with `alive` marking steps in an episode."""
    steps = env.config.episode_length
    groups = contact_groups(env)

    @jax.jit
    def run(keys):
        state = jax.vmap(env.reset)(keys)

        def body(carry, key):
            state, alive = carry
            action = policy(state.obs, key)
            nxt = jax.vmap(env.step)(state, action)
            out = {"qpos": nxt.pipeline_state.qpos, "reward": nxt.reward, "done": nxt.done, "alive": alive,
                   "contacts": jax.vmap(lambda d: group_contacts(env, d, groups))(nxt.pipeline_state),
                   **{k: v for k, v in nxt.metrics.items()
                      if k.startswith("reward/") or k in ("distance", "fell", "goal_bonus", "nonfinite")}}
            return (nxt, alive * (1.0 - nxt.done)), out

        start_qpos = state.pipeline_state.qpos
        _, traj = jax.lax.scan(body, (state, jp.ones(num_episodes)), jax.random.split(keys[0], steps))
        return start_qpos, traj

    start, traj = run(jax.random.split(jax.random.PRNGKey(seed), num_episodes))
    return np.asarray(start), jax.tree.map(np.asarray, traj)


def episode_table(env, start_qpos, traj) -> dict:
    """Per-episode figures and their summary (means over episodes; median final distance too)."""
    alive = traj["alive"]  # 1 for steps taken inside the episode, terminal step included
    length = alive.sum(0)
    last = np.maximum(length.astype(int) - 1, 0)
    idx = np.arange(alive.shape[1])
    final_xy = traj["qpos"][last, idx, :2]
    dist = np.where(alive > 0, traj["distance"], np.inf)
    per_episode = {
        "success": dist.min(0) < env.config.success_radius,
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
        # Mean floor contact points per step, by link group, before and after first reaching the goal.
        for phase, mask in phases.items():
            steps = np.maximum(mask.sum(0), 1)[:, None]
            per_episode[f"contacts_{phase}"] = (traj["contacts"] * mask[..., None]).sum(0) / steps
        points = traj["contacts"].sum(-1) * alive  # floor contact points at once, every group
        per_episode["contact_points_max"] = points.max(0)
        cap = env.config.max_contact_points
        # Steps at which the physics had as many contact points as it keeps (more may have been dropped).
        per_episode["steps_at_contact_cap"] = (points >= cap).sum(0) if cap else np.zeros_like(length)

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
    return {"summary": summary, "per_episode": {k: v.tolist() for k, v in per_episode.items()}}


def format_table(summary: dict) -> str:
    rows = [("episodes", f"{summary['episodes']}"), ("success rate", f"{summary['success_rate']:.1%}"),
            ("final distance, mean", f"{summary['final_distance_mean']:.3f} m"),
            ("final distance, median", f"{summary['final_distance_median']:.3f} m"),
            ("minimum distance, mean", f"{summary['min_distance_mean']:.3f} m"),
            ("goal bonus, mean", f"{summary['goal_bonus_mean']:.1f}"),
            ("return, mean +- std", f"{summary['return_mean']:.1f} +- {summary['return_std']:.1f}"),
            ("fall rate", f"{summary['fall_rate']:.1%}"), ("mean speed", f"{summary['mean_speed']:.3f} m/s"),
            ("episode length, mean", f"{summary['episode_length_mean']:.0f} steps")]
    steps = summary["steps_to_goal_mean"]
    rows.append(("steps to the goal, mean of successes", "-" if steps is None else f"{steps:.0f}"))
    if "body_contact_before_goal_mean" in summary:
        rows.append(("body contact before the goal, mean", f"{summary['body_contact_before_goal_mean']:.1f}"))
    for phase in ("before_goal", "after_goal"):
        if f"contacts_{phase}" in summary:
            counts = summary[f"contacts_{phase}"]
            counts = "-" if counts is None else ", ".join(f"{k} {v:.2f}" for k, v in counts.items())
            rows.append((f"floor contacts per step, {phase.replace('_', ' ')}", counts))
    if "contact_points_max" in summary:
        cap = summary["contact_cap"]
        kept = (f"physics keeps {cap}; at that cap in {summary['steps_at_contact_cap']:,} of {summary['steps']:,} "
                "steps" if cap else "physics keeps every contact")
        rows.append(("floor contact points at once, most", f"{summary['contact_points_max']} ({kept})"))
    rows += [(f"  reward/{k}, per episode", f"{v:.1f}") for k, v in summary["reward_terms"].items()]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def render_video(env, qpos_frames: np.ndarray, path: Path, width=640, height=480) -> int:
    """Render qpos frames (T, nq) from the tracking camera into an MP4 at the control rate."""
    import imageio.v2 as imageio
    import mujoco

    model = env.mj_model
    data = mujoco.MjData(model)
    mocap = model.body_mocapid[model.body(robot.GOAL_BODY).id]
    data.mocap_pos[mocap, :2] = np.asarray(env._goal)
    if not os.environ.get("MUJOCO_GL"):
        raise RuntimeError(f"no off-screen OpenGL found (neither EGL nor OSMesa): install it with "
                           f"`apt-get install {GL_PACKAGES}`, or pass --no-video")
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as e:
        backend = os.environ.get("MUJOCO_GL", "none")
        raise RuntimeError(
            f"off-screen OpenGL ({backend}) is not usable: {e}. Install it with "
            f"`apt-get install {GL_PACKAGES}` (or try MUJOCO_GL=osmesa), "
            "or pass --no-video") from e
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    with imageio.get_writer(tmp, fps=round(1 / env.dt), codec="libx264", quality=7, macro_block_size=16) as writer:
        for qpos in qpos_frames:
            data.qpos[:] = qpos
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=robot.TRACKING_CAMERA)
            writer.append_data(renderer.render())
    renderer.close()
    tmp.replace(path)
    return len(qpos_frames)


def evaluate(ckpt: str | Path, episodes: int = 128, videos: int = 1, out: str | Path | None = None,
             seed: int = 0, video: bool = True, **env_overrides) -> dict:
    """Load a checkpoint, run `episodes` deterministic episodes, write metrics JSON and videos.

    `start_joint_noise` / `start_yaw_noise` / `max_contact_points` keywords replace the run's own
    setting (None keeps it). Without start noise every episode starts from the same state and the
    episodes differ only by numerics.
    """
    run_dir, ckpt_dir = training.resolve_checkpoint(Path(ckpt))
    cfg = training.load_config(run_dir)
    env = training.make_env_for(cfg, **{k: v for k, v in env_overrides.items() if v is not None})
    step, params = training.load_checkpoint(ckpt_dir, training.init_params(cfg, env))
    policy = training.make_inference(cfg, env, params, deterministic=True)
    start, traj = rollout(env, policy, episodes, seed)
    table = episode_table(env, start, traj)
    out = Path(out) if out else run_dir / "eval"
    out.mkdir(parents=True, exist_ok=True)
    run = {"reward": cfg.reward, "ablate": cfg.ablate, "seed": cfg.seed,
           "start_joint_noise": env.config.start_joint_noise, "start_yaw_noise": env.config.start_yaw_noise,
           "max_contact_points": env.config.max_contact_points}
    result = {"checkpoint": str(ckpt_dir), "step": step, "config": run, **table, "videos": []}
    if video:
        for i in range(min(videos, episodes)):
            n = int(traj["alive"][:, i].sum())
            frames = np.concatenate([start[i:i + 1], traj["qpos"][:n, i]])
            path = out / f"episode_{i}.mp4"
            render_video(env, frames, path)
            result["videos"].append(str(path))
    tmp = out / "metrics.json.tmp"
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(out / "metrics.json")
    return result
