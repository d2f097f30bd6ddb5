"""Checking a scene once, where it enters the engine: every body's fields, the scene's count,
gravity, horizon and bodies against their support. Errors are :class:`~ipe_ros.engine.errors.SceneError`
naming the object and field (``objects[2].mass_kg``) and the fix."""

from __future__ import annotations

import math

import numpy as np

from . import limits, shapes
from ..errors import SceneError, shown
from .bodies import (DEFAULT_MAX_OBJECTS, MAX_HORIZON_S, MAX_SET_DOWN_M, QUATERNION_NORM_TOLERANCE, Body, Floor, Scene, Table,
                     deepest_into_support)


def _finite(values, path: str, what: str) -> None:
    arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise SceneError(path, f"{what} must be finite numbers, got {shown([float(v) for v in np.ravel(arr)])}")


def _check_vector(values, n: int, path: str, what: str, *, max_abs: float | None = None,
                  max_norm: float | None = None, why: str = "") -> None:
    if not isinstance(values, (tuple, list)) or len(values) != n:
        raise SceneError(path, f"{what} must be a list of {n} numbers, got {shown(values)}")
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(path, f"{what} must be a list of {n} numbers, got {shown(values)}")
    _finite(values, path, what)
    if max_abs is not None and max(abs(v) for v in values) > max_abs:
        raise SceneError(path, f"{what} must be within +-{max_abs:g}{why}, got {shown(list(values))}")
    if max_norm is not None and math.sqrt(sum(v * v for v in values)) > max_norm:
        raise SceneError(path, f"{what} must have a magnitude of at most {max_norm:g}{why}, got {shown(list(values))}")


def _check_name(value, path: str) -> None:
    """Names are printed in logs, messages and recordings: real text, of bounded length."""
    if not isinstance(value, str) or not value.strip():
        raise SceneError(path, "must be a non-empty string")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise SceneError(path, f"must be valid Unicode text (it holds a lone surrogate), got {shown(value)}") from None
    if len(value) > limits.MAX_NAME_CHARS:
        raise SceneError(path, f"must be at most {limits.MAX_NAME_CHARS} characters, got {len(value)}")
    if any(not c.isprintable() for c in value):
        raise SceneError(path, f"must be printable (no control characters), got {shown(value)}")


_COORDINATE = dict(max_abs=limits.MAX_COORDINATE_M, why=" m of the scene frame's origin (use a frame near the scene)")
_SPEED = dict(max_norm=limits.MAX_SPEED_M_S, why=" m/s (faster objects are projectiles, not scenes)")
_SPIN = dict(max_norm=limits.MAX_SPIN_RAD_S, why=" rad/s")


def _check_number(value, path: str, what: str, *, lo: float | None = None, lo_open: bool = False,
                  hi: float | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(path, f"{what} must be a number, got {shown(value)}")
    if not math.isfinite(value):
        raise SceneError(path, f"{what} must be finite, got {shown(value)}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        bound = f"> {lo:g}" if lo_open else f">= {lo:g}"
        raise SceneError(path, f"{what} must be {bound}, got {shown(value)}")
    if hi is not None and value > hi:
        raise SceneError(path, f"{what} must be <= {hi:g}, got {shown(value)}")


def validate_body(body: Body, path: str) -> None:
    """Check one body's own fields; raises SceneError naming ``path`` + the field."""
    _check_name(body.name, f"{path}.name")
    path = f"{path} ({shown(body.name)})"
    shapes.validate_shape(body.shape, f"{path}.shape")
    extents = body.extents_m
    if min(extents) < limits.MIN_SIZE_M or max(extents) > limits.MAX_SIZE_M:
        raise SceneError(f"{path}.shape", f"every extent must be within [{limits.MIN_SIZE_M:g}, {limits.MAX_SIZE_M:g}] m "
                                          f"(smaller bodies need ever finer steps; check the units), got "
                                          f"{shown(list(extents))}")
    _check_vector(body.position_m, 3, f"{path}.position_m", "position in metres", **_COORDINATE)
    _check_vector(body.orientation_xyzw, 4, f"{path}.orientation_xyzw", "quaternion (x, y, z, w)")
    norm = math.sqrt(sum(c * c for c in body.orientation_xyzw))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise SceneError(f"{path}.orientation_xyzw",
                         f"must be a unit quaternion (norm within {QUATERNION_NORM_TOLERANCE:g} of 1),"
                         f" got norm {norm:.6g}; normalise it")
    _check_number(body.friction, f"{path}.friction", "friction", lo=0.0, hi=limits.MAX_FRICTION)
    _check_number(body.restitution, f"{path}.restitution", "restitution", lo=0.0, hi=1.0)
    if not isinstance(body.group, str):
        raise SceneError(f"{path}.group", f"must be a string, got {shown(body.group)}")
    if body.group:
        _check_name(body.group, f"{path}.group")
    if not isinstance(body.static, bool):
        raise SceneError(f"{path}.static", f"must be true or false, got {shown(body.static)}")
    if body.mass_kg is not None and body.density_kg_m3 is not None:
        raise SceneError(f"{path}.mass_kg", "give mass_kg or density_kg_m3, not both")
    if body.mass_kg is None and body.density_kg_m3 is None and not body.static:
        raise SceneError(f"{path}.mass_kg", "a dynamic body needs mass_kg or density_kg_m3 (> 0)")
    if body.mass_kg is not None:
        _check_number(body.mass_kg, f"{path}.mass_kg", "mass in kg", lo=0.0, lo_open=True)
    if body.density_kg_m3 is not None:
        _check_number(body.density_kg_m3, f"{path}.density_kg_m3", "density in kg/m^3", lo=0.0,
                      lo_open=True)
    mass = body.resolved_mass_kg
    if not body.static and not limits.MIN_MASS_KG <= mass <= limits.MAX_MASS_KG:
        field = "mass_kg" if body.mass_kg is not None else "density_kg_m3"
        raise SceneError(f"{path}.{field}", f"the mass must be within [{limits.MIN_MASS_KG:g}, {limits.MAX_MASS_KG:g}] kg "
                                            f"(check the units), got {mass:.6g} kg")
    _check_vector(body.linear_velocity_m_s, 3, f"{path}.linear_velocity_m_s", "velocity in m/s", **_SPEED)
    _check_vector(body.angular_velocity_rad_s, 3, f"{path}.angular_velocity_rad_s", "angular velocity in rad/s",
                  **_SPIN)
    if body.static and body.moving:
        raise SceneError(f"{path}.linear_velocity_m_s", "a static body cannot move; drop its velocity or make it "
                                                        "dynamic")
    sigma = body.position_sigma_m
    if sigma is not None:
        if isinstance(sigma, (tuple, list)):
            _check_vector(sigma, 3, f"{path}.position_sigma_m", "position noise SDs (x, y, z) in metres",
                          max_abs=limits.MAX_SIGMA_M, why=" m (check the units)")
            if min(sigma) < 0:
                raise SceneError(f"{path}.position_sigma_m", f"noise SDs must be >= 0, got {shown(list(sigma))}")
        else:
            _check_number(sigma, f"{path}.position_sigma_m", "position noise SD in metres", lo=0.0,
                          hi=limits.MAX_SIGMA_M)
    if body.yaw_sigma_rad is not None:
        _check_number(body.yaw_sigma_rad, f"{path}.yaw_sigma_rad", "yaw noise SD in radians", lo=0.0, hi=math.pi)


_CHECKED = "_ipe_checked"


def validate_scene(scene: Scene, max_objects: int = DEFAULT_MAX_OBJECTS) -> Scene:
    """Check a whole scene; return it unchanged or raise :class:`SceneError`.

    Checks: well-formed shapes, finite numbers, positive sizes and masses, unit quaternions, unique
    names, at least one dynamic body, no more than ``max_objects`` bodies, gravity pointing down, a
    horizon within MAX_HORIZON_S, and no body starting below its support (a tolerance of 1% of the
    body's smallest extent absorbs rounding in the input). A scene is checked in full once: found
    valid and immutable all the way down (hashable), it is marked so, and a later check (where a
    request is costed, where it is predicted) compares only its object count with ``max_objects``.
    """
    if getattr(scene, _CHECKED, False):
        _check_count(scene, max_objects)
        return scene
    _validate(scene, max_objects)
    try:
        hash(scene)  # a list where a tuple belongs could change after the check: checked every time
    except TypeError:
        return scene
    object.__setattr__(scene, _CHECKED, True)  # frozen: the mark is not a field (equality, replace ignore it)
    return scene


def _check_count(scene: Scene, max_objects: int) -> None:
    support = scene.support
    n_objects = len(scene.objects) + (len(support.obstacles) if isinstance(support, Table) else 0)
    if n_objects > max_objects:
        raise SceneError("objects", f"{n_objects} objects exceed the maximum of {max_objects}; "
                                    "split the scene or raise max_objects")


def _validate(scene: Scene, max_objects: int) -> Scene:
    _check_name(scene.name, "name")
    _check_vector(scene.gravity_m_s2, 3, "gravity_m_s2", "gravity in m/s^2")
    if scene.gravity_m_s2[2] >= 0:
        raise SceneError("gravity_m_s2", f"z must be negative (z is up), got {shown(scene.gravity_m_s2[2])}")
    g = math.sqrt(sum(v * v for v in scene.gravity_m_s2))
    if not limits.MIN_GRAVITY_M_S2 <= g <= limits.MAX_GRAVITY_M_S2:
        raise SceneError("gravity_m_s2", f"the magnitude must be within [{limits.MIN_GRAVITY_M_S2:g}, "
                                         f"{limits.MAX_GRAVITY_M_S2:g}] m/s^2 (Earth: 9.81), got {shown(list(scene.gravity_m_s2))}")
    height = dict(lo=-limits.MAX_COORDINATE_M, hi=limits.MAX_COORDINATE_M)
    support = scene.support
    if isinstance(support, Floor):
        _check_number(support.friction, "support.friction", "friction", lo=0.0, hi=limits.MAX_FRICTION)
        _check_number(support.restitution, "support.restitution", "restitution", lo=0.0, hi=1.0)
        _check_number(support.height_m, "support.height_m", "floor height in metres", **height)
    elif isinstance(support, Table):
        _check_number(support.top_height_m, "support.top_height_m", "table top height in metres", **height)
        _check_vector(support.size_m, 2, "support.size_m", "table top (x, y) size in metres", **_COORDINATE)
        if min(support.size_m) <= 0:
            raise SceneError("support.size_m", f"both sizes must be > 0 metres, got {shown(list(support.size_m))}")
        _check_vector(support.center_xy_m, 2, "support.center_xy_m", "table centre (x, y) in metres", **_COORDINATE)
        _check_number(support.thickness_m, "support.thickness_m", "thickness in metres", lo=0.0,
                      lo_open=True, hi=limits.MAX_SIZE_M)
        _check_number(support.friction, "support.friction", "friction", lo=0.0, hi=limits.MAX_FRICTION)
        _check_number(support.restitution, "support.restitution", "restitution", lo=0.0, hi=1.0)
        if support.floor_z_m is not None:
            _check_number(support.floor_z_m, "support.floor_z_m", "floor height in metres", **height)
            if support.floor_z_m > support.top_height_m - support.thickness_m:
                raise SceneError("support.floor_z_m",
                                 f"must be at or below the table's underside "
                                 f"({support.top_height_m - support.thickness_m:g} m), got {shown(support.floor_z_m)}")
        for i, obstacle in enumerate(support.obstacles):
            if obstacle.static is not True:
                raise SceneError(f"support.obstacles[{i}] ({shown(obstacle.name)}).static",
                                 "obstacles are attached to the table and must be static: true")
            validate_body(obstacle, f"support.obstacles[{i}]")
    else:
        raise SceneError("support", f"must be a Floor or a Table, got {type(support).__name__}")

    if scene.horizon_s is not None:
        _check_number(scene.horizon_s, "horizon_s", "the simulated time in seconds", lo=0.0, lo_open=True,
                      hi=MAX_HORIZON_S)
    _check_number(scene.set_down_m, "set_down_m", "how far above its support an object is set down onto it, m",
                  lo=0.0, hi=MAX_SET_DOWN_M)
    _check_count(scene, max_objects)
    if not scene.dynamic_objects:
        raise SceneError("objects", "the scene has no dynamic object: nothing can fall")

    seen: set[str] = set()
    everything = [(f"objects[{i}]", b) for i, b in enumerate(scene.objects)]
    if isinstance(support, Table):
        everything += [(f"support.obstacles[{i}]", b) for i, b in enumerate(support.obstacles)]
    for path, body in everything:
        if path.startswith("objects"):
            validate_body(body, path)
        if body.name in seen:
            raise SceneError(f"{path}.name", f"duplicate name {shown(body.name)}; names must be unique")
        seen.add(body.name)
        lowest, ground = deepest_into_support(support, body)
        tolerance = 0.01 * body.smallest_extent_m
        if ground is not None and lowest < ground - tolerance:
            raise SceneError(f"{path} ({shown(body.name)}).position_m",
                             f"the body's lowest point z = {lowest:.6g} m is below the support surface "
                             f"at z = {ground:.6g} m; raise it by at least {ground - lowest:.6g} m")
    dynamic = {b.name for b in scene.dynamic_objects}
    for i, push in enumerate(scene.pushes):
        if push.name not in dynamic:
            raise SceneError(f"pushes[{i}].name", f"no dynamic object {shown(push.name)} in the scene")
        _check_number(push.at_s, f"pushes[{i}].at_s", "the push's time in seconds", lo=0.0, hi=MAX_HORIZON_S)
        _check_vector(push.velocity_change_m_s, 3, f"pushes[{i}].velocity_change_m_s", "a velocity change in m/s",
                      max_norm=limits.MAX_SPEED_M_S)
    masses = [(b.resolved_mass_kg, b.name) for b in scene.dynamic_objects]
    (heaviest, heavy_name), (lightest, light_name) = max(masses), min(masses)
    if lightest > 0 and heaviest / lightest > limits.MAX_MASS_RATIO:
        raise SceneError("objects", f"{shown(heavy_name)} is {heaviest / lightest:.4g} times as heavy as "
                                    f"{shown(light_name)}; mass ratios above {limits.MAX_MASS_RATIO:g}:1 are beyond what "
                                    "the solver converges on (check the units)")
    return scene
