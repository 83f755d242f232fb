"""Validation episodes: disjoint from the test episodes a table reports, chosen by a flag."""

import pytest

from rmbench.eval import EvalConfig
from rmbench.eval.seeds import verified_seeds
from rmbench.seeds import EVAL_SEED_STRIDE, SPLIT_STRIDE, eval_seed_start
from rmbench.suite.plan import Plan


def test_each_evaluation_seed_splits_its_block_in_two():
    for seed in (0, 3):
        test, validation = eval_seed_start(seed), eval_seed_start(seed, "validation")
        assert test == EVAL_SEED_STRIDE * (1 + seed)  # the test episodes did not move
        assert validation == test + SPLIT_STRIDE
        assert validation + SPLIT_STRIDE == eval_seed_start(seed + 1)  # nor meet the next block
    with pytest.raises(ValueError, match="unknown split"):
        eval_seed_start(0, "train")


def test_validation_seeds_are_verified_apart_from_the_test_seeds(tmp_path):
    validation = verified_seeds("put_back_block", 0, 2, cache=tmp_path, split="validation")
    test = verified_seeds("put_back_block", 0, 2, cache=tmp_path)
    assert all(eval_seed_start(0, "validation") <= s < eval_seed_start(1) for s in validation)
    assert all(eval_seed_start(0) <= s < eval_seed_start(0, "validation") for s in test)
    assert len(list(tmp_path.glob("*.json"))) == 2  # a cache file per split


def test_a_validation_run_is_its_own_evaluation(tmp_path):
    test = EvalConfig(("put_back_block",), "noop", tmp_path)
    validation = EvalConfig(("put_back_block",), "noop", tmp_path, split="validation")
    assert test.identity() != validation.identity() and "split" not in test.identity()
    with pytest.raises(ValueError, match="split"):
        EvalConfig(("put_back_block",), "noop", tmp_path, split="val")
    plans = [Plan("state", ("put_back_block",), ("mem0",), split=s) for s in ("test", "validation")]
    dirs = [p.eval_dir(tmp_path, "put_back_block", "mem0") for p in plans]
    assert dirs[0] != dirs[1] and dirs[1].name.endswith("-validation")
    assert plans[0].train_dir(tmp_path, "put_back_block", "mem0") == plans[1].train_dir(
        tmp_path, "put_back_block", "mem0")  # one checkpoint, evaluated on either
