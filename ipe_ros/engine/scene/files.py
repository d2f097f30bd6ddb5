"""Scenes from files: a JSON scene file (``scene_io``'s format) or the paper's tower CSV, by extension.
Files are read as UTF-8; a file that is not is named with its first bad byte."""

from __future__ import annotations

import csv
import os
from collections import OrderedDict
from pathlib import Path
from typing import Iterable

from ..errors import SceneError, shown
from .bodies import DEFAULT_MAX_OBJECTS, Box, Floor, Scene
from .validation import validate_scene
from .format import OnRefused, RefusedScene, scenes_from_json
from .meshes import MeshAccess

_CSV_COLUMNS = ("name", "object", "friction", "mass", "pos_x", "pos_y", "pos_z", "quat_w", "quat_x",
                "quat_y", "quat_z", "restitution", "scale_x", "scale_y", "scale_z")
_CSV_OPTIONAL = ("", "shape", "blocktype", "ratio")
#: The authors' gravity (their README: -9.8).
PAPER_GRAVITY_M_S2 = (0.0, 0.0, -9.8)
#: pybullet multiplies the friction of two touching bodies: a floor of 1.0 leaves each block's own
#: coefficient (0.894) in force against the ground.
PAPER_FLOOR_FRICTION = 1.0


def scenes_from_tower_csv(path: str | Path, towers: Iterable[str] | None = None,
                          max_objects: int = DEFAULT_MAX_OBJECTS, on_refused: OnRefused | None = None) -> list[Scene]:
    """Load the paper's tower stimuli (one row per block; see shared/data/battaglia2013/README.md).

    Units are taken as metres and kilograms; blocks with ``blocktype`` 1 get group "heavy", the rest
    "light". Rows are grouped by (name, ratio): where a file holds a tower at several mass ratios the
    scene name gets a ``@ratio=R`` suffix. ``towers`` selects by base name or full scene name. With
    ``on_refused``, a tower that cannot be read is handed to it and the others are returned (the
    file's own structure, its columns and rows, must still be right).
    """
    path = Path(path)
    grouped: "OrderedDict[tuple[str, str], list[dict[str, str]]]" = OrderedDict()
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle, strict=True)
        try:
            columns = reader.fieldnames or []
            missing = [c for c in _CSV_COLUMNS if c not in columns]
            if missing:
                raise SceneError(f"{path.name}", f"not a tower CSV: missing columns {', '.join(missing)}")
            unknown = [c for c in columns if c not in _CSV_COLUMNS + _CSV_OPTIONAL]
            if unknown:
                raise SceneError(f"{path.name}", f"unknown column {shown(unknown[0])}; the columns are "
                                                 f"{', '.join(_CSV_COLUMNS + _CSV_OPTIONAL[1:])} (and an unnamed index)")
            for row in reader:
                where = f"{path.name}:{reader.line_num}"
                if None in row:
                    raise SceneError(where, f"{len(columns) + len(row[None])} values on a row of a "
                                            f"{len(columns)}-column file; remove the extra values")
                if any(value is None for value in row.values()):
                    raise SceneError(where, f"fewer values than the {len(columns)} columns; complete the row")
                ratio = row.get("ratio") or "1"
                try:
                    float(ratio)
                except ValueError:
                    raise SceneError(f"{where}.ratio", f"must be a number, got {shown(ratio)}") from None
                grouped.setdefault((row["name"], ratio), []).append(row)
        except csv.Error as exc:
            raise SceneError(path.name, f"not readable as CSV after line {reader.line_num} ({exc})") from None
    ratios_per_name: dict[str, int] = {}
    for name, _ratio in grouped:
        ratios_per_name[name] = ratios_per_name.get(name, 0) + 1

    wanted = None if towers is None else set(towers)
    scenes: list[Scene] = []
    refused_names: set[str] = set()
    refused = 0
    for position, ((name, ratio), rows) in enumerate(grouped.items()):
        scene_name = name if ratios_per_name[name] == 1 else f"{name}@ratio={float(ratio):g}"
        if wanted is not None and name not in wanted and scene_name not in wanted:
            continue
        try:
            scenes.append(_tower_scene(path, scene_name, rows, max_objects))
        except SceneError as exc:
            if on_refused is None:
                raise
            refused_names |= {scene_name, name}
            refused += 1
            on_refused(RefusedScene(position, scene_name, exc))
    if not scenes and refused:
        raise SceneError(path.name, f"none of the {refused} towers asked for can be read (each refusal is reported)")
    if wanted is not None:
        found = {s.name for s in scenes} | {s.name.split("@", 1)[0] for s in scenes} | refused_names
        unknown = sorted(wanted - found)
        if unknown:
            raise SceneError("--tower", f"no tower named {shown(unknown[0])} in {path.name}")
    if not scenes:
        raise SceneError(path.name, "the file holds no towers")
    return scenes


def _tower_scene(path: Path, scene_name: str, rows: list[dict[str, str]], max_objects: int) -> Scene:
    boxes = []
    for row in rows:
        where = f"{path.name}:{scene_name}:{row['object']}"
        try:
            values = {c: float(row[c]) for c in _CSV_COLUMNS[2:]}
        except ValueError as exc:
            raise SceneError(where, f"non-numeric value ({exc})") from None
        blocktype = row.get("blocktype", "0") or "0"
        boxes.append(Box(
            name=row["object"],
            extents_m=(values["scale_x"], values["scale_y"], values["scale_z"]),
            position_m=(values["pos_x"], values["pos_y"], values["pos_z"]),
            orientation_xyzw=(values["quat_x"], values["quat_y"], values["quat_z"], values["quat_w"]),
            friction=values["friction"],
            restitution=values["restitution"],
            mass_kg=values["mass"],
            group="heavy" if blocktype.strip() in ("1", "1.0") else "light",
        ))
    scene = Scene(name=scene_name, objects=tuple(boxes),
                  support=Floor(friction=PAPER_FLOOR_FRICTION, restitution=0.0),
                  gravity_m_s2=PAPER_GRAVITY_M_S2)
    try:
        return validate_scene(scene, max_objects=max_objects)
    except SceneError as exc:
        raise SceneError(f"{path.name}:{scene_name}:{exc.field}", exc.problem) from None


def load_scenes(path: str | Path, towers: Iterable[str] | None = None,
                max_objects: int = DEFAULT_MAX_OBJECTS, on_refused: OnRefused | None = None,
                decompose_within_s: float | None = None) -> list[Scene]:
    """Load a JSON scene file or a paper-format tower CSV, by extension. ``on_refused``: see
    ``scenes_from_json``; without it any unreadable scene ends the read. ``decompose_within_s``: the
    most seconds each mesh not yet cached may take to decompose (None: no limit)."""
    path = Path(path)
    if not path.exists():
        raise SceneError(str(path), "no such file")
    try:
        if path.suffix.lower() == ".csv":
            return scenes_from_tower_csv(path, towers, max_objects, on_refused)
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(str(path), f"not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start}); "
                                    "save the file as UTF-8") from None
    refusals: list[RefusedScene] = []
    wanted = None if towers is None else set(towers)

    def refuse(refusal: RefusedScene) -> None:  # handed on at once: the read may still end in an error
        if wanted is None or refusal.name in wanted:
            refusals.append(refusal)
            on_refused(refusal)

    # a file's meshes are read beside it and under the folders $IPE_MESH_PATH names (os.pathsep-separated)
    roots = (path.resolve().parent, *(Path(p).resolve() for p in os.environ.get("IPE_MESH_PATH", "").split(os.pathsep)
                                      if p))
    scenes = scenes_from_json(text, max_objects, refuse if on_refused is not None else None,
                              MeshAccess(roots=roots, base=path.resolve().parent, decompose_within_s=decompose_within_s))
    if wanted is not None:
        picked = [s for s in scenes if s.name in wanted]
        missing = sorted(wanted - {s.name for s in picked} - {r.name for r in refusals})
        if missing:
            raise SceneError("--tower", f"no scene named {shown(missing[0])} in {path.name}")
        scenes = picked
    return scenes
