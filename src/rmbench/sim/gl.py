"""Choose a headless OpenGL backend for MuJoCo before ``mujoco`` is imported.

MuJoCo reads ``MUJOCO_GL`` once, at import time, so the choice cannot be undone inside
a process. We therefore probe each backend in a short-lived subprocess (EGL first: it is
the faster of the two; OSMesa is the software fallback), and export the winner so worker
processes inherit it without probing again. A user's own ``MUJOCO_GL`` is respected.
"""

from __future__ import annotations

import functools
import logging
import os
import subprocess
import sys

BACKENDS = ("egl", "osmesa")

_PROBE = """
import os, sys
os.environ["MUJOCO_GL"] = sys.argv[1]
os.environ["PYOPENGL_PLATFORM"] = sys.argv[1]
import mujoco
ctx = mujoco.GLContext(16, 16)
ctx.make_current()
ctx.free()
"""


class RenderingUnavailableError(RuntimeError):
    """No headless OpenGL backend could create a context."""


def _probe(backend: str) -> str | None:
    """Return None when ``backend`` can create a context, else the error text."""
    env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE, backend],
            env=env, capture_output=True, text=True, timeout=60,
        )
    except subprocess.TimeoutExpired:
        return "timed out creating a context"
    if proc.returncode == 0:
        return None
    lines = (proc.stderr or proc.stdout).strip().splitlines()
    return lines[-1] if lines else f"exit code {proc.returncode}"


@functools.cache
def select_backend() -> str | None:
    """Set MUJOCO_GL to the user's choice, else the first backend that works.

    Returns the backend, or None when none works; rendering then fails with
    :func:`require_rendering`'s message while physics-only use keeps working.
    """
    chosen = os.environ.get("MUJOCO_GL")
    if not chosen and "mujoco" in sys.modules:
        logging.getLogger(__name__).warning(
            "mujoco was imported before rmbench without MUJOCO_GL set; offscreen rendering may "
            "fail: import rmbench first or set MUJOCO_GL=egl (or osmesa)")
    if chosen:
        if chosen in BACKENDS:
            os.environ.setdefault("PYOPENGL_PLATFORM", chosen)
        return chosen
    for backend in BACKENDS:
        err = _probe(backend)
        if err is None:
            os.environ["MUJOCO_GL"] = backend
            os.environ["PYOPENGL_PLATFORM"] = backend
            return backend
        _ERRORS.append(f"{backend}: {err}")
    os.environ["MUJOCO_GL"] = "disable"
    return None


_ERRORS: list[str] = []


def require_rendering() -> str:
    """Return the rendering backend or raise a one-line error saying how to get one."""
    backend = select_backend()
    if backend is None or backend == "disable":
        raise RenderingUnavailableError(
            "no headless OpenGL backend works (" + "; ".join(_ERRORS or ["MUJOCO_GL=disable"])
            + "); install the Debian packages libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 "
            "(scripts/install.sh does this as root) or set MUJOCO_GL yourself"
        )
    return backend
