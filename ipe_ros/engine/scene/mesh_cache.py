"""The meshes' decomposition cache: each mesh's convex parts and mass properties, keyed by the file's
content, its scale and the decomposition's settings (``meshes._compound``), in
``$IPE_CACHE_DIR/convex_parts``. Read and written inside its folder only (``safe_files``), and an
entry is taken only once it describes its mesh (``verified_parts``): a link, a FIFO, a folder or a
planted entry is named and the mesh decomposed again. A decomposition that failed or ran out of
time is remembered beside them (``remembered_refusal``): asked again, the mesh is refused at once,
not decomposed again for minutes. Its entries together hold at most ``MAX_CACHE_BYTES``: writing
one removes the oldest beyond that.
"""

from __future__ import annotations

import collections
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from ..safe_files import UnsafeEntry, open_folder, read_entry, trim_folder, write_entry

#: cache keys whose entries were found to describe their mesh in this process
VERIFIED: set[str] = set()
#: a mesh cache entry holds a few hundred hull points: far under this
MAX_CACHE_ENTRY_BYTES = 4 * 2**20
#: the cache's entries together (thousands of meshes' parts): beyond, the oldest are removed on writing
MAX_CACHE_BYTES = 256 * 2**20
#: refusals remembered in this process too (where the cache folder cannot be written), newest kept
MAX_REMEMBERED_IN_PROCESS = 256
_REFUSED: collections.OrderedDict[str, dict] = collections.OrderedDict()


def _report(line: str) -> None:
    print(line, file=sys.stderr)


def _entry(folder: Path, key: str) -> Path:
    return folder / f"{key}.json"


def _refusal_entry(folder: Path, key: str) -> Path:
    return folder / f"{key}.refused.json"


def remembered_refusal(folder: Path, key: str, within_s: float | None) -> str | None:
    """Why the mesh under ``key`` was refused before, where that still holds: a failed decomposition
    always; one that ran out of time where ``within_s`` (the time now allowed, None: no limit) is no
    longer than the time it had. None: decompose it."""
    refusal = _REFUSED.get(key) or _read_refusal(folder, key)
    if refusal is None:
        return None
    if refusal["kind"] == "time" and (within_s is None or within_s > refusal["within_s"]):
        return None
    when = time.strftime("%Y-%m-%d %H:%M", time.localtime(refusal["at_s"]))
    return (f"{refusal['reason']} (remembered from {when}; remove {_refusal_entry(folder, key)} "
            "to try again)")


def _read_refusal(folder: Path, key: str) -> dict | None:
    try:
        raw = _read(folder, _refusal_entry(folder, key).name, 64 * 1024)
        data = json.loads(raw) if raw is not None else None
        if not isinstance(data, dict) or data.get("key") != key or data.get("kind") not in ("failed", "time") \
                or not isinstance(data.get("reason"), str):
            return None
        return {"kind": data["kind"], "reason": data["reason"][:2000], "within_s": float(data.get("within_s") or 0.0),
                "at_s": float(data.get("at_s") or 0.0)}
    except (UnsafeEntry, OSError, ValueError, TypeError):
        return None


def remember_refusal(folder: Path, key: str, reason: str, within_s: float | None) -> None:
    """Remember that the mesh under ``key`` was refused: ``within_s`` the time its decomposition had
    when it ran out (None: it failed, and fails again)."""
    refusal = {"key": key, "kind": "failed" if within_s is None else "time", "reason": reason,
               "within_s": within_s, "at_s": time.time()}
    _REFUSED[key] = refusal
    _REFUSED.move_to_end(key)
    while len(_REFUSED) > MAX_REMEMBERED_IN_PROCESS:
        _REFUSED.popitem(last=False)
    _write(folder, _refusal_entry(folder, key).name, json.dumps(refusal).encode())


def verified_parts(folder: Path, key: str, load) -> tuple[list[np.ndarray], float, tuple, tuple, str | None] | None:
    """The entry under ``key`` once it describes its mesh (``load()``: the mesh, loaded to check it
    once per process), or None where there is none usable (named where it is refused): parts,
    volume, centre of mass, inertia per kg, and how an open mesh was repaired (None: closed)."""
    cached = _cached_parts(folder, key)
    if cached is None or key in VERIFIED:
        return cached
    why = _describes(cached, load())
    if why is not None:
        _report(f"ipe: ignoring mesh cache entry {_entry(folder, key)} and decomposing again: {why}")
        return None
    VERIFIED.add(key)
    return cached


def has_parts(folder: Path, key: str) -> bool:
    """Whether an entry is stored under ``key`` (checked against its mesh when read, not here)."""
    return _cached_parts(folder, key) is not None


def mass_properties(mesh) -> tuple[float, tuple, tuple]:
    """The solid's volume, centre of mass and inertia about it per kg (trimesh's at density 1 weighs
    its volume)."""
    inertia = np.diag(np.asarray(mesh.moment_inertia, float)) / float(mesh.mass)
    return float(mesh.volume), tuple(float(v) for v in mesh.center_mass), tuple(float(v) for v in inertia)


def _describes(cached: tuple, mesh) -> str | None:
    """Why a cache entry does not describe ``mesh`` (None: it does): its mass properties must be the
    mesh's own, its parts within the mesh's bounds and holding about its volume. A planted entry
    that changes the object's mass, balance or extent is caught; one that reshuffles parts within
    them would need the decomposition again to tell."""
    parts, volume, centre, inertia, _ = cached
    own_volume, own_centre, own_inertia = mass_properties(mesh)
    if not (np.isclose(volume, own_volume, rtol=1e-6) and np.allclose(centre, own_centre, rtol=1e-6, atol=1e-9)
            and np.allclose(inertia, own_inertia, rtol=1e-6, atol=1e-12)):
        return "its volume, centre of mass or inertia is not the mesh's"
    low, high = mesh.bounds
    margin = 0.02 * float(np.max(high - low))
    if any(np.any(p < low - margin) or np.any(p > high + margin) for p in parts):
        return "a part reaches beyond the mesh"
    from scipy.spatial import ConvexHull as QHull

    try:
        held = sum(QHull(p).volume for p in parts)
    except Exception:  # noqa: BLE001 - qhull's errors: a degenerate part
        return "a part is not a solid hull"
    if not 0.5 * own_volume <= held <= 3.0 * own_volume:
        return f"its parts hold {held / own_volume:.2f}x the mesh's volume"
    return None


def _cached_parts(folder: Path, key: str) -> tuple[list[np.ndarray], float, tuple, tuple, str | None] | None:
    """The parts, volume, centre of mass and inertia per kg stored under ``key`` (JSON, never code),
    or None when there are none usable (a link, a FIFO or a folder at the entry's name, or at the
    cache folder's, is never followed: named and decomposed again)."""
    try:
        raw = _read(folder, _entry(folder, key).name, MAX_CACHE_ENTRY_BYTES)
        if raw is None:
            return None
        data = json.loads(raw)
        parts = [np.asarray(p, float) for p in data["parts"]]
        volume, centre = float(data["volume_m3"]), tuple(float(v) for v in data["centre_of_mass_m"])
        inertia = tuple(float(v) for v in data["inertia_diagonal_per_kg_m2"])
        repaired = data.get("repaired")
        if data.get("key") != key or not parts or any(p.ndim != 2 or p.shape[1] != 3 or len(p) < 4 for p in parts) \
                or len(centre) != 3 or len(inertia) != 3 or not isinstance(repaired, (str, type(None))):
            return None
        return parts, volume, centre, inertia, None if repaired is None else repaired[:500]
    except UnsafeEntry as exc:
        _report(f"ipe: ignoring mesh cache entry {_entry(folder, key)} and decomposing again: {exc}")
        return None
    except (OSError, ValueError, KeyError, TypeError):
        return None


def store_parts(folder: Path, key: str, parts: list[np.ndarray], volume_m3: float, centre_m: tuple,
                 inertia_per_kg_m2: tuple, repaired: str | None = None) -> None:
    """Written inside the cache only (``safe_files.write_entry``: a temporary file created anew,
    renamed over the entry), so a reader never sees half an entry and a planted link is not written
    through; once written, the entry is this process's own (``VERIFIED``), not before: what a failed
    write left at its name is checked when read."""
    data = json.dumps({"key": key, "parts": [p.tolist() for p in parts], "volume_m3": volume_m3,
                       "centre_of_mass_m": list(centre_m),
                       "inertia_diagonal_per_kg_m2": list(inertia_per_kg_m2),
                       **({"repaired": repaired} if repaired is not None else {})}).encode()
    if _write(folder, _entry(folder, key).name, data):
        VERIFIED.add(key)


def _read(folder: Path, name: str, max_bytes: int) -> bytes | None:
    """The entry ``name``'s bytes, or None where the folder or the entry is not there; UnsafeEntry
    where either is not what the cache writes (``safe_files``)."""
    fd = open_folder(folder, create=False, owner="the mesh cache")
    if fd is None:
        return None
    try:
        return read_entry(fd, name, max_bytes)
    finally:
        os.close(fd)


def _write(folder: Path, name: str, data: bytes) -> bool:
    """``data`` as the entry ``name`` (then the oldest entries beyond MAX_CACHE_BYTES removed);
    whether it was written (a read-only home, or a link where the cache belongs: not)."""
    try:
        fd = open_folder(folder, create=True, owner="the mesh cache")
    except (UnsafeEntry, OSError):
        return False
    try:
        write_entry(fd, name, data)
        trim_folder(fd, ".json", MAX_CACHE_BYTES, keep=name)  # a bounded disk
        return True
    except (UnsafeEntry, OSError):
        return False
    finally:
        os.close(fd)
