"""The machine a piece of work ran on, as wall times need it said.

A wall time means little without its machine: the state table's Mem-0 cells trained at 12-14
steps/s on the first machines and at 4.5 steps/s on a later one of the same size
and name ("AMD EPYC", 2 cores, 24 GB), whose CPU has AVX2 and no AVX-512 (the earlier ones'
flags were not recorded). A table may be built over several runs, each on another
machine, so each stage records the machine it ran on beside its time
(``suite.clock.add_time``). Read from ``/proc/cpuinfo`` where there is one; nothing here
imports torch.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

CPUINFO = Path("/proc/cpuinfo")
# the widest x86 vector extension present decides torch's and MuJoCo's kernels; widest first
VECTOR_ISAS = ("avx512f", "avx2", "avx", "sse4_2")


# what sizes OpenMP's and the BLAS libraries' thread pools (torch reads them at its import)
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def usable_cores() -> int:
    """The cores this process may run on (its affinity: ``taskset``, a container's cpuset),
    which a job's threads and worker processes are sized by; ``os.cpu_count()`` counts the
    machine's."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # (no affinity call: macOS, Windows)
        return os.cpu_count() or 1


def _cpuinfo_fields(text: str) -> dict[str, str]:
    """The first processor's ``key: value`` lines of a ``/proc/cpuinfo`` text."""
    fields: dict[str, str] = {}
    for line in text.splitlines():
        if not line.strip():
            if fields:
                break
            continue
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())
    return fields


def describe(cpuinfo: str | None = None) -> dict[str, object]:
    """``{"cpu": model name, "isa": widest vector extension, "cores": n, "platform": ...,
    "python": version}``;
    ``cpuinfo`` (a ``/proc/cpuinfo`` text) is read from the system when not given."""
    if cpuinfo is None:
        try:
            cpuinfo = CPUINFO.read_text()
        except OSError:  # not Linux
            cpuinfo = ""
    fields = _cpuinfo_fields(cpuinfo)
    flags = set(fields.get("flags", "").split())
    isa = next((f for f in VECTOR_ISAS if f in flags), "unknown" if not flags else "none")
    return {"cpu": fields.get("model name") or platform.processor() or platform.machine(),
            "isa": isa, "cores": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version()}


def short(machine: dict[str, object]) -> str:
    """One machine in a few words: ``AMD EPYC, 2 cores, avx2`` (``, NVIDIA H100`` with a GPU)."""
    gpu = f", {machine['gpu']}" if machine.get("gpu") else ""
    return f"{machine.get('cpu')}, {machine.get('cores')} cores, {machine.get('isa')}{gpu}"
