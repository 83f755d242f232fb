"""The memory probe: a memoryless policy's episodes are unchanged by it, a policy is reset at
the aliasing step of every task, a chunk's rest is dropped, and it works through the server."""

import gymnasium as gym
import numpy as np
import pytest

import rmbench
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.episode import run_policy_episode
from rmbench.eval.probe import MemoryReset, ResetTrigger, compare
from rmbench.eval.records import read_records
from rmbench.eval.seeds import verified_seeds
from rmbench.policies import BasePolicy, make_policy, register_policy
from rmbench.serve.server import PolicyServer
from tests.conftest import load_script

TASK = "put_back_block"
STATE = {"render": False, "obs_type": "environment_state_agent_pos"}


def key(obs) -> bytes:
    """The observation's bytes: the state one's, or the arms' joints and the images."""
    scene = (obs["environment_state"].tobytes() if "environment_state" in obs else
             b"".join(obs["pixels"][c].tobytes() for c in sorted(obs["pixels"])))
    return scene + obs["agent_pos"].tobytes()


class Recorder(BasePolicy):
    """The expert, writing down which action it took for which observation."""

    def __init__(self, expert):
        self.expert, self.table = expert, {}

    def reset(self, instruction, task_info):
        self.expert.reset(instruction, task_info)

    def act(self, observation):
        action = np.asarray(self.expert.act(observation), dtype=np.float64)
        self.table[key(observation)] = action
        return action


class Lookup(BasePolicy):
    """Memoryless by construction: its action is a function of the current observation (the
    expert's recorded one for it), so it retraces the expert's episode with nothing carried
    from step to step. It counts its calls so a test can see where ``reset`` came."""

    def __init__(self, table, resets: list | None = None):
        # the log may be shared: a server may serve a copy of the policy it built
        self.table, self.acts, self.resets = table, 0, ([] if resets is None else resets)

    def reset(self, instruction, task_info):
        self.resets.append(self.acts)

    def act(self, observation):
        self.acts += 1
        return self.table[key(observation)]


def expert_table(seed: int, **options) -> dict:
    env = rmbench.make(TASK, **(options or STATE))
    try:
        rec = Recorder(make_policy("expert", env))
        assert run_policy_episode(env, rec, seed)["success"]
        return rec.table
    finally:
        env.close()


def strip(record: dict) -> dict:
    return {k: v for k, v in record.items() if k not in ("wall_s", "memory_resets")}


def test_probe_specs_are_checked():
    assert MemoryReset.parse("aliasing").every is None
    assert MemoryReset.parse("every:25").every == 25 and MemoryReset.parse("every:25").name == "every-25"
    for bad in ("every:0", "every:x", "sometimes", "every"):
        with pytest.raises(ValueError, match="memory reset must be"):
            MemoryReset.parse(bad)
    with pytest.raises(ValueError, match="memory reset must be"):
        EvalConfig((TASK,), "noop", "unused", memory_reset="every:-3")
    trigger = ResetTrigger(None, 2)
    assert [trigger.due(s, {"subtask_step": st}) for s, st in
            enumerate([0, 1, 2, 2, 3], 1)] == [False, False, True, False, False]


def test_a_memoryless_policy_runs_the_same_episode_under_the_probe(lookup):
    seed, _ = lookup
    table = SERVED["table"]
    env = rmbench.make(TASK, **STATE)
    try:
        plain = run_policy_episode(env, Lookup(table), seed)
        assert plain["success"] and "memory_resets" not in plain
        for spec in ("aliasing", "every:7"):
            policy = Lookup(table)
            probed = run_policy_episode(env, policy, seed, memory_reset=MemoryReset.parse(spec))
            assert strip(probed) == strip(plain), spec
            assert probed["memory_resets"] and policy.resets[1:] == probed["memory_resets"]
        assert probed["memory_resets"] == list(range(7, plain["steps"], 7))
    finally:
        env.close()


class StopAfterProbe(BasePolicy):
    """The expert until the probe resets it; then it says so and stops (the episode ends as a
    policy error: the rest of it is not what this test is about)."""

    def __init__(self, expert):
        self.expert, self.acts, self.resets = expert, 0, []

    def reset(self, instruction, task_info):
        self.resets.append(self.acts)
        if len(self.resets) == 1:
            self.expert.reset(instruction, task_info)

    def act(self, observation):
        if len(self.resets) > 1:
            raise RuntimeError("stopped after the probe")
        self.acts += 1
        return self.expert.act(observation)


class FixHidden(gym.Wrapper):
    """Every reset with the hidden variables fixed (an episode that reaches a given stage)."""

    def __init__(self, env, hidden):
        super().__init__(env)
        self.hidden = hidden

    def reset(self, **kw):
        return self.env.reset(**kw, options={"hidden": self.hidden})


def test_the_policy_is_reset_at_the_aliasing_step_of_every_task(task_name):
    env = rmbench.make(task_name, **STATE)
    cls = type(env.unwrapped.task)
    # the aliasing moment further into the plan: its hidden values make an episode that goes
    # past the aliasing stage before it ends (a lucky first try may end it before)
    hidden, _, _ = max(cls.aliasing_pairs[0], key=lambda m: m[1])
    env = FixHidden(env, hidden)
    try:
        stage = cls.aliasing_stage
        policy = StopAfterProbe(make_policy("expert", env))
        reached = []
        record = run_policy_episode(
            env, policy, 100000, memory_reset=MemoryReset.parse("aliasing"),
            on_step=lambda step, info: reached.append(step) if info["subtask_step"] >= stage
            else None)
        # reset once, right after the first step at which the task's stage reached it, and
        # before the policy was asked for the next action
        assert reached, f"the expert never reached {task_name}'s aliasing stage {stage}"
        assert record["memory_resets"] == [reached[0]] == policy.resets[1:]
        assert record["reason"] == "policy_error" and "stopped after the probe" in record["message"]
        assert record["steps"] == reached[0]
    finally:
        env.close()


class Chunks(BasePolicy):
    """Holds still in chunks of ten; remembers the steps at which it was asked."""

    def __init__(self):
        self.t, self.asked = 0, []

    def reset(self, instruction, task_info):
        pass

    def act(self, observation):
        self.asked.append(self.t)
        self.t += 10
        return np.repeat(observation["agent_pos"][None], 10, 0)


def test_the_rest_of_a_chunk_is_dropped_at_a_reset():
    env = rmbench.make(TASK, **STATE, step_limit=40)
    try:
        plain, probed = Chunks(), Chunks()
        run_policy_episode(env, plain, 100000)
        record = run_policy_episode(env, probed, 100000, memory_reset=MemoryReset.parse("every:4"))
        # without the probe each chunk runs out; with it, the policy is asked after each reset
        assert len(plain.asked) == 4 and len(probed.asked) == 10
        assert record["memory_resets"] == [4, 8, 12, 16, 20, 24, 28, 32, 36]
    finally:
        env.close()


SERVED: dict = {}
register_policy("test_lookup", "the expert's recorded actions by observation (memoryless)",
                cameras=(), obs_type=lambda arg: "environment_state_agent_pos")(
    lambda arg, env: Lookup(SERVED["table"], SERVED.setdefault("resets", [])))


@pytest.fixture(scope="module")
def lookup(tmp_path_factory):
    """``test_lookup`` on the first verified seed of the evaluation (and the seed cache)."""
    cache = tmp_path_factory.mktemp("seeds")
    seed = verified_seeds(TASK, 0, 1, cache, progress=False)[0]
    SERVED.clear()
    SERVED["table"] = expert_table(seed)
    return seed, cache


def test_an_evaluation_runs_the_probe_beside_the_plain_arm(lookup, tmp_path):
    seed, cache = lookup
    SERVED.pop("resets", None)
    common = {"episodes": 1, "video": "none", "progress": False, "seed_cache": cache}
    first = evaluate(EvalConfig((TASK,), "test_lookup", tmp_path / "out", **common))
    assert first["tasks"][TASK]["memory_reset"] == {}
    assert first["tasks"][TASK]["success_ci95"] == [0.2065, 1.0]  # Wilson's for 1 of 1
    # the probe is added to the folder already evaluated: only its arm runs
    summary = evaluate(EvalConfig((TASK,), "test_lookup", tmp_path / "out",
                                  memory_reset="aliasing", **common))
    probe = summary["tasks"][TASK]["memory_reset"]["aliasing"]
    assert probe["episodes"] == 1 and probe["reset_episodes"] == 1
    assert probe["without"]["successes"] == probe["with"]["successes"] == 1
    assert probe["drop"] == 0 and not probe["outside_noise"]
    plain = read_records(tmp_path / "out" / TASK / "episodes.jsonl")
    probed = read_records(tmp_path / "out" / TASK / "memory_reset-aliasing.jsonl")
    assert len(plain) == 1 and [strip(r) for r in probed] == [strip(r) for r in plain]
    # each evaluation builds its policy: reset at its episode's start, and the probed one again
    # after as many actions as the aliasing step counts
    assert SERVED["resets"] == [0, 0, probed[0]["memory_resets"][0]]
    assert "drop (points)" in (tmp_path / "out" / "summary.md").read_text()
    # a later evaluation without the probe keeps its result in the summary
    again = evaluate(EvalConfig((TASK,), "test_lookup", tmp_path / "out", **common))
    assert again["tasks"][TASK]["memory_reset"]["aliasing"] == probe
    # the results JSON beside a memoryless control cell (0 of 100 here)
    import json

    bench = load_script("benchmarks/memory_probe.py")
    ref = tmp_path / "ref.json"
    ref.write_text(json.dumps({"policies": {"mem0:no_memory": {"success_rate": 0.0,
                                                                "episodes": 100}}}))
    assert bench.main(["--eval", str(tmp_path / "out"), "--task", TASK, "--reference", str(ref),
                       "--out", str(tmp_path / "r.json")]) == 0
    res = json.loads((tmp_path / "r.json").read_text())
    assert res["with"]["successes"] == 1 and res["reference"]["successes"] == 0
    assert res["with_minus_reference"]["difference"] == 1.0
    assert res["reference"]["success_ci95"] == [0.0, 0.037]


def test_the_probe_resets_a_served_policy_over_the_wire(lookup):
    seed, _ = lookup
    SERVED.pop("resets", None)
    server = PolicyServer("test_lookup", TASK, port=0).start()
    env = rmbench.make(TASK, **STATE)
    try:
        remote = make_policy(f"remote:ws://127.0.0.1:{server.port}", env)
        try:
            plain = run_policy_episode(env, remote, seed)
            probed = run_policy_episode(env, remote, seed,
                                        memory_reset=MemoryReset.parse("aliasing"))
        finally:
            remote.close()
    finally:
        env.close()
        server.stop()
    assert plain["success"] and strip(probed) == strip(plain)
    # the served policy was reset at each episode's start and at the probed one's aliasing step
    assert SERVED["resets"] == [0, plain["steps"], plain["steps"] + probed["memory_resets"][0]]


def test_compare_counts_the_episodes_the_probe_changed():
    from rmbench.eval.intervals import paired_difference

    plain = [{"seed": s, "success": s < 8, "progress": 1.0} for s in range(10)]
    probed = [{"seed": s, "success": s in (0, 9), "progress": 0.5, "memory_resets": [3]}
              for s in range(10)]
    c = compare(plain, probed)
    assert c["without"]["successes"] == 8 and c["with"]["successes"] == 2
    assert c["drop"] == 0.6 and c["changed"] == {"lost": 7, "gained": 1}
    assert c["drop_ci95"][0] > 0 and c["outside_noise"]
    # the interval is the pairs': 1 both, 7 lost, 1 gained, 1 neither of 10
    assert c["drop_ci95"] == [round(v, 4) for v in paired_difference(1, 7, 1, 10)[1:]]
