"""The README's "Evaluate your policy" example as written: its policy module and its
pyproject's entry point make a package that rmbench finds without installing it, that
``rmbench eval --help`` lists, and that ``rmbench eval`` runs without rendering a camera."""

import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from rmbench.cli.main import main
from rmbench.eval import worker
from rmbench.eval.records import read_records
from rmbench.policies import registry
from rmbench.sim.simulator import Simulator
from tests.conftest import DATA_TASK as TASK

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_block(lang: str, marker: str) -> str:
    """The one ```lang block of the README that holds ``marker``."""
    blocks = re.findall(rf"^```{lang}\n(.*?)^```", README.read_text(), re.S | re.M)
    (block,) = [b for b in blocks if marker in b]
    return block


@pytest.fixture
def mypolicy(tmp_path) -> Path:
    """The README's package under ``tmp_path/src``: ``mypolicy/__init__.py`` and the metadata
    ``pip install`` would write for its pyproject (the entry points), which importlib.metadata
    finds on the path. Returns the folder to put on the path."""
    pyproject = tomllib.loads(readme_block("toml", 'entry-points."rmbench.policies"'))
    project = pyproject["project"]
    src = tmp_path / "src"
    package = src / project["name"]
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(readme_block("python", "class HoldStill"))
    info = src / f"{project['name']}-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\n"
                                   f"Version: {project['version']}\n")
    (info / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in names.items()) + "\n"
        for group, names in project["entry-points"].items()))
    return src


def test_eval_help_lists_the_plugins_policies(mypolicy):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(mypolicy), os.environ["PYTHONPATH"]])}
    out = subprocess.run([sys.executable, "-m", "rmbench.cli.main", "eval", "--help"], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert re.search(r"^  holdstill +hold the arms where they are$", out.stdout, re.M), out.stdout
    assert re.search(r"^  expert +the scripted expert", out.stdout, re.M)
    assert re.search(r"^  replay:ARG +replay a dataset's", out.stdout, re.M)


@pytest.fixture
def plugin_on_path(mypolicy, monkeypatch):
    """The README's package importable here, with the registry to load its plugins afresh;
    afterwards the registry is as it was and the module forgotten."""
    # the installed plugins registered into the registry kept afterwards (a module registers
    # at its first import only), then the README's added to a copy of it
    registry.registered_policies()
    monkeypatch.syspath_prepend(str(mypolicy))
    monkeypatch.setattr(registry, "POLICIES", dict(registry.POLICIES))
    monkeypatch.setattr(registry, "_loaded", False)
    monkeypatch.setattr(registry, "_failed", {})
    yield
    sys.modules.pop("mypolicy", None)


def test_the_readme_policy_is_evaluated_without_rendering(plugin_on_path, tmp_path, monkeypatch):
    assert registry.env_options("holdstill") == {"render": False}
    made, rendered = [], []
    real_make, real_renderer = worker.make, Simulator.renderer

    def make(task, **kw):
        made.append(kw)
        return real_make(task, **kw)

    def renderer(self, *args, **kw):
        rendered.append(args)
        return real_renderer(self, *args, **kw)

    monkeypatch.setattr(worker, "make", make)
    monkeypatch.setattr(Simulator, "renderer", renderer)
    monkeypatch.setenv("RMBENCH_CACHE", str(tmp_path / "cache"))
    # the README's command on one task and one episode; a video would render its own view
    out = tmp_path / "out"
    assert main(["eval", "--task", TASK, "--policy", "holdstill", "--episodes", "1",
                 "--video", "none", "--json", "--out", str(out)]) == 0
    (record,) = read_records(out / TASK / "episodes.jsonl")
    assert record["reason"] in ("timeout", "task_failure"), record
    assert json.loads((out / "summary.json").read_text())["policy"] == "holdstill"
    assert made and all(kw.get("render") is False for kw in made), made
    assert rendered == []
