import copy
import importlib.util
import os
import signal
import sys
import time
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

# Each test's setup, call and teardown each get this long (a hang fails its test, not the
# run): far above the slowest test's time on two busy cores, so it catches a deadlock, a
# server that never answers or a subprocess that never ends, not a slow test.
# @pytest.mark.timeout(SECONDS) sets a test's own limit; RMBENCH_TEST_TIMEOUT the default.
TEST_TIMEOUT = float(os.environ.get("RMBENCH_TEST_TIMEOUT", 600))


class RanPastLimit(BaseException):
    """Raised in a test that ran past its limit: a BaseException, so that no ``except
    Exception`` (or ``except TimeoutError``) in the code under test swallows it."""


def pytest_configure(config):
    config.addinivalue_line("markers", "timeout(seconds): this test's own time limit")


@contextmanager
def time_limit(item, phase: str):
    if not hasattr(signal, "setitimer"):  # no SIGALRM here (Windows): no limit
        yield
        return
    mark = item.get_closest_marker("timeout")
    seconds = float(mark.args[0]) if mark else TEST_TIMEOUT

    def expire(signum, frame):
        raise RanPastLimit(f"{item.nodeid}: {phase} ran past {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    outer, _ = signal.setitimer(signal.ITIMER_REAL, seconds)
    start = time.monotonic()
    try:
        yield
    finally:
        # an enclosing limit (a test of this one) goes on with what it had left
        left = outer - (time.monotonic() - start) if outer else 0.0
        signal.setitimer(signal.ITIMER_REAL, max(left, 1e-3) if outer else 0.0)
        signal.signal(signal.SIGALRM, previous)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    with time_limit(item, "setup"):
        yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    with time_limit(item, "call"):
        yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item):
    with time_limit(item, "teardown"):
        yield


def load_script(relative: str):
    """A script of the repository that is no package module (benchmarks/, scripts/), loaded
    from its path, e.g. ``load_script("benchmarks/table_state.py")``."""
    path = SRC.parent / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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
