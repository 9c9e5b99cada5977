"""Environment speed: MJX batched env/physics steps per second beside MuJoCo C.

    python -m hexa_mjx.benchmark [--batches 64 256 1024] [--steps 100] [--repeats 3] [--compare_solver 4 8]

Prints compile time, then for each batch size the median over repeats of env
steps/s and physics steps/s (env steps x substeps) under random actions, then
MuJoCo C's single-thread physics steps/s on the same model (mujoco.rollout) and
the MJX/C ratio. Everything is measured in one run, side by side.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import rollout

import hexa_mjx
from hexa_mjx import robot


def _rollout_fn(env, steps):
    """A jitted batched rollout of `steps` control steps under uniform random actions."""
    def run(state, rng):
        def body(carry, _):
            state, rng = carry
            rng, key = jax.random.split(rng)
            action = jax.random.uniform(key, (state.obs.shape[0], env.action_size), minval=-1, maxval=1)
            return (jax.vmap(env.step)(state, action), rng), None
        (state, _), _ = jax.lax.scan(body, (state, rng), None, length=steps)
        return state
    return jax.jit(run)


def mjx_speed(env, batch: int, steps: int, repeats: int) -> dict:
    """Compile time and median env steps/s for one batch size."""
    reset = jax.jit(jax.vmap(env.reset))
    run = _rollout_fn(env, steps)
    state = reset(jax.random.split(jax.random.PRNGKey(0), batch))
    t0 = time.perf_counter()
    state = jax.block_until_ready(run(state, jax.random.PRNGKey(1)))
    compile_s = time.perf_counter() - t0
    rates = []
    for r in range(repeats):
        t0 = time.perf_counter()
        state = jax.block_until_ready(run(state, jax.random.PRNGKey(2 + r)))
        rates.append(batch * steps / (time.perf_counter() - t0))
    env_rate = statistics.median(rates)
    return {"batch": batch, "compile_s": compile_s, "env_steps_per_s": env_rate,
            "physics_steps_per_s": env_rate * env.n_substeps}


def mujoco_c_speed(model: mujoco.MjModel, steps: int, repeats: int, seed: int = 0) -> float:
    """Median single-thread physics steps/s of MuJoCo C (mujoco.rollout) under random targets."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    state = np.zeros(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    lo, hi = model.actuator_ctrlrange.T
    rng = np.random.default_rng(seed)
    control = lo + (hi - lo) * rng.uniform(size=(1, steps, model.nu))
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        rollout.rollout(model, data, state[None], control)
        rates.append(steps / (time.perf_counter() - t0))
    return statistics.median(rates)


def gait_actions(steps: int, dt: float) -> np.ndarray:
    """A smooth, gait-like action sequence (18 phase-shifted sines) for reproducible rollouts."""
    t = np.arange(steps)[:, None] * dt
    actions = 0.5 * np.sin(2 * np.pi * 1.5 * t + 0.7 * np.arange(18)[None])
    actions[:, 2::3] -= 0.5  # ankles near their zero angle
    return actions


def c_rollout(env, model: mujoco.MjModel, actions: np.ndarray) -> np.ndarray:
    """qpos after each control step when MuJoCo C runs `actions` from the env's start state."""
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = np.asarray(env._qpos0), np.asarray(env._qvel0)
    mujoco.mj_forward(model, data)
    lo, hi = model.actuator_ctrlrange.T
    out = []
    for action in actions:
        data.ctrl[:] = lo + (np.clip(action, -1, 1) + 1) / 2 * (hi - lo)
        for _ in range(env.n_substeps):
            mujoco.mj_step(model, data)
        out.append(data.qpos.copy())
    return np.array(out)


def solver_error(env, steps: int) -> tuple[float, float]:
    """Max torso-position (m) and joint-angle (rad) gap between the model's solver settings and
    robot.TIGHT_SOLVER after `steps` control steps of gait_actions, both in MuJoCo C."""
    actions = gait_actions(steps, env.dt)
    tight = mujoco.MjModel.from_xml_path(env.config.model_path)
    tight.opt.iterations, tight.opt.ls_iterations = robot.TIGHT_SOLVER["iterations"], robot.TIGHT_SOLVER["ls_iterations"]
    fast, ref = c_rollout(env, env.mj_model, actions)[-1], c_rollout(env, tight, actions)[-1]
    return float(np.abs(fast[:3] - ref[:3]).max()), float(np.abs(fast[7:] - ref[7:]).max())


def train_speed(num_envs: int = 256, updates: int = 8) -> dict:
    """End-to-end PPO env steps/s (train.py's default settings, no evaluations) and compile time.
    Two training epochs of `updates` updates each: the first includes compiling, the second not."""
    from brax.training.agents.ppo import train as ppo

    from hexa_mjx import training

    cfg = training.TrainConfig(num_envs=num_envs)
    env = training.make_env_for(cfg)
    marks = [(0, time.perf_counter())]
    ppo.train(environment=env, num_timesteps=2 * updates * cfg.steps_per_update, **training.ppo_settings(cfg),
              num_evals=3, run_evals=False, progress_fn=lambda step, m: marks.append((step, time.perf_counter())))
    (s1, t1), (s2, t2) = marks[-2:]
    epoch_s = t2 - t1
    first_s = t1 - marks[0][1]
    return {"train_steps_per_s": (s2 - s1) / epoch_s, "compile_s": first_s - epoch_s}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.benchmark", description=__doc__.split("\n\n")[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[64, 256, 1024], help="numbers of environments")
    parser.add_argument("--steps", type=int, default=100, help="control steps per timed rollout")
    parser.add_argument("--repeats", type=int, default=3, help="timed rollouts per batch size (median reported)")
    parser.add_argument("--ctrl_hz", type=float, default=60.0, help="control rate, Hz")
    parser.add_argument("--train", action="store_true",
                        help="also time end-to-end PPO training (train.py defaults) at the largest batch")
    parser.add_argument("--compare_solver", type=int, nargs=2, metavar=("ITERATIONS", "LS_ITERATIONS"),
                        help="also time this solver setting at the largest batch, beside the model's own")
    args = parser.parse_args(argv)

    env = hexa_mjx.make_env(ctrl_hz=args.ctrl_hz)
    m = env.mj_model
    print(f"model: {env.config.model_path}  nv={m.nv} nu={m.nu} ngeom={m.ngeom} "
          f"solver iterations={m.opt.iterations} ls_iterations={m.opt.ls_iterations} "
          f"substeps/env step={env.n_substeps}  jax {jax.__version__} on {jax.devices()[0].platform}")
    c_rate = mujoco_c_speed(m, steps=4000, repeats=args.repeats)
    print(f"{'envs':>6} {'compile s':>10} {'env steps/s':>12} {'physics steps/s':>16} {'vs MuJoCo C 1-thread':>21}")
    for batch in args.batches:
        r = mjx_speed(env, batch, args.steps, args.repeats)
        print(f"{batch:>6} {r['compile_s']:>10.1f} {r['env_steps_per_s']:>12.0f} {r['physics_steps_per_s']:>16.0f} "
              f"{r['physics_steps_per_s'] / c_rate:>20.0%}")
    print(f"MuJoCo C single-thread (mujoco.rollout): {c_rate:.0f} physics steps/s")
    if args.compare_solver:
        it, ls = args.compare_solver
        other = hexa_mjx.make_env(ctrl_hz=args.ctrl_hz, solver_iterations=it, ls_iterations=ls)
        r = mjx_speed(other, args.batches[-1], args.steps, args.repeats)
        print(f"solver iterations={it} ls_iterations={ls}: {r['physics_steps_per_s']:.0f} physics steps/s "
              f"at {args.batches[-1]} envs ({r['physics_steps_per_s'] / c_rate:.0%} of MuJoCo C 1-thread)")
    if args.train:
        r = train_speed(args.batches[-1])
        env_only = mjx_speed(env, args.batches[-1], args.steps, args.repeats)["env_steps_per_s"]
        print(f"PPO training at {args.batches[-1]} envs: {r['train_steps_per_s']:.0f} env steps/s after "
              f"{r['compile_s']:.0f} s of compiling; environment alone {env_only:.0f} env steps/s: the learner adds "
              f"{env_only / r['train_steps_per_s'] - 1:.0%} to the physics time")
    for steps in (15, 60):
        pos, joint = solver_error(env, steps)
        print(f"solver accuracy after {steps * env.dt:.2f} s of a gait: torso {pos * 1000:.1f} mm, joints {joint:.3f} rad "
              f"from iterations={robot.TIGHT_SOLVER['iterations']}, ls_iterations={robot.TIGHT_SOLVER['ls_iterations']}")


if __name__ == "__main__":
    main()
