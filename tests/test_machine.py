"""rmbench.machine: the machine a wall time was measured on, read from /proc/cpuinfo."""

import os

from rmbench.machine import describe, short

CPUINFO = """processor\t: 0
vendor_id\t: AuthenticAMD
model name\t: AMD EPYC
flags\t\t: fpu sse4_2 avx fma avx2 sha_ni

processor\t: 1
model name\t: another model the first processor's lines win over
flags\t\t: fpu avx512f
"""


def test_the_first_processor_and_its_widest_vector_extension():
    m = describe(CPUINFO)
    assert m["cpu"] == "AMD EPYC" and m["isa"] == "avx2" and m["cores"] == os.cpu_count()
    assert describe(CPUINFO.replace("sha_ni", "avx512f avx512bw"))["isa"] == "avx512f"
    assert short(m) == f"AMD EPYC, {os.cpu_count()} cores, avx2"


def test_no_cpuinfo_still_describes_the_machine():
    m = describe("")
    assert m["isa"] == "unknown" and m["cpu"] and m["python"].count(".") == 2
    assert describe("model name : X\nflags : fpu\n")["isa"] == "none"


def test_this_machine():
    m = describe()
    assert set(m) == {"cpu", "isa", "cores", "platform", "python"} and m["cores"] >= 1


def test_usable_cores_follow_the_affinity():
    """Jobs size their threads by the cores this process may use (``taskset``, a cpuset),
    not the machine's count."""
    import os

    from rmbench.machine import usable_cores

    if not hasattr(os, "sched_getaffinity"):
        assert usable_cores() == (os.cpu_count() or 1)
        return
    before = os.sched_getaffinity(0)
    try:
        os.sched_setaffinity(0, {min(before)})
        assert usable_cores() == 1
    finally:
        os.sched_setaffinity(0, before)
    assert usable_cores() == len(before)
