"""Local worker processes end with the process that started them: a run killed by a signal
leaves no worker going on with its job beside the run that resumes it."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

# A parent that starts a worker on a long job, prints the worker's pid and kills itself: no
# clean-up of any kind runs.
PARENT = """
import os, signal, time
from rmbench.parallel import Pool
pool = Pool(1)
print(pool.submit(os.getpid).result(), flush=True)
pool.submit(time.sleep, 300)
time.sleep(0.5)
os.kill(os.getpid(), signal.SIGKILL)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:  # no such process
        return False
    return state != "Z"  # a zombie has ended; only its reaping is left


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_worker_ends_when_its_parent_is_killed(tmp_path):
    # files, not pipes: the worker inherits them, and a pipe would keep the run waiting
    out, err = tmp_path / "out", tmp_path / "err"
    with open(out, "w") as f, open(err, "w") as g:
        code = subprocess.run([sys.executable, "-c", PARENT], stdout=f, stderr=g,
                              timeout=120).returncode
    assert code == -9, err.read_text()
    worker = int(out.read_text().split()[0])
    deadline = time.monotonic() + 30
    while _alive(worker) and time.monotonic() < deadline:
        time.sleep(0.2)
    if _alive(worker):
        os.kill(worker, 9)
        pytest.fail(f"worker {worker} still running its job after its parent was killed")


def test_a_worker_whose_parent_died_before_it_started_ends():
    # the parent names its pid: a worker that read getppid() at start-up would find its
    # re-parenting process there and run on
    gone = subprocess.Popen(["true"])
    gone.wait()
    run = subprocess.run(
        [sys.executable, "-c", "import time; from rmbench.parallel import exit_with_parent; "
         f"exit_with_parent({gone.pid}, poll_s=0.05); time.sleep(60)"],
        capture_output=True, text=True, timeout=30)
    assert (run.returncode, run.stderr) == (1, "")
