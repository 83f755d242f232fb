"""Batched evaluation: several episodes side by side in one worker, the policy asked once per
step for all of them; records as one at a time gives them, whatever shares the batch."""

import numpy as np
import pytest

from rmbench.envs.registration import make
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.episode import run_policy_episode, run_policy_episodes
from rmbench.eval.probe import MemoryReset
from rmbench.eval.records import read_records
from rmbench.policies import BasePolicy, register_policy
from rmbench.policies.mem0.agent import Mem0Policy
from tests.conftest import DATA_TASK as TASK
from tests.conftest import keep_exports
from tests.test_mem0 import TINY_STATE, train_tiny

STATE = "environment_state_agent_pos"


class Scripted(BasePolicy):
    """Holds still, in chunks of a seed-dependent length; by seed, a NaN or a wrong shape at
    a seed-dependent step ends its episode early, or it runs to the step limit."""

    def reset(self, instruction, task_info):
        self.seed, self.t = task_info["seed"], 0

    def act(self, observation):
        self.t += 1
        if self.seed % 3 == 0 and self.t == 5 + self.seed % 7:
            return np.full(14, np.nan)
        if self.seed % 3 == 1 and self.t == 9 + self.seed % 5:
            return np.zeros(7)
        return np.repeat(np.asarray(observation["agent_pos"])[None], 1 + self.seed % 3, 0)

    def status(self):
        return {"calls": self.t // 4}


class ScriptedBatch(BasePolicy):
    """Scripted with the batched form: one Scripted per slot."""

    def __init__(self):
        self.slots = {}
        self.asked = []  # how many slots each act_batch call held

    def reset_batch(self, slot, instruction, task_info, env=None):
        self.slots[slot] = Scripted()
        self.slots[slot].reset(instruction, task_info)

    def act_batch(self, observations):
        self.asked.append(len(observations))
        return [None if o is None else self.slots[i].act(o) for i, o in enumerate(observations)]

    def status_batch(self, slot):
        return self.slots[slot].status()


register_policy("test_scripted", "holds still; NaN or wrong shape by seed", cameras=())(
    lambda arg, env: Scripted())
register_policy("test_scripted_batch", "test_scripted with act_batch", cameras=())(
    lambda arg, env: ScriptedBatch())


def run(tmp_path, name, policy, **kw):
    args = {"episodes": 6, "seed_cache": tmp_path / "seeds", "progress": False,
            "video": "none", **kw}
    summary = evaluate(EvalConfig((TASK,), policy, tmp_path / name, **args))
    return summary, read_records(tmp_path / name / TASK / "episodes.jsonl")


def strip(records):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in records]


def test_batched_and_one_at_a_time_give_the_same_records(tmp_path):
    one, plain = run(tmp_path, "one", "test_scripted", batch=1, video="first:2")
    # a policy without the batched form runs through the batched harness one at a time
    fallback, unbatched = run(tmp_path, "fallback", "test_scripted", batch=4, video="first:2")
    both, batched = run(tmp_path, "both", "test_scripted_batch", batch=4, video="first:2")
    assert strip(plain) == strip(unbatched) == strip(batched)
    assert one["tasks"] == fallback["tasks"] == both["tasks"]
    # episodes of different lengths and endings shared the batch; records in seed order
    assert len({r["steps"] for r in batched}) >= 3
    assert {r["reason"] for r in batched} >= {"policy_error", "timeout"}
    assert [r["seed"] for r in batched] == sorted(r["seed"] for r in batched)
    assert any("NaN" in r["message"] for r in batched)
    assert any("shape" in r["message"] for r in batched)
    assert [r["video"] is not None for r in batched] == [True, True] + [False] * 4
    assert any(e[1] == "policy" for e in batched[-1]["events"])  # status_batch recorded


def test_memory_probe_batched_as_one_at_a_time():
    probe = MemoryReset.parse("every:6")
    seeds = [100000, 100001, 100002, 100004, 100005]
    envs = [make(TASK, render=False, obs_type=STATE, step_limit=40) for _ in range(3)]
    try:
        batched = run_policy_episodes(envs, ScriptedBatch(), seeds, memory_reset=probe)
        alone = [run_policy_episode(envs[0], Scripted(), s, memory_reset=probe) for s in seeds]
    finally:
        for env in envs:
            env.close()
    assert strip(batched) == strip(alone)
    assert any(r["memory_resets"] for r in batched)


def test_a_slot_plays_its_seeds_in_turn_and_the_policy_sees_one_batch_size():
    policy = ScriptedBatch()
    envs = [make(TASK, render=False, obs_type=STATE, step_limit=40) for _ in range(2)]
    try:
        # slot 0 plays 100000 and 100002, slot 1 100001 and 100003: 100000 ends early (a
        # wrong shape) and 100002 follows it while 100001 runs to the limit
        records = run_policy_episodes(envs, policy, [100000, 100001, 100002, 100003], slots=4)
    finally:
        for env in envs:
            env.close()
    assert [r["seed"] for r in records] == [100000, 100001, 100002, 100003]
    assert [r["reason"] for r in records] == ["policy_error", "timeout", "policy_error",
                                              "policy_error"]
    assert records[1]["steps"] == 40 and records[0]["steps"] + records[2]["steps"] < 40
    assert set(policy.asked) == {4}  # two slots idle throughout, still four entries


def test_resume_mid_batch_keeps_every_record_and_runs_the_rest(tmp_path):
    _, full = run(tmp_path, "a", "test_scripted_batch", batch=4)
    path = tmp_path / "a" / TASK / "episodes.jsonl"
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:3]) + lines[3][:25])  # killed inside the first batch
    _, again = run(tmp_path, "a", "test_scripted_batch", batch=4)
    assert strip(again) == strip(full) and len({r["seed"] for r in again}) == 6


def test_a_kill_mid_job_keeps_the_episodes_that_ended_and_the_rerun_is_the_same(tmp_path,
                                                                               monkeypatch):
    """A job of several batches run in this process keeps its records as its episodes end (in
    the order a whole job writes them), so a run killed mid-job loses only the episodes still
    playing; the re-run plays them and gives the uninterrupted run's records."""
    import rmbench.eval.episode as episode

    _, full = run(tmp_path, "whole", "test_scripted_batch", batch=2, episodes=8)
    real, resets = episode._Episode.reset_policy, []

    def killed_at_the_seventh_reset(self, policy, slot):
        if isinstance(policy, ScriptedBatch):  # (not the seed search's expert)
            resets.append(self.seed)
            if len(resets) == 7:
                raise KeyboardInterrupt
        real(self, policy, slot)

    monkeypatch.setattr(episode._Episode, "reset_policy", killed_at_the_seventh_reset)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path, "killed", "test_scripted_batch", batch=2, episodes=8)
    kept = read_records(tmp_path / "killed" / TASK / "episodes.jsonl")
    assert 0 < len(kept) < 8 and strip(kept) == strip(full)[:len(kept)]  # one job of 8 seeds
    monkeypatch.setattr(episode._Episode, "reset_policy", real)
    _, again = run(tmp_path, "killed", "test_scripted_batch", batch=2, episodes=8)
    assert strip(again) == strip(full)


# ---------------------------------------------------------------------------- Mem-0
@pytest.fixture(scope="module")
def state_ckpt(mn_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("ckpt") / "state"
    with keep_exports():
        train_tiny(mn_dataset, out, cfg=TINY_STATE)
    return out


def observations(seed, steps=12):
    """A state episode of press_button under small joint moves: the observations."""
    env = make("press_button", obs_type=STATE)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    rng = np.random.default_rng(seed)
    for _ in range(steps - 1):
        obs, *_ = env.step(np.asarray(obs["agent_pos"]) + rng.normal(0, 0.05, 14))
        out.append(obs)
    env.close()
    return out


def batched_actions(policy, slots):
    """Slot i plays ``slots[i]`` = (seed, observations) or None (idle); each slot's actions."""
    for i, s in enumerate(slots):
        if s is not None:
            policy.reset_batch(i, "", {"seed": s[0]})
    steps = max(len(s[1]) for s in slots if s is not None)
    out = [[] for _ in slots]
    for t in range(steps):
        answers = policy.act_batch([s[1][t] if s is not None and t < len(s[1]) else None
                                    for s in slots])
        for i, a in enumerate(answers):
            if a is not None:
                out[i].append(a)
    return [np.stack(a) if a else None for a in out]


def test_mem0_slot_results_do_not_depend_on_the_other_slots(state_ckpt):
    # the end classifier's path (no gt_classifier) and sampling noise both run
    policy = Mem0Policy(f"{state_ckpt}?sample_noise=1.0")
    episodes = {s: observations(s) for s in (100000, 100001, 100002, 100003)}
    mine = (100000, episodes[100000])
    others = [(s, episodes[s]) for s in (100001, 100002, 100003)]
    # in one slot, whatever the others hold: other episodes, one that ends early, none
    a = batched_actions(policy, [mine, *others])[0]
    b = batched_actions(policy, [mine, None, (100001, episodes[100001][:5]), others[2]])[0]
    c = batched_actions(policy, [mine, None, None, None])[0]
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    e = batched_actions(policy, [others[2], None, mine, None])[2]
    np.testing.assert_array_equal(e, batched_actions(policy, [None, others[0], mine, None])[2])
    # one episode alone (reset/act: a batch of one) agrees to float tolerance
    policy.reset("", {"seed": 100000})
    alone = np.stack([policy.act(o) for o in episodes[100000]])
    np.testing.assert_allclose(alone, a, rtol=1e-4, atol=1e-5)
    # each slot's own noise: two slots on the same observations but other seeds differ
    d = batched_actions(policy, [mine, (100005, episodes[100000]), None, None])
    assert not np.array_equal(d[0], d[1])
    np.testing.assert_array_equal(d[0], a)


def test_mem0_record_does_not_depend_on_its_batch(state_ckpt):
    spec = f"mem0:{state_ckpt}"
    from rmbench.policies.registry import make_policy

    def records(seeds, positions):
        envs = [make("press_button", obs_type=STATE, step_limit=60) for _ in range(4)]
        try:
            policy = make_policy(spec, envs[0])
            return {r["seed"]: r for r in strip(run_policy_episodes(
                envs, policy, seeds, slots=4, positions=positions))}
        finally:
            for env in envs:
                env.close()

    # the seeds of a whole run, and two of them again in their places (a resumed run's rest)
    a = records([100000, 100001, 100002, 100003, 100004], [0, 1, 2, 3, 0])
    b = records([100002, 100004], [2, 0])
    assert a[100004] == b[100004] and a[100002] == b[100002]
    assert all(r["reason"] != "policy_error" for r in a.values()), a


# ------------------------------------------------------------------------- DP and ACT
@pytest.mark.parametrize("name", ["dp", "act"])
def test_baseline_slot_results_do_not_depend_on_the_other_slots(name):
    """DP and ACT in slots, as Mem-0: a slot's actions whatever its neighbours (DP's noise
    from each slot's own generator), and one episode alone to float tolerance."""
    from dataclasses import replace

    import torch

    from rmbench.tasks import get_task
    from tests.test_baselines import BASELINES

    base, _, policy_cls = BASELINES[name]
    torch.manual_seed(0)
    cfg = replace(base, observation="state", obs_steps=2 if name == "dp" else 1,
                  **({"temporal_ensemble": 0.1} if name == "act" else {}))
    model = policy_cls.model_cls(cfg, len(get_task("press_button").state_names))
    policy = policy_cls.from_model(model)
    episodes = {s: observations(s, steps=10) for s in (100000, 100001, 100002)}
    mine = (100000, episodes[100000])
    others = [(s, episodes[s]) for s in (100001, 100002)]
    # in one slot, whatever the others hold: other episodes, one that ends early, none
    a = batched_actions(policy, [mine, *others])[0]
    b = batched_actions(policy, [mine, (100001, episodes[100001][:3]), None])[0]
    c = batched_actions(policy, [mine, None, None])[0]
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    e = batched_actions(policy, [others[1], None, mine])[2]
    np.testing.assert_array_equal(e, batched_actions(policy, [None, others[0], mine])[2])
    policy.reset("", {"seed": 100000})
    alone = np.stack([policy.act(o) for o in episodes[100000]])
    np.testing.assert_allclose(alone, a, rtol=1e-4, atol=1e-5)
    if name == "dp":  # each slot's own noise
        d = batched_actions(policy, [mine, (100005, episodes[100000]), None])
        assert not np.array_equal(d[0], d[1])
        np.testing.assert_array_equal(d[0], a)


def test_jobs_split_the_seeds_evenly_over_the_workers(tmp_path):
    from concurrent.futures import Future

    from rmbench.eval.harness import JOB_BATCHES, job_count

    class Batched:  # an executor whose policy has the batched form
        def submit(self, *args):
            done = Future()
            done.set_result(True)
            return done

    for workers, batch, todo, want in ((1, 8, 100, 4), (2, 8, 100, 4), (2, 8, 99, 4),
                                       (2, 8, 10, 2), (3, 4, 7, 3), (16, 8, 100, 16),
                                       (4, 8, 3, 3)):
        cfg = EvalConfig((TASK,), "random", tmp_path, workers=workers, batch=batch)
        n = job_count(cfg, TASK, todo, Batched())
        sizes = [(k + 1) * todo // n - k * todo // n for k in range(n)]
        assert n == want and sum(sizes) == todo and max(sizes) - min(sizes) <= 1
        assert max(sizes) <= JOB_BATCHES * batch
