"""The evaluation seed lists rmbench ships (``eval/seeds.SHIPPED``): each names a current task
version, the default cache starts from it, an explicit cache verifies afresh, and the expert
still solves the seeds a list holds."""

import json

import pytest

from rmbench.eval import seeds
from rmbench.eval.seeds import SHIPPED, list_name, verified_seeds
from rmbench.seeds import SPLIT_STRIDE, eval_seed_start
from rmbench.tasks import get_task
from rmbench.tasks.registry import ordered

LISTS = sorted(SHIPPED.glob("*.json"))


def _split(path) -> str:
    return "validation" if path.stem.endswith("-validation") else "test"


def test_every_shipped_list_is_a_current_task_versions_first_solved_seeds():
    """A list of an older task version would hand out episodes verified on other physics:
    a version change ships new lists (scripts/ship_seed_lists.py)."""
    assert LISTS, f"no seed lists in {SHIPPED}"
    current = {t.gym_id for t in ordered()}
    for path in LISTS:
        doc = json.loads(path.read_text())
        cls = get_task(doc["task"])
        assert doc["gym_id"] == cls.gym_id in current, path.name
        assert path.name == list_name(cls.name, doc["seed"], _split(path)), path.name
        start = eval_seed_start(doc["seed"], _split(path))
        tried = sorted(doc["verified"] + [r["seed"] for r in doc["rejected"]])
        # the first candidates of the split, each tried once, none left out
        assert tried == list(range(start, start + len(tried))) and tried[-1] < start + SPLIT_STRIDE
        assert len(doc["verified"]) >= 100 and doc["verified"] == sorted(doc["verified"])


def test_the_default_cache_starts_from_the_shipped_list_and_a_given_one_verifies(
        tmp_path, monkeypatch):
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    cls = get_task("put_back_block")
    name = list_name(cls.name, 0)
    # a list no expert run made: taken as it is from the default cache, never from a given one
    fake = {"task": cls.name, "gym_id": cls.gym_id, "seed": 0,
            "verified": [100000, 100002], "rejected": [{"seed": 100001, "reason": "x"}]}
    (shipped / name).write_text(json.dumps(fake))
    monkeypatch.setattr(seeds, "SHIPPED", shipped)
    monkeypatch.setenv("RMBENCH_CACHE", str(tmp_path / "home"))
    assert verified_seeds("put_back_block", 0, 2) == [100000, 100002]
    assert verified_seeds("put_back_block", 0, 2, cache=tmp_path / "own") == [100000, 100001]
    # a longer list extends the shipped one into the default cache, the shipped file untouched
    assert verified_seeds("put_back_block", 0, 3) == [100000, 100002, 100003]
    assert json.loads((tmp_path / "home" / "seeds" / name).read_text())["verified"][-1] == 100003
    assert json.loads((shipped / name).read_text()) == fake


@pytest.mark.slow
@pytest.mark.parametrize("path", LISTS, ids=[p.stem for p in LISTS])
def test_the_expert_solves_a_shipped_lists_first_seeds_here(path, tmp_path):
    """This machine's expert agrees with the list on its first three seeds."""
    doc = json.loads(path.read_text())
    fresh = verified_seeds(doc["task"], doc["seed"], 3, cache=tmp_path, split=_split(path))
    assert fresh == doc["verified"][:3]
