"""Export a trained policy to ONNX: normalizer folded in, deterministic action in [-1, 1] out.

    python -m hexa_mjx.deploy.export runs/goal_directed-s0 -o policy.onnx
    python -m hexa_mjx.deploy.export --show policy.onnx

The graph is built with onnx's own helpers from the checkpoint's arrays (the actor is a plain
MLP). Everything a deployer needs (observation layout and units, joint order, action-to-target
mapping, control rate, task and environment settings, the model file's hash) is stored in the
file's metadata under "hexa_mjx" and in a JSON file beside it.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from hexa_mjx.robot import constants as robot
from hexa_mjx import atomic

METADATA_KEY = "hexa_mjx"
FORMAT = 1  # bumped when the metadata's meaning changes
OPSET = 17
IR_VERSION = 8  # readable by onnxruntime releases back to 1.10


def policy_arrays(policy_dist: str, params) -> dict:
    """NumPy arrays of the deterministic actor: normalizer mean and std, [(kernel, bias)] of every
    layer (tanh between them), and whether the output is squashed by tanh (brax's tanh_normal)."""
    normalizer, policy = params[0], params[1]["params"]

    def by_index(tree):
        return [tree[name] for name in sorted(tree, key=lambda name: int(name.split("_")[-1]))]

    if "MLP_0" in policy:  # brax's "normal" actor: an MLP, then a mean layer (the std is a parameter)
        layers = [(l["kernel"], l["bias"]) for l in by_index(policy["MLP_0"]) + [policy["Dense_0"]]]
    else:  # "tanh_normal": one MLP whose last layer outputs (loc, scale); the mode is tanh(loc)
        layers = [(l["kernel"], l["bias"]) for l in by_index(policy)]
        kernel, bias = layers[-1]
        half = kernel.shape[1] // 2
        layers[-1] = (kernel[:, :half], bias[:half])
    return {"mean": np.asarray(normalizer.mean, np.float32), "std": np.asarray(normalizer.std, np.float32),
            "layers": [(np.asarray(k, np.float32), np.asarray(b, np.float32)) for k, b in layers],
            "squash": policy_dist == "tanh_normal"}


def onnx_model(arrays: dict, metadata: dict):
    """The ONNX graph obs (batch, n) -> action (batch, m) of `policy_arrays`, with `metadata`."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    inits = [numpy_helper.from_array(arrays["mean"], "obs_mean"), numpy_helper.from_array(arrays["std"], "obs_std"),
             numpy_helper.from_array(np.array(-1.0, np.float32), "lo"),
             numpy_helper.from_array(np.array(1.0, np.float32), "hi")]
    nodes = [helper.make_node("Sub", ["obs", "obs_mean"], ["centred"]),
             helper.make_node("Div", ["centred", "obs_std"], ["x0"])]
    x, last = "x0", len(arrays["layers"]) - 1
    for i, (kernel, bias) in enumerate(arrays["layers"]):
        inits += [numpy_helper.from_array(kernel, f"kernel_{i}"), numpy_helper.from_array(bias, f"bias_{i}")]
        nodes += [helper.make_node("MatMul", [x, f"kernel_{i}"], [f"matmul_{i}"]),
                  helper.make_node("Add", [f"matmul_{i}", f"bias_{i}"], [f"pre_{i}"])]
        x = f"pre_{i}"
        if i < last or arrays["squash"]:
            nodes.append(helper.make_node("Tanh", [x], [f"act_{i}"]))
            x = f"act_{i}"
    nodes.append(helper.make_node("Clip", [x, "lo", "hi"], ["action"]))  # the env clips to [-1, 1] too
    n_obs, n_act = arrays["layers"][0][0].shape[0], arrays["layers"][-1][0].shape[1]
    graph = helper.make_graph(
        nodes, "hexa_mjx_policy",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", n_obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", n_act])], inits)
    model = helper.make_model(graph, producer_name="hexa_mjx", opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = IR_VERSION
    helper.set_model_props(model, {METADATA_KEY: json.dumps(metadata)})
    onnx.checker.check_model(model, full_check=True)
    return model


def deployment_metadata(env, cfg, step: int, source: str) -> dict:
    """What a deployer needs to run the policy: docs/DEPLOYMENT.md, "Export"."""
    model = env.mj_model
    env_config = dataclasses.asdict(env.config)
    env_config.pop("model_path")
    env_config.update(env.task.deployment_settings())
    model_path = Path(env.config.model_path)
    return {
        "format": FORMAT,
        "task": env.config.task,
        "observation_size": env.observation_size,
        "observation_layout": [dict(start=a, end=b, what=w, units=u) for a, b, w, u in env.task.layout(model.nu)],
        "action_size": env.action_size,
        "joint_order": env.robot.actuator_joints,
        "action_mapping": {
            "target_rad": "ctrl_lo + (clip(action, -1, 1) + 1) / 2 * (ctrl_hi - ctrl_lo)",
            "ctrl_lo": model.actuator_ctrlrange[:, 0].round(6).tolist(),
            "ctrl_hi": model.actuator_ctrlrange[:, 1].round(6).tolist(),
            "servo": {"kp_Nm_per_rad": robot.KP, "torque_limit_Nm": robot.TORQUE_LIMIT,
                      "damping_Nms_per_rad": robot.JOINT_DAMPING},
        },
        "control_hz": env.config.ctrl_hz,
        "physics_dt_s": float(model.opt.timestep),
        "env_config": env_config,
        **({"command": env.task.command_fields()} if env.task.uses_command else {}),
        "model": {"file": model_path.name, "sha256": hashlib.sha256(model_path.read_bytes()).hexdigest()},
        "trained": {"step": step, "source": source, "train_config": dataclasses.asdict(cfg)},
    }


def read_metadata(path: Path) -> dict:
    """The "hexa_mjx" metadata of an exported ONNX file (onnx only, no runtime)."""
    import onnx

    path = Path(path)
    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as e:
        raise ValueError(f"{path} is not a readable ONNX file ({type(e).__name__}: {str(e)[:120]})") from e
    if METADATA_KEY not in {p.key for p in model.metadata_props}:
        raise ValueError(f"{path} has no hexa_mjx metadata: export it with `python -m hexa_mjx.deploy.export RUN -o FILE`")
    return metadata_of(model)


def metadata_of(model) -> dict:
    """The "hexa_mjx" metadata of an ONNX ModelProto."""
    return json.loads({p.key: p.value for p in model.metadata_props}[METADATA_KEY])


def export(ckpt: str | Path, out: str | Path) -> Path:
    """Write the ONNX file (and `<out>.json` metadata) of a run's latest checkpoint or one checkpoint."""
    from hexa_mjx.training import checkpoints, config, critic, networks

    out = Path(out)
    if out.suffix != ".onnx" or out.is_dir():
        raise ValueError(f"-o must name a .onnx file, got {out}")
    config.writable_folder(out.parent, "-o's folder")  # before anything loads: a clear line, no temporary left
    run_dir, ckpt_dir = checkpoints.resolve_checkpoint(Path(ckpt))
    cfg = config.load_config(run_dir)
    env = config.make_env_for(cfg)
    step, params = checkpoints.load_checkpoint(ckpt_dir, networks.init_params(cfg, env))
    model = onnx_model(policy_arrays(cfg.policy_dist, critic.actor_params(params)),
                       deployment_metadata(env, cfg, step, str(ckpt_dir)))
    atomic.write(out, model.SerializeToString())
    atomic.write(out.with_suffix(".json"), json.dumps(metadata_of(model), indent=1))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hexa_mjx.deploy.export", description=__doc__.split("\n\n")[0])
    parser.add_argument("ckpt", help="run directory (its latest checkpoint) or checkpoint folder; with --show, an ONNX file")
    parser.add_argument("-o", "--out", default="policy.onnx", help="ONNX file to write (and .json beside it)")
    parser.add_argument("--show", action="store_true", help="print an exported file's metadata")
    args = parser.parse_args(argv)
    try:
        if args.show:
            print(json.dumps(read_metadata(Path(args.ckpt)), indent=1))
            return 0
        from hexa_mjx.training import jax_setup

        jax_setup.prepare_jax()
        path = export(args.ckpt, args.out)
    except (FileNotFoundError, ValueError, RuntimeError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    meta = read_metadata(path)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB) and {path.with_suffix('.json')}: {meta['task']} "
          f"policy, {meta['observation_size']} observations -> {meta['action_size']} actions at "
          f"{meta['control_hz']:g} Hz, step {meta['trained']['step']:,}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
