"""A checkpoint's config.json read back: every damage a one-line CheckpointError naming it."""

import json

import pytest

from rmbench.policies.builtin import checkpoint_check
from rmbench.policies.checkpoint import FORMAT, CheckpointError, read_config
from rmbench.policies.registry import check_policy

GOOD = {"format": FORMAT, "policy": "dp", "task": "put_back_block", "config": {"dim": 8},
        "step": 10}


@pytest.mark.parametrize("text, message", [
    ("[1]", r"config\.json: holds a JSON list, not an object"),
    ("{bad", r"config\.json: unreadable"),
    (json.dumps({k: v for k, v in GOOD.items() if k != "step"}), r"no 'step' field"),
    (json.dumps({k: v for k, v in GOOD.items() if k not in ("task", "config")}),
     r"no 'task', 'config' fields"),
    (json.dumps({**GOOD, "config": [1]}), r"no 'config' field"),
    (json.dumps({**GOOD, "policy": "act"}), r"is a 'act' checkpoint, not 'dp'"),
])
def test_a_damaged_config_is_a_checkpoint_error_naming_it(tmp_path, text, message):
    (tmp_path / "config.json").write_text(text)
    with pytest.raises(CheckpointError, match=message):
        read_config(tmp_path, "dp")


def test_a_learned_policy_spec_is_checked_without_building_it(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps(GOOD))
    assert read_config(tmp_path, "dp")["step"] == 10
    checkpoint_check("dp", "rmbench.policies.dp.config.DPConfig")(f"{tmp_path}?execute=4")
    check_policy(f"dp:{tmp_path}")
    # its options, before anything runs: an unknown one, one without a value
    with pytest.raises(ValueError, match=r"unknown option 'foo'; options: .*execute"):
        check_policy(f"dp:{tmp_path}?foo=1")
    with pytest.raises(ValueError, match=r"option execute='' is not a number"):
        check_policy(f"dp:{tmp_path}?execute")
    with pytest.raises(CheckpointError, match="not a checkpoint"):
        check_policy(f"mem0:{tmp_path / 'missing'}")
    with pytest.raises(CheckpointError, match="is a 'dp' checkpoint, not 'act'"):
        check_policy(f"act:{tmp_path}")


def test_weights_of_another_shape_name_the_tensor(tmp_path):
    import torch

    from rmbench.policies.checkpoint import load_weights, save_checkpoint

    save_checkpoint(tmp_path, torch.nn.Linear(3, 4), {"policy": "line"}, step=2)
    load_weights(tmp_path, torch.nn.Linear(3, 4), 2)
    with pytest.raises(CheckpointError, match=r"weight is \(4, 3\), the model's \(5, 3\) "
                                              r"\(2 tensors of other shapes\)"):
        load_weights(tmp_path, torch.nn.Linear(3, 5), 2)


def test_a_config_takes_numpy_numbers_as_their_builtin_types_and_refuses_other_types():
    import numpy as np

    from rmbench.policies.act.config import ACTConfig

    cfg = ACTConfig(dim=np.int64(256), lr=np.float64(1e-4))
    assert type(cfg.dim) is int and type(cfg.lr) is float and cfg.dim == 256
    assert ACTConfig(lr=0).lr == 0.0  # (JSON writes 0.0 as 0)
    for bad, said in (({"dim": True}, "dim must be int, got bool"),
                      ({"dim": 2.0}, "dim must be int, got float"),
                      ({"dim": "x"}, "dim must be int, got str")):
        with pytest.raises(ValueError, match=said):
            ACTConfig(**bad)


@pytest.mark.parametrize("name, config", [
    ("mem0", "rmbench.policies.mem0.config.Mem0Config"),
    ("dp", "rmbench.policies.dp.config.DPConfig"),
    ("act", "rmbench.policies.act.config.ACTConfig"),
])
def test_a_learned_policys_help_names_each_option_its_argument_takes(name, config):
    import importlib

    from rmbench.policies.registry import POLICIES

    module, cls = config.rsplit(".", 1)
    fields = getattr(importlib.import_module(module), cls).INFERENCE_FIELDS
    help_text = POLICIES[name].help
    assert [f for f in fields if f not in help_text] == []
