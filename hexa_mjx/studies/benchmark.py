"""Environment speed: MJX batched env/physics steps per second beside MuJoCo C.

    python -m hexa_mjx.studies.benchmark [--batches 64 256 1024] [--steps 100] [--repeats 3] [--compare_solver 4 8]
                                 [--profile] [--train] [--max_contact_points N] [--compare_contacts N ...]
                                 [--compare_terrain KIND ...] [--compare_randomize]

Prints compile time, then for each batch size the median over repeats of env
steps/s and physics steps/s (env steps x substeps) under random actions, then
MuJoCo C's single-thread physics steps/s on the same model (mujoco.rollout) and
the MJX/C ratio. Everything is measured in one run, side by side. --profile splits
one PPO update into its parts; --train times end-to-end PPO beside the environment
alone, on one device and on one CPU device per core. --compare_contacts times
MJX contact caps (`EnvConfig.max_contact_points`) in turns with the model's setting,
--compare_terrain heightfields against the flat floor, --compare_randomize a randomized
model per environment against the nominal one.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import mujoco
import numpy as np
from mujoco import rollout

import hexa_mjx
from hexa_mjx.training import jax_setup
from hexa_mjx.mdp import randomization, terrain
from hexa_mjx.robot import constants as robot
from hexa_mjx.engines import wrappers


def rollout_fn(batched_step, action_size: int, steps: int):
    """A jitted rollout of `steps` control steps of a batched step function under uniform random actions."""
    def run(state, rng):
        def body(carry, _):
            state, rng = carry
            rng, key = jax.random.split(rng)
            action = jax.random.uniform(key, (state.obs.shape[0], action_size), minval=-1, maxval=1)
            return (batched_step(state, action), rng), None
        (state, _), _ = jax.lax.scan(body, (state, rng), None, length=steps)
        return state
    return jax.jit(run)


def timed(fn, args, repeats):
    """(compile s, median run s, output) of a jitted function."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    compile_s, times = time.perf_counter() - t0, []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return compile_s, statistics.median(times), out


def mjx_speed(env, batch: int, steps: int, repeats: int) -> dict:
    """Compile time and median env steps/s for one batch size."""
    compile_s, env_rate = compare_speed({"env": env}, batch, steps, repeats)["env"]
    return {"batch": batch, "compile_s": compile_s, "env_steps_per_s": env_rate,
            "physics_steps_per_s": env_rate * env.n_substeps}


def randomized(env):
    """A batch factory for `compare_speed`: `env` with its own randomized physics model per
    environment (train.py --randomize's ranges and wrapper)."""
    def batched(batch: int):
        draw = randomization.randomization_fn(env, randomization.Ranges())
        return wrappers.RandomizedVmap(env, lambda model: draw(model, jax.random.split(jax.random.PRNGKey(3), batch)))
    batched.action_size = env.action_size
    return batched


def compare_speed(envs: dict, batch: int, steps: int, repeats: int) -> dict:
    """(compile s, median env steps/s) of each named env (or batch factory, `randomized`) at one
    batch size, timed in turns (one rollout of each per round) so that a noisy, shared machine
    slows them alike."""
    runs, compile_s, rates = {}, {}, {name: [] for name in envs}
    for name, env in envs.items():
        step, reset = ((jax.vmap(env.step), jax.vmap(env.reset)) if hasattr(env, "step")
                       else (lambda b: (b.step, b.reset))(env(batch)))
        run = rollout_fn(step, env.action_size, steps)
        state = jax.jit(reset)(jax.random.split(jax.random.PRNGKey(0), batch))
        t0 = time.perf_counter()
        runs[name] = (run, jax.block_until_ready(run(state, jax.random.PRNGKey(1))))
        compile_s[name] = time.perf_counter() - t0
    for r in range(repeats):
        for name, (run, state) in runs.items():
            t0 = time.perf_counter()
            runs[name] = (run, jax.block_until_ready(run(state, jax.random.PRNGKey(2 + r))))
            rates[name].append(batch * steps / (time.perf_counter() - t0))
    return {name: (compile_s[name], statistics.median(r)) for name, r in rates.items()}


def pmap_speed(env, batch: int, steps: int, repeats: int, devices: int) -> float:
    """Median env steps/s with the batch split over `devices` devices (pmap), as PPO splits it."""
    reset = jax.pmap(jax.vmap(env.reset))
    run = jax.pmap(rollout_fn(jax.vmap(env.step), env.action_size, steps))
    state = reset(jax.random.split(jax.random.PRNGKey(0), batch).reshape(devices, batch // devices, -1))
    keys = jax.random.split(jax.random.PRNGKey(1), devices)
    return batch * steps / timed(run, (state, keys), repeats)[1]


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
    data.qpos[:], data.qvel[:] = env.qpos0, env.qvel0
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


# The command line top to bottom: one section per measurement it can print.
def main(argv=None) -> None:
    from hexa_mjx.studies import training_speed  # it times with this module's helpers

    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.studies.benchmark", description=__doc__.split("\n\n")[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[64, 256, 1024], help="numbers of environments")
    parser.add_argument("--steps", type=int, default=100, help="control steps per timed rollout")
    parser.add_argument("--repeats", type=int, default=3, help="timed rollouts per batch size (median reported)")
    parser.add_argument("--ctrl_hz", type=float, default=60.0, help="control rate, Hz")
    parser.add_argument("--train", action="store_true",
                        help="also time end-to-end PPO training (train.py defaults) at the largest batch, "
                             "on one device and on one CPU device per core")
    parser.add_argument("--profile", action="store_true",
                        help="also split one PPO update (largest batch, one device) into physics, contacts, "
                             "policy inference and SGD")
    parser.add_argument("--compare_solver", type=int, nargs=2, metavar=("ITERATIONS", "LS_ITERATIONS"),
                        help="also time this solver setting at the largest batch, beside the model's own")
    parser.add_argument("--max_contact_points", type=int, default=0,
                        help="contact points MJX keeps per step, for every measurement (0: all the model's slots)")
    parser.add_argument("--compare_contacts", type=int, nargs="+", metavar="N",
                        help="also time these max_contact_points at the largest batch, in turns with the setting above")
    parser.add_argument("--compare_terrain", nargs="+", metavar="KIND",
                        choices=[kind for kind in terrain.KINDS if kind != "flat"],
                        help="also time these terrains at the largest batch, in turns with the flat floor")
    parser.add_argument("--compare_randomize", action="store_true",
                        help="also time randomized physics (one model per environment) at the largest batch, in "
                             "turns with the nominal model")
    args = parser.parse_args(argv)

    jax_setup.prepare_jax()  # as train.py does; single-device timings use one of the CPU devices
    cap = {"max_contact_points": args.max_contact_points}
    env = hexa_mjx.make_env(ctrl_hz=args.ctrl_hz, **cap)
    m = env.mj_model
    print(f"model: {env.config.model_path}  nv={m.nv} nu={m.nu} ngeom={m.ngeom} "
          f"contact slots={env.contact_slots} "
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
        other = hexa_mjx.make_env(ctrl_hz=args.ctrl_hz, solver_iterations=it, ls_iterations=ls, **cap)
        r = mjx_speed(other, args.batches[-1], args.steps, args.repeats)
        print(f"solver iterations={it} ls_iterations={ls}: {r['physics_steps_per_s']:.0f} physics steps/s "
              f"at {args.batches[-1]} envs ({r['physics_steps_per_s'] / c_rate:.0%} of MuJoCo C 1-thread)")
    if args.compare_contacts:
        envs = {n: hexa_mjx.make_env(ctrl_hz=args.ctrl_hz, max_contact_points=n)
                for n in [args.max_contact_points, *args.compare_contacts]}
        rates = compare_speed(envs, args.batches[-1], args.steps, args.repeats)
        base = rates[args.max_contact_points][1]
        print(f"contact points kept, env steps/s at {args.batches[-1]} envs (timed in turns, median of {args.repeats}):")
        for n, (_, rate) in rates.items():
            print(f"  max_contact_points={n:<3} ({envs[n].contact_slots} slots) {rate:8.0f}  {rate / base:5.2f}x")
    if args.compare_randomize:
        rates = compare_speed({"nominal": env, "randomized": randomized(env)}, args.batches[-1], args.steps,
                              args.repeats)
        base = rates["nominal"][1]
        print(f"domain randomization, env steps/s at {args.batches[-1]} envs (timed in turns, median of {args.repeats}):")
        for name, (compile_s, rate) in rates.items():
            print(f"  {name:<10} {rate:8.0f}  {rate / base:5.2f}x  compile {compile_s:.0f} s")
    if args.compare_terrain:
        envs = {kind: hexa_mjx.make_env(ctrl_hz=args.ctrl_hz, terrain=kind, **cap)
                for kind in ["flat", *args.compare_terrain]}
        rates = compare_speed(envs, args.batches[-1], args.steps, args.repeats)
        base = rates["flat"][1]
        print(f"terrain, env steps/s at {args.batches[-1]} envs (timed in turns, median of {args.repeats}):")
        for kind, (compile_s, rate) in rates.items():
            print(f"  {kind:<7} ({envs[kind].contact_slots} contact slots) {rate:8.0f}  {rate / base:5.2f}x  "
                  f"compile {compile_s:.0f} s")
    if args.profile:
        p = training_speed.training_profile(args.batches[-1], args.repeats, **cap)
        parts = {"physics without contacts": p["env_without_contacts"], "contacts": p["env"] - p["env_without_contacts"],
                 "policy inference": p["acting"] - p["env"], "SGD (epochs x minibatches)": p["sgd"]}
        total = p["acting"] + p["sgd"]
        print(f"one PPO update at {args.batches[-1]} envs on one device, parts timed alone (median of {args.repeats}):")
        for name, sec in parts.items():
            print(f"  {name:<28} {sec * 1000:7.0f} ms  {sec / total:5.0%}")
        print(f"  learner (policy + SGD) adds {(total - p['env']) / p['env']:.0%} to the environment time")
        print(f"  SGD: {p['sgd_flop'] / 1e9:.0f} GFLOP per update in dense layers = "
              f"{p['sgd_flop'] / p['sgd'] / 1e9:.0f} GFLOP/s; a matmul chain of one minibatch's shape runs at "
              f"{p['matmul_flop_per_s'] / 1e9:.0f} GFLOP/s here")
    if args.train:
        cores = jax.local_device_count()
        env_rates = {1: mjx_speed(env, args.batches[-1], args.steps, args.repeats)["env_steps_per_s"]}
        if cores > 1:
            env_rates[cores] = pmap_speed(env, args.batches[-1], args.steps, args.repeats, cores)
        for devices, env_rate in env_rates.items():
            r = training_speed.train_speed(args.batches[-1], devices=devices, **cap)
            print(f"PPO training at {args.batches[-1]} envs on {devices} device(s): {r['train_steps_per_s']:.0f} "
                  f"env steps/s after {r['compile_s']:.0f} s of compiling; environment alone {env_rate:.0f} env "
                  f"steps/s: the learner adds {env_rate / r['train_steps_per_s'] - 1:.0%} to the environment time")
    for steps in (15, 60):
        pos, joint = solver_error(env, steps)
        print(f"solver accuracy after {steps * env.dt:.2f} s of a gait: torso {pos * 1000:.1f} mm, joints {joint:.3f} rad "
              f"from iterations={robot.TIGHT_SOLVER['iterations']}, ls_iterations={robot.TIGHT_SOLVER['ls_iterations']}")


if __name__ == "__main__":
    main()
