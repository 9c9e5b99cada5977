"""A training run's evaluations run brax's episodes: the same figures as brax's own evaluator,
from the same key, on randomized physics (one model per episode), evaluation after evaluation."""

import functools

import jax
import numpy as np
import pytest

from hexa_mjx.evaluation.run_evaluator import RunEvaluator, brax_eval_key
from hexa_mjx.mdp import randomization
from hexa_mjx.training import config, loop, networks

EPISODES, LENGTH, SEED = 2, 20, 3


@pytest.fixture(scope="module")
def setup():
    cfg = config.TrainConfig(hidden=[16, 16], episode_length=LENGTH, num_eval_envs=EPISODES, randomize=True,
                             start_joint_noise=0.1)
    env = config.make_env_for(cfg)
    params = networks.init_params(cfg, env)
    # Params a little away from the fresh ones, so that the policy's actions differ between observations.
    params = jax.tree.map(lambda x: x + 0.05 * np.cos(np.arange(np.size(x)).reshape(np.shape(x))), params)
    return cfg, env, params


def brax_figures(cfg, env, params, calls: int) -> list[dict]:
    from brax.training import acting

    key = brax_eval_key(SEED)
    wrapped = loop.wrap_env_fn(env, randomized=True)(
        env, episode_length=LENGTH, action_repeat=1,
        randomization_fn=functools.partial(randomization.randomization_fn(env), rng=jax.random.split(key, EPISODES)))
    evaluator = acting.Evaluator(wrapped, functools.partial(networks.policy_maker(cfg, env), deterministic=True),
                                 num_eval_envs=EPISODES, episode_length=LENGTH, action_repeat=1, key=key)
    return [evaluator.run_evaluation(params, training_metrics={}) for _ in range(calls)]


def test_the_same_figures_as_brax_evaluator(setup):
    cfg, env, params = setup
    ours = RunEvaluator(env, loop.wrap_env_fn(env, randomized=True), randomization.randomization_fn(env),
                        networks.policy_maker(cfg, env), params, EPISODES, LENGTH, seed=SEED)
    mine = [ours(params) for _ in range(2)]
    theirs = brax_figures(cfg, env, params, 2)
    for a, b in zip(mine, theirs):
        for name in ("eval/episode_distance", "eval/episode_final_distance", "eval/avg_episode_length",
                     "eval/episode_reward/energy"):
            assert a[name] == pytest.approx(float(b[name]), rel=1e-4, abs=1e-5), name
        # The return nets terms that scale distances by 1000 (goal_approach): on some CPUs the two
        # batch layouts round the final position 6e-7 m apart, which is 1.0e-4 of a return of -7.
        assert a["eval/episode_reward"] == pytest.approx(float(b["eval/episode_reward"]), rel=1e-3)
    assert mine[0]["eval/episode_reward"] != pytest.approx(mine[1]["eval/episode_reward"], rel=1e-6)  # new episodes
    # An exact resume after one evaluation continues with the second one's key.
    resumed = RunEvaluator(env, loop.wrap_env_fn(env), None, networks.policy_maker(cfg, env), params, EPISODES, LENGTH,
                           seed=SEED, done=1)
    assert np.array_equal(resumed.key, jax.random.split(brax_eval_key(SEED))[0])
