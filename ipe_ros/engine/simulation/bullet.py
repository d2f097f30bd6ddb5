"""pybullet itself: the module loaded quietly, this process's DIRECT client, its C output silenced,
and the references its calls keep given back.

One DIRECT client per process (``client()``), created on first use and re-created after a fork or
a disconnect (more beside it only for islands simulated side by side). The rest of the engine
reaches pybullet through ``pybullet()``.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys

_PYBULLET = None
_CLIENTS: dict[int, int] = {}  # slot -> this process's DIRECT client in it
_CLIENT_PID: int | None = None
#: pybullet's software renderer, which every client loads: it turns each body's shapes into meshes
#: as the body is created (a floor plane ~0.5 ms). These clients only simulate (images come from
#: clients of their own, ``vision/tinyrenderer.py``), so it is unloaded: a `default` tower sample
#: 4% faster in one process, 1-2% in the worker pool, bit for bit the same (benchmarks/HISTORY.md).
RENDERER_PLUGIN = "tinyRendererPlugin"


@contextlib.contextmanager
def quiet_c_output():
    """Send fds 1 and 2 to /dev/null for the block: pybullet's C code prints a build banner on
    connect, which would clutter the CLI's output and logs."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no stdout/stderr at all: nothing to protect
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    try:
        yield
    finally:
        try:
            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


def pybullet():
    global _PYBULLET
    if _PYBULLET is None:
        with quiet_c_output():
            import pybullet
        _PYBULLET = pybullet
    return _PYBULLET


def client(slot: int = 0) -> int:
    """This process's pybullet DIRECT client (re-created after a fork or a disconnect). ``slot`` > 0:
    another one, for a world that must exist beside slot 0's (islands simulated side by side)."""
    global _CLIENT_PID
    p = pybullet()
    if _CLIENT_PID != os.getpid():
        _CLIENTS.clear()
        _CLIENT_PID = os.getpid()
    cid = _CLIENTS.get(slot)
    if cid is None or not p.isConnected(cid):
        with quiet_c_output():
            cid = _CLIENTS[slot] = p.connect(p.DIRECT)
            renderer = p.loadPlugin(RENDERER_PLUGIN, physicsClientId=cid)  # the static plugin's id, by its name
            if renderer >= 0:
                p.unloadPlugin(renderer, physicsClientId=cid)
    return cid


def without_leaked_references(call, arguments: tuple):
    """``call()``, then give back the references it kept to ``arguments`` and never released.

    pybullet 3.2.7 reads a mesh's ``vertices`` through ``PySequence_Fast`` without releasing what
    that returns: every sequence passed (the list and each vertex) is kept alive for ever, ~1.8 KB
    per hull per world built. The node builds a world for every question's geometry, and that alone
    grew it without bound (benchmarks/README, the soak). pybullet keeps no Python object after the
    call (it copies the numbers), so the excess references are released here; a pybullet that
    releases them itself leaves no excess and nothing is done."""
    before = _references(arguments)
    result = call()
    for i, excess in enumerate(after - was for after, was in zip(_references(arguments), before)):
        for _ in range(excess):
            ctypes.pythonapi.Py_DecRef(ctypes.py_object(arguments[i]))
    return result


def _references(objects: tuple) -> list[int]:
    """Each object's reference count, counted the same way every time (no loop variable or
    iterator holding one of them: ``zip`` keeps its last items)."""
    return [sys.getrefcount(objects[i]) for i in range(len(objects))]
