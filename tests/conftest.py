import copy
import os
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest

# A checkout tests its own source, in this process and in every process a test starts (spawned
# workers inherit sys.path, subprocesses PYTHONPATH). Otherwise a clone run with a shared
# virtualenv imports the editable install's checkout, which others may be editing: then the
# workers spawned minutes into a run import other code than this process did.
SRC = Path(__file__).resolve().parents[1] / "src"
sys.path.insert(0, str(SRC))
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))

import rmbench  # noqa: E402
from rmbench.data import CollectConfig, collect  # noqa: E402

DATA_TASK = "observe_and_pickup"  # the shortest episodes


def small_collection(out, **kw) -> CollectConfig:
    """Three demonstrations at 64x48 from two cameras: a dataset in a few seconds."""
    args = {"episodes": 3, "seed": 0, "cameras": ("head", "left_wrist"), "width": 64,
            "height": 48, "progress": False, **kw}
    return CollectConfig(DATA_TASK, out, **args)


@pytest.fixture(scope="session")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("data") / "ds"
    collect(small_collection(out))
    return out


@pytest.fixture(params=sorted(rmbench.TASKS))
def task_name(request):
    return request.param


def roll_out(env, policy, seed, steps):
    """Roll ``policy`` (an expert or any Policy) for up to ``steps`` steps from ``seed``,
    stopping where the episode ends; return observations and actions."""
    obs, info = env.reset(seed=seed)
    policy.reset(info["instruction"], {**info, "seed": seed})
    observations, actions = [obs], []
    for _ in range(steps):
        action = policy.act(obs)
        obs, _, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        actions.append(action)
        if terminated or truncated:
            break
    return observations, actions


@pytest.fixture(scope="session")
def mn_dataset(tmp_path_factory):
    """Two press_button demonstrations (an M(n) task: several subtasks, key frames)."""
    out = tmp_path_factory.mktemp("data") / "mn"
    collect(CollectConfig("press_button", out, episodes=2, seed=0, cameras=("head", "left_wrist"),
                          width=64, height=48, progress=False))
    return out


# out folder -> the module a training's last save exported, as it was in memory (keep_exports)
EXPORTED: dict = {}


@contextmanager
def keep_exports():
    """While open, every training's saves also keep a copy of the module they export: what a
    checkpoint's round trip must reproduce, not another load of the same file."""
    from rmbench.training import loop

    real = loop._export

    def export(out, model, identity, step, write_checkpoint):
        real(out, model, identity, step, write_checkpoint)
        module = model.export_module() if hasattr(model, "export_module") else model
        EXPORTED[Path(out)] = copy.deepcopy(module).eval()

    loop._export = export
    try:
        yield
    finally:
        loop._export = real


@pytest.fixture
def interrupt_training(monkeypatch):
    """``interrupt_training(run)`` calls ``run()`` with the training loop killed right after
    its first checkpoint, as a SIGKILL would leave it."""
    from rmbench.training import loop

    def interrupt(run):
        save = loop._save

        def save_then_die(*args, **kw):
            save(*args, **kw)
            raise KeyboardInterrupt

        monkeypatch.setattr(loop, "_save", save_then_die)
        with pytest.raises(KeyboardInterrupt):
            run()
        monkeypatch.setattr(loop, "_save", save)

    return interrupt
