"""Reading the actor's action-noise std from a run's checkpoints."""

import dataclasses
import json

import jax
import numpy as np
import pytest

from hexa_mjx.evaluation import action_noise
from hexa_mjx.training import checkpoints, config, networks


def test_run_noise_reads_each_checkpoints_std(tmp_path, capsys):
    cfg = config.TrainConfig(hidden=[8, 8], init_noise_std=0.4)
    (tmp_path / "config.json").write_text(json.dumps(dataclasses.asdict(cfg)))
    normalizer, policy, value = networks.init_params(cfg, config.make_env_for(cfg))
    checkpoints.save_checkpoint(tmp_path, 100, (normalizer, policy, value))
    # A later checkpoint whose std PPO has moved: half of each joint's at the start.
    moved = jax.tree_util.tree_map_with_path(
        lambda path, x: x + np.log(0.5) if "std_logparam" in jax.tree_util.keystr(path) else x, policy)
    checkpoints.save_checkpoint(tmp_path, 200, (normalizer, moved, value))
    rows = action_noise.run_noise(tmp_path)
    assert [step for step, _ in rows] == [100, 200]
    np.testing.assert_allclose([std for _, std in rows], [0.4, 0.2], rtol=1e-5)
    assert action_noise.main([str(tmp_path)]) == 0
    assert "0.00M 0.400  0.00M 0.200" in capsys.readouterr().out


def test_bad_input(tmp_path):
    assert action_noise.main([str(tmp_path)]) == 2  # no config.json
    cfg = config.TrainConfig(hidden=[8, 8], policy_dist="tanh_normal")
    with pytest.raises(ValueError, match="depends on the state"):
        action_noise.action_noise_std(networks.init_params(cfg, config.make_env_for(cfg)))
