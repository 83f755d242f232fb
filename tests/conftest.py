import pytest

import rmbench


@pytest.fixture(params=sorted(rmbench.TASKS))
def task_name(request):
    return request.param


def run_expert_steps(env, expert, seed, steps):
    """Roll the expert for ``steps`` steps; return observations and actions."""
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    observations, actions = [obs], []
    for _ in range(steps):
        action = expert.act(obs)
        obs, _, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        actions.append(action)
        if terminated or truncated:
            break
    return observations, actions
