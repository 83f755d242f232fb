"""The docs' generated tables: every table between ``<!-- table:NAME -->`` markers in README.md
and docs/ is what scripts/render_docs.py renders from benchmarks/results/, and every results
page shows its first table within its first 40 lines."""

import re
from pathlib import Path

import pytest

from tests.conftest import load_script

ROOT = Path(__file__).resolve().parents[1]


def _render_docs():
    return load_script("scripts/render_docs.py")


def test_committed_tables_match_their_json():
    assert _render_docs().stale() == []


def test_a_changed_number_is_caught(tmp_path):
    """The check fails on a doc whose table differs from its JSON by one cell."""
    render_docs = _render_docs()
    readme = (ROOT / "README.md").read_text()
    assert "<!-- table:readme-results -->" in readme
    edited = tmp_path / "README.md"
    row = next(line for line in readme.splitlines() if line.startswith("| put_back_block | M(1) | "))
    cells = row.split(" | ")
    cells[2] = str(int(cells[2].split()[0]) + 1) + cells[2][len(cells[2].split()[0]):]  # Mem-0's rate
    edited.write_text(readme.replace(row, " | ".join(cells), 1))
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


MACHINES = {"cpu": {"label": "CPU"}, "h100": {"label": "H100"}}


def test_a_cell_pooled_over_seeds_shows_each_seed():
    """A pooled cell's record names each seed's success and walls (each with the conditions its
    record keeps), and one evaluation's wall is the fastest seed's."""
    render_docs = _render_docs()

    def seed(k, train, evals, **extra):
        return {"successes": k, "episodes": 100, "train_wall_s": train, "eval_wall_s": evals,
                **extra}

    cell = {"successes": 130, "episodes": 200, "mean_progress": 0.9,
            "endings": {"success": 130, "task_failure": 70}, "failure_reasons": {"short": 70},
            "seeds": {"0": seed(69, 600.0, 300.0, planner_refit={"from": "x"},
                                conditions={"train": [{"machine": "h100"}],
                                            "eval": [{"jobs_beside": 1, "beside": "a training"}]}),
                      "1": seed(61, 1200.0, 180.0)}}
    (row,) = render_docs._record_rows({"press_button": {"mem0": cell}}, MACHINES)
    assert row[2] == "130/200 (seeds 0: 69, 1: 61)"
    assert row[6].startswith("10.0 min on H100 (the executor), then its planner refit")
    assert row[6].endswith("(seed 0) + 20.0 min (seed 1)")
    assert row[7] == "5.0 min (beside a training) (seed 0) + 3.0 min (seed 1)"
    assert render_docs._one_eval(cell) == 180.0


def test_a_wall_prints_its_conditions_and_its_pieces():
    """A wall's conditions come from its record's fields, in one wording: the machine where it
    is not the page's one, the threads or workers, the jobs beside it; a training run in pieces
    piece by piece, a piece before the step its wall is timed from marked not timed."""
    wall = _render_docs()._wall
    one = {"train_wall_s": 2610.0, "eval_wall_s": 174.0, "conditions": {
        "train": [{"machine": "cpu", "threads": 2, "jobs_beside": 1,
                   "beside": "the test suite for 13 min of it"}],
        "eval": [{"workers": 2, "jobs_beside": 0}]}}
    assert wall(one, "train", MACHINES) == ("43.5 min (2 torch threads, beside the test suite "
                                            "for 13 min of it)")
    assert wall(one, "eval", MACHINES) == "2.9 min (2 workers, alone)"
    pieces = {"train_wall_s": 1932.0, "train_wall_from_step": 16500, "conditions": {"train": [
        {"machine": "h100", "steps": [0, 8000], "jobs_beside": 7, "beside": "seven other trainings"},
        {"machine": "cpu", "steps": [8000, 16500], "note": "several runs"},
        {"machine": "cpu", "steps": [16500, 18000], "wall_s": 1932.0, "jobs_beside": 1}]}}
    assert wall(pieces, "train", MACHINES) == (
        "32.2 min from step 16,500: on H100 to step 8,000 (beside seven other trainings, not "
        "timed); on CPU to step 16,500 (several runs, not timed); 32.2 min on CPU to step 18,000 "
        "(beside 1 other job)")
    assert wall({"train_wall_s": 60.0}, "train", MACHINES) == "1.0 min"  # no conditions kept


def test_every_record_keeps_its_wall_conditions_as_fields():
    """Each cell's (or seed's) record in the state table keeps the conditions of its walls as
    fields, none as words: a training's pieces run from step 0 to its last step, one after the
    other, their kept walls add up to its wall, and each machine is one the results name."""
    import json

    res = json.loads((ROOT / "benchmarks" / "results" / "table_state.json").read_text())
    assert set(res["wall_defaults"]["train"]) == {"machine", "threads", "jobs_beside"}
    steps = res["plan"]["steps"]
    groups = [res["cells"], *(g["cells"] for g in res["superseded"])]
    records = [(t, s, r) for cells in groups for t, row in cells.items() for s, c in row.items()
               for r in (c.get("seeds") or {"0": c}).values()]
    assert len(records) >= 99  # the 99 converted to fields, and every record since
    for task, spec, r in records:
        where = f"{task} {spec}"
        assert not {"train_wall", "eval_wall"} & set(r.get("record", {})), where
        train, evals = r["conditions"]["train"], r["conditions"]["eval"]
        assert len(evals) == 1 and (train == [] if spec == "mem0:gt_classifier" else train), where
        for piece in [*train, *evals]:
            assert piece["machine"] is None or piece["machine"] in res["machines"], where
            assert piece["jobs_beside"] is None or piece["jobs_beside"] >= 0, where
        if len(train) > 1:
            ends = [p["steps"] for p in train]
            assert ends[0][0] == 0 and ends[-1][1] == steps, where
            assert all(a[1] == b[0] for a, b in zip(ends, ends[1:], strict=False)), where
            start = r["train_wall_from_step"]
            timed = [p["wall_s"] for p in train if p["steps"][0] >= start and p["wall_s"]]
            assert sum(timed) <= r["train_wall_s"] + 1e-6, where
            if all(p["wall_s"] for p in train if p["steps"][0] >= start):
                assert sum(timed) == pytest.approx(r["train_wall_s"]), where


def test_the_camera_tables_memory_gap_is_in_points():
    """Mem-0 minus ``no_memory`` in the camera table: points with their interval (the rates'
    difference once scaled, not twice: +6700 for 67 points was printed)."""
    render_docs = _render_docs()
    def cell(k):
        return {"successes": k, "episodes": 100, "success_rate": k / 100}

    res = {"cells": {"put_back_block": {"mem0": cell(67), "mem0:no_memory": cell(0)}}}
    assert render_docs._memory_gap(res, "put_back_block") == ["+67 [+57, +75]*"]
    assert render_docs._memory_gap(res, "swap_T") == ["—"]


def test_a_task_not_measured_reads_as_missing_and_empties_its_averages():
    """A table's JSON without a task's cells shows its row as — and every average over it as
    —, never an average over the other rows beside published ones over all of them."""
    import json
    from pathlib import Path

    docs = _render_docs()
    res = json.loads(Path("benchmarks/results/table_state.json").read_text())
    res["cells"] = {t: c for t, c in res["cells"].items() if t not in ("swap_T", "press_button")}
    rows = {r[0]: r[2:4] for r in docs._state_rows(res, ["mem0", "mem0:no_memory"])}
    assert rows["swap_T"] == rows["press_button"] == ["—", "—"]
    assert rows["**average M(1)**"] == rows["**average M(n)**"] == ["—", "—"]
    assert rows["**average (all)**"] == ["—", "—"]


def test_a_rerun_is_set_beside_the_seed_it_repeats_with_each_cpu(monkeypatch):
    """A seed trained again elsewhere reads as the recorded seed and the re-run, each with the
    CPU its training ran on, and the re-run minus the recorded in points."""
    docs = _render_docs()

    def run(k, isa):
        return {"successes": k, "episodes": 100,
                "machines": {"train": [{"cpu": "AMD EPYC", "isa": isa}]}}

    res = {"cells": {"cover_blocks": {"mem0": {"successes": 51, "episodes": 200, "seeds": {
        "0": run(28, "avx512f"), "1": run(23, "avx512f")}}}},
        "reruns": [{"task": "cover_blocks", "column": "mem0", "seed": 0, **run(36, "avx2")}]}
    monkeypatch.setattr(docs, "load", lambda name: res)
    assert docs.state_reruns().splitlines()[2] == (
        "| cover_blocks | Mem-0 | 0 | 28 [20, 37] (AMD EPYC, avx512f) | "
        "36 [27, 46] (AMD EPYC, avx2) | +8 [-5, +21] |")
    res["reruns"] = []
    assert docs.state_reruns() == "No seed has been trained again yet.\n"


def test_an_ablation_without_its_rows_recipe_items_is_marked_and_kept_apart():
    """After a recipe change re-runs a row's Mem-0, its ablations still trained without the
    task's new items read '§', with a note saying so, and stand apart from Mem-0 in a
    difference (``measured_on``); ablations trained with the same items read no mark."""
    from rmbench.suite.records import measured_on

    render_docs = _render_docs()
    reach = ['mem0.reach_input=["cube_left"]']
    row = {"mem0": {"task_items": reach, "dataset": "rmbench/2"},
           "mem0:no_key": {"seeds": {"0": {"task_items": reach}, "1": {"task_items": reach}},
                           "dataset": "rmbench/2"},
           "mem0:no_memory": {"dataset": "rmbench/2"}, "dp": {}}
    res = render_docs._recipe_marked({"cells": {"blocks_ranking_try": row}})
    marks = {s: render_docs._older("blocks_ranking_try", s, c) for s, c in row.items()}
    assert marks == {"mem0": "", "mem0:no_key": "", "mem0:no_memory": " §", "dp": ""}
    assert res["cells"]["blocks_ranking_try"]["mem0:no_memory"]["recipe_before"]
    assert "§ trained without the items" in render_docs._footnote("| 13 [8, 21] § |")
    on = {s: measured_on("blocks_ranking_try", s, row[s]) for s in row if s != "dp"}
    assert on["mem0"] == on["mem0:no_key"] != on["mem0:no_memory"]


def test_a_withdrawn_cell_is_named_under_its_table_and_a_replaced_one_is_not():
    """A cell of an earlier task version moved to superseded and not re-run reads '—' with a
    note naming it; one that a current cell replaced is not named."""
    from rmbench.tasks import get_task

    render_docs = _render_docs()
    old = {"gym_id": "rmbench/PressButton-v1"}
    res = {"cells": {"press_button": {"dp": {"gym_id": get_task("press_button").gym_id}}},
           "superseded": [{"why": "v1", "cells": {"press_button": {"act": old, "dp": old}}}]}
    line = render_docs._withdrawn_line(res, ["dp", "act"])
    assert "(ACT on press_button): measured on an earlier version" in line
    assert "DP" not in line
    assert render_docs._withdrawn_line(res, ["dp"]) == ""
