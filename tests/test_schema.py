"""The published JSON Schema of the scene format: current, valid, never stricter than the engine, documented."""

from __future__ import annotations

import json
import re

import jsonschema
import pytest
from hypothesis import HealthCheck, given, settings

from ipe_ros.engine import SceneError, scenes_from_json
from ipe_ros.engine.scene import format as io
from ipe_ros.engine.scene.catalogue import capped_tower, scene_catalogue
from ipe_ros.engine.scene.schema import SCHEMA_PATH, scene_schema, schema_text
from ipe_ros.engine.scene.format import scene_to_dict
from tests.conftest import REPO
from tests.test_fuzz import mutated_scenes

VALIDATOR = jsonschema.Draft202012Validator(json.loads(SCHEMA_PATH.read_text()))


def test_the_committed_schema_is_the_generated_one_and_a_valid_schema():
    assert SCHEMA_PATH.read_text() == schema_text(), "regenerate it: python -m ipe_ros.engine.scene.schema"
    jsonschema.Draft202012Validator.check_schema(scene_schema())


def test_schema_and_reader_name_the_same_fields():
    defs = scene_schema()["$defs"]
    assert set(defs["object"]["properties"]) == set(io.OBJECT_REQUIRED) | set(io._OBJECT_OPTIONAL)
    assert set(defs["object"]["required"]) == set(io.OBJECT_REQUIRED)
    assert set(defs["scene"]["properties"]) == {"format", "horizon_s", "set_down_m", *io.SCENE_REQUIRED}
    assert set(defs["floor"]["properties"]) == set(io.FLOOR_FIELDS) | set(io.SUPPORT_OPTIONAL)
    assert set(defs["table"]["properties"]) == set(io.TABLE_FIELDS) | set(io.SUPPORT_OPTIONAL)
    assert set(defs["floor"]["required"]) == set(io.FLOOR_FIELDS)
    for kind, fields in io._SHAPE_FIELDS.items():
        assert set(defs[kind]["properties"]) == {"type", *fields, *io._SHAPE_OPTIONAL.get(kind, ())}, kind


def test_every_example_scene_is_valid_under_the_schema():
    scenes = [capped_tower(), *scene_catalogue(seed=3, count=25)]
    for scene in scenes:
        VALIDATOR.validate(scene_to_dict(scene))
    VALIDATOR.validate([scene_to_dict(s) for s in scenes[:3]])  # a file may hold a list of scenes


def _refused_by_schema(scene: dict) -> str:
    errors = sorted(VALIDATOR.iter_errors(scene), key=lambda e: list(e.absolute_path))
    return "; ".join(f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in errors)


@pytest.mark.parametrize("change, where", [
    (lambda s: s["objects"][0].update(colour="red"), "objects.0"),
    (lambda s: s["objects"][0].pop("friction"), "objects.0"),
    (lambda s: s["objects"][0]["shape"].update(extents_m=[0.2, 0.2, 20.0]), "objects.0.shape"),
    (lambda s: s.update(gravity_m_s2=[0.0, 0.0, 9.81]), "gravity_m_s2"),
    (lambda s: s["objects"][1].update(restitution=1.5), "objects.1"),
    (lambda s: s["support"].update(type="ramp"), "support"),
    (lambda s: s.update(horizon_s=120.0), "horizon_s"),
    (lambda s: s.update(set_down_m=-0.01), "set_down_m"),
    (lambda s: s.update(set_down_m=0.5), "set_down_m"),
])
def test_what_the_schema_can_say_it_refuses_as_the_engine_does(change, where):
    scene = scene_to_dict(capped_tower())
    change(scene)
    with pytest.raises(SceneError):
        scenes_from_json(json.dumps(scene))
    refused = _refused_by_schema(scene)
    assert refused and refused.split(":")[0].startswith(where), refused


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(mutated_scenes())
def test_every_scene_the_engine_accepts_is_valid_under_the_schema(scene):
    try:
        text = json.dumps(scene, allow_nan=False)
        scenes_from_json(text)
    except (SceneError, ValueError):
        return
    assert not _refused_by_schema(json.loads(text)), _refused_by_schema(json.loads(text))


def test_the_scene_format_document_describes_every_field_and_links_the_schema():
    document = (REPO / "docs" / "scene-format.md").read_text()
    assert "ipe_ros/schema/scene-2.json" in document
    defs = scene_schema()["$defs"]
    fields = {name for d in defs.values() for name in d.get("properties", {})} - {"type"}
    missing = sorted(f for f in fields if not re.search(rf"`[^`]*\b{re.escape(f)}\b", document))
    assert not missing, f"docs/scene-format.md does not mention {missing}"
