"""rmbench.eval.rows: a row given again replaces its own, the others stay, and a file that is
not a results file is refused before anything is written."""

import json

import pytest

from rmbench.eval.rows import put_row


def test_a_row_replaces_the_row_of_its_key_and_keeps_the_others(tmp_path):
    out = tmp_path / "r.json"
    put_row(out, {"label": "a", "n": 1}, key=("label",))
    put_row(out, {"label": "b", "n": 2}, key=("label",))
    rows = put_row(out, {"label": "a", "n": 3}, key=("label",))
    assert rows == [{"label": "b", "n": 2}, {"label": "a", "n": 3}]
    assert json.loads(out.read_text()) == {"rows": rows}


def test_a_file_that_is_not_a_results_file_is_refused_and_kept(tmp_path):
    out = tmp_path / "r.json"
    for text in ('{"rows": [', '{"other": []}', '{"rows": 3}'):
        out.write_text(text)
        with pytest.raises(ValueError, match="not a results file of 'rows' rows"):
            put_row(out, {"label": "a"}, key=("label",))
        assert out.read_text() == text
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left
