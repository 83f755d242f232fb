"""The paper's published numbers (eval/published.json): one source for every published rate
rmbench prints, covering the nine tasks, with the averages the paper states matching its
per-task numbers."""

import tomllib
from pathlib import Path

import pytest

from rmbench.eval import published, report
from rmbench.tasks.registry import ordered

ROOT = Path(__file__).resolve().parents[1]
NINE = {t.name for t in ordered()}


def test_the_data_loads_and_names_the_paper_and_its_tables():
    assert published.arxiv() == "2603.01229"
    assert published.rollouts() == 100
    assert published.table_name("main") and published.table_name("ablations")
    # the TMC groups as the registry has them
    assert published.data()["tasks"] == {t.name: t.tmc for t in ordered()}


def test_the_main_table_covers_every_task_of_every_policy():
    columns = published.columns("main")
    assert list(columns) == ["DP", "ACT", "Pi0.5", "X-VLA", "Mem-0"]
    for name, rates in columns.items():
        assert set(rates) == NINE, name
        assert all(0 <= v <= 100 for v in rates.values()), name
    assert report.PUBLISHED is columns  # rmbench report --published reads the same data


def test_the_ablations_cover_their_tasks_and_map_to_policy_specs():
    columns = published.columns("ablations")
    m_n = {t.name for t in ordered() if t.tmc == "M(n)"}
    for name in ("Mem-0", "w/o Anchor", "w/o Sliding"):
        assert set(columns[name]) == NINE, name
    for name in ("w/o Key", "GT classifier"):  # the planner's parts: M(n) tasks only
        assert set(columns[name]) == m_n, name
    assert columns["Mem-0"] == published.columns("main")["Mem-0"]
    assert published.ablation_names() == {
        "mem0": "Mem-0", "mem0:no_anchor": "w/o Anchor", "mem0:no_sliding": "w/o Sliding",
        "mem0:no_key": "w/o Key", "mem0:gt_classifier": "GT classifier"}
    assert columns["w/o Anchor"]["put_back_block"] == 35
    assert columns["w/o Anchor"]["cover_blocks"] == 92


@pytest.mark.parametrize("table", ["main", "ablations"])
def test_each_stated_average_is_the_mean_of_its_tasks(table):
    """The paper's averages are its per-task numbers' means, rounded half up to one decimal
    (26.75 reads 26.8, 25.25 reads 25.3)."""
    stated = published.data()["tables"][table]["averages"]
    assert stated
    for column, groups in stated.items():
        for group, value in groups.items():
            mean = published.mean(published.columns(table)[column], "" if group == "all" else group)
            assert mean is not None and abs(mean - value) <= 0.05 + 1e-9, (column, group)
    assert published.average(table, "Mem-0", "M(1)") == pytest.approx(52.8)


def test_averages_the_paper_does_not_state_are_derived():
    assert published.stated("main", "DP", "M(1)") is None
    assert published.average("main", "DP", "M(1)") == pytest.approx(6.4)
    assert published.average("ablations", "w/o Sliding") == pytest.approx(303 / 9)
    assert published.average("ablations", "w/o Key") is None  # no M(1) numbers


def test_the_data_file_is_packaged():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "published.json" in config["tool"]["setuptools"]["package-data"]["rmbench.eval"]
    assert (ROOT / "src" / "rmbench" / "eval" / "published.json").is_file()
