"""benchmarks/learning.py's argument handling: policies with ablations, ``--set`` overrides
routed to the configs that have the field, and run folders named by them."""

import importlib.util
from pathlib import Path

import pytest

PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "learning.py"


@pytest.fixture(scope="module")
def learning():
    spec = importlib.util.spec_from_file_location("learning_benchmark", PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_policies_and_ablations(learning):
    assert learning.parse_policy("mem0:no_memory") == ("mem0", ("no_memory",))
    assert learning.parse_policy("dp") == ("dp", ())
    with pytest.raises(SystemExit, match="unknown policy"):
        learning.parse_policy("pi0")
    with pytest.raises(SystemExit, match="only Mem-0 has ablations"):
        learning.parse_policy("act:no_memory")


def test_set_reaches_only_the_configs_with_the_field(learning):
    sets = ["head_layers=2", "execute=10", "obs_steps=3"]
    mem0 = learning.config_for("mem0", "state", sets, ("no_anchor",))
    assert (mem0.head_layers, mem0.execute, mem0.observation) == (2, 10, "state")
    assert mem0.ablations == ("no_anchor",)
    dp = learning.config_for("dp", "state", sets)
    assert (dp.execute, dp.obs_steps) == (10, 3)  # DP has no head_layers: left alone
    learning.check_sets(sets)
    # a value one policy's config refuses is a one-line error naming the policy
    with pytest.raises(SystemExit, match="dp with execute=20: execute"):
        learning.config_for("dp", "state", ["execute=20"])
    with pytest.raises(SystemExit, match="no_such_field"):
        learning.check_sets(["no_such_field=1"])
    with pytest.raises(SystemExit, match="FIELD=VALUE"):
        learning.check_sets(["head_layers"])


def test_run_names_tell_overrides_apart(learning):
    plain = learning.run_name("mem0:no_memory", 12000, 128)
    assert plain == "mem0-no_memory-s12000-b128"
    tagged = learning.run_name("mem0:no_memory", 12000, 128, ["head_layers=2", 'observation="x"'])
    assert tagged.startswith(plain) and tagged != plain
    assert "/" not in learning.run_name("mem0", 1, 1, ["cameras=[\"a/b\"]"])
    no_sliding = learning.config_for("mem0", "state", [], ("no_sliding",))
    assert "sliding" not in learning.memory_of("mem0:no_sliding", "M(1)", no_sliding)
    window = learning.config_for("mem0", "state", ["sliding_window=4"])
    assert "4 x 5 steps" in learning.memory_of("mem0", "M(1)", window)


def test_a_job_repeats_the_parent_settings_for_one_policy(learning, tmp_path):
    import argparse

    args = argparse.Namespace(task="put_back_block", obs="state", demos=50, steps=12000,
                              batch=128, episodes=100, noise=0.02, noise_kind="white",
                              workers=1, set=["head_layers=2", "execute=20"], jobs=2)
    cmd = learning.job_command(args, "mem0:no_anchor", tmp_path, tmp_path / "r.json", 1)
    assert cmd[1] == str(PATH)
    flags = dict(zip(cmd[2::2], cmd[3::2], strict=False))
    assert flags["--policies"] == "mem0:no_anchor" and flags["--threads"] == "1"
    assert flags["--noise"] == "0.02" and flags["--out"] == str(tmp_path)
    assert [cmd[i + 1] for i, a in enumerate(cmd) if a == "--set"] == args.set
    assert "--jobs" not in cmd  # a job runs its one policy itself
