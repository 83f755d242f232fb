"""The docs' generated tables: every table between ``<!-- table:NAME -->`` markers in README.md
and docs/ is what scripts/render_docs.py renders from benchmarks/results/, and every results
page shows its first table within its first 40 lines."""

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _render_docs():
    spec = importlib.util.spec_from_file_location("render_docs", ROOT / "scripts" / "render_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_tables_match_their_json():
    assert _render_docs().stale() == []


def test_a_changed_number_is_caught(tmp_path):
    """The check fails on a doc whose table differs from its JSON by one cell."""
    render_docs = _render_docs()
    readme = (ROOT / "README.md").read_text()
    assert "<!-- table:readme-results -->" in readme
    edited = tmp_path / "README.md"
    row = "| put_back_block | M(1) | 85 [77, 91]"
    edited.write_text(readme.replace(row, row.replace("85", "86", 1)))
    render_docs.ROOT = tmp_path
    assert render_docs.stale([edited]) == ["README.md: readme-results"]


def test_an_unknown_table_is_an_error(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("<!-- table:no-such-table -->\n<!-- /table -->\n")
    with pytest.raises(ValueError, match="unknown table 'no-such-table'"):
        _render_docs().render(doc.read_text(), doc)


@pytest.mark.parametrize("page", sorted((ROOT / "docs" / "results").glob("*.md")), ids=lambda p: p.name)
def test_results_pages_start_with_their_table(page):
    lines = page.read_text().splitlines()[:40]
    assert any(re.match(r"^\|.*\|$", line) for line in lines), f"{page.name}: no table in its first 40 lines"


def test_a_cell_pooled_over_seeds_shows_each_seed():
    """A pooled cell's record names each seed's success and walls (a seed's hand-written wall
    where it has one), and one evaluation's wall is the fastest seed's."""
    render_docs = _render_docs()

    def seed(k, train, evals, **extra):
        return {"successes": k, "episodes": 100, "train_wall_s": train, "eval_wall_s": evals,
                **extra}

    cell = {"successes": 130, "episodes": 200, "mean_progress": 0.9,
            "endings": {"success": 130, "task_failure": 70}, "failure_reasons": {"short": 70},
            "seeds": {"0": seed(69, 600.0, 300.0, record={"train_wall": "10 min on a GPU"},
                                planner_refit={"from": "x"}),
                      "1": seed(61, 1200.0, 180.0)}}
    (row,) = render_docs._record_rows({"press_button": {"mem0": cell}})
    assert row[2] == "130/200 (seeds 0: 69, 1: 61)"
    assert row[6].startswith("10 min on a GPU (the executor), then its planner refit")
    assert row[6].endswith("(seed 0) + 20.0 min (seed 1)")
    assert row[7] == "5.0 min (seed 0) + 3.0 min (seed 1)"
    assert render_docs._one_eval(cell) == 180.0
