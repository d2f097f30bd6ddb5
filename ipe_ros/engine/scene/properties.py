"""A property's prior, as a scene's objects (``mass_prior``, ``friction_prior``, ``restitution_prior``),
the model-wide spreads (``PropertySpread``) and an observation's ``unknowns`` spell it.

Each prior maps its support onto the whole real line (a coordinate z): the sampler proposes and
adapts there (a Gaussian never strays outside a bounded prior), and weighs with the prior's density
in z, so the change of variable needs no Jacobian at the end.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass
from statistics import NormalDist
from typing import Mapping

import numpy as np

from ..errors import ConfigError, SceneError, shown

#: what each property may be, whatever a prior says (the scene reader's own bounds)
PROPERTY_BOUNDS = {"mass_kg": (1e-6, 1e6), "friction": (0.0, 10.0), "restitution": (0.0, 1.0)}
PROPERTIES = tuple(PROPERTY_BOUNDS)
#: the support's surface properties (it does not move: no mass)
SUPPORT_PROPERTIES = ("friction", "restitution")
#: how the scene format spells a property's prior
PRIOR_FIELDS = {prop: f"{prop.removesuffix('_kg')}_prior" for prop in PROPERTIES}


def _logistic_log_density(z: np.ndarray) -> np.ndarray:
    return -np.logaddexp(0.0, z) - np.logaddexp(0.0, -z)


def _logit(u: float) -> float:
    u = min(max(u, 1e-12), 1 - 1e-12)
    return math.log(u) - math.log1p(-u)


def _probit(u: float) -> float:
    return NormalDist().inv_cdf(min(max(u, 1e-12), 1 - 1e-12))


@dataclass(frozen=True)
class _Interval:
    """Uniform on [low, high] after ``_scaled`` (the identity, or log); z = logit of the position in it."""

    low: float
    high: float

    _scaled, _unscaled = staticmethod(lambda x: x), staticmethod(lambda y: y)

    def value(self, z):
        a, b = self._scaled(self.low), self._scaled(self.high)
        return self._unscaled(a + (b - a) / (1.0 + np.exp(-np.asarray(z, float))))

    def coordinate(self, x):
        a, b = self._scaled(self.low), self._scaled(self.high)
        u = (self._scaled(np.asarray(x, float)) - a) / (b - a)
        return np.log(u) - np.log1p(-u)

    def log_density_z(self, z):
        return _logistic_log_density(np.asarray(z, float))

    @staticmethod
    def z_from_uniform(u: float) -> float:
        return _logit(u)


@dataclass(frozen=True)
class Uniform(_Interval):
    """Uniform on [low, high]."""

    def to_dict(self) -> dict:
        return {"uniform": [self.low, self.high]}


@dataclass(frozen=True)
class LogUniform(_Interval):
    """Uniform in log x on [low, high] (scale-free: a mass of 0.1 kg as likely as one of 1 kg per decade)."""

    _scaled, _unscaled = staticmethod(np.log), staticmethod(np.exp)

    def to_dict(self) -> dict:
        return {"log_uniform": [self.low, self.high]}


class _NormalCoordinate:
    """A prior whose coordinate z is a standard normal."""

    def log_density_z(self, z):
        z = np.asarray(z, float)
        return -0.5 * z * z - 0.5 * math.log(2 * math.pi)

    @staticmethod
    def z_from_uniform(u: float) -> float:
        return _probit(u)


@dataclass(frozen=True)
class LogNormal(_NormalCoordinate):
    """log x ~ N(log median, log_sd^2); z = (log x - log median) / log_sd."""

    median: float
    log_sd: float

    def value(self, z):
        return self.median * np.exp(self.log_sd * np.asarray(z, float))

    def coordinate(self, x):
        return np.log(np.asarray(x, float) / self.median) / self.log_sd

    def to_dict(self) -> dict:
        return {"log_sd": self.log_sd, "median": self.median}


@dataclass(frozen=True)
class Normal(_NormalCoordinate):
    """x ~ N(mean, sd^2): a nuisance (an initial velocity estimated from the frames), z = (x - mean) / sd."""

    mean: float
    sd: float

    def value(self, z):
        return self.mean + self.sd * np.asarray(z, float)

    def coordinate(self, x):
        return (np.asarray(x, float) - self.mean) / self.sd

    def to_dict(self) -> dict:
        return {"normal": [self.mean, self.sd]}


Prior = Uniform | LogUniform | LogNormal | Normal


def prior_from_dict(data, field: str, prop: str, given: float | None = None) -> Prior:
    """A prior from its JSON spelling; ``given`` is the scene's value (a log-normal's median unless
    it names its own). Raises ConfigError naming ``field`` for anything outside ``prop``'s bounds."""
    if prop not in PROPERTY_BOUNDS:
        raise ConfigError(field, f"unknown property {shown(prop)}; choose from {', '.join(PROPERTIES)}")
    lo, hi = PROPERTY_BOUNDS[prop]
    if not isinstance(data, dict) or len(set(data) - {"median"}) != 1:
        raise ConfigError(field, "must be one of {\"uniform\": [LOW, HIGH]}, {\"log_uniform\": [LOW, HIGH]} or "
                                 f"{{\"log_sd\": SD}} (optionally with \"median\"), got {shown(data)}")
    kind = next(k for k in data if k != "median")
    if kind in ("uniform", "log_uniform"):
        bounds = data[kind]
        if "median" in data:
            raise ConfigError(f"{field}.median", f"only a log_sd prior has a median; {kind} has bounds only")
        if not isinstance(bounds, list) or len(bounds) != 2 or not all(_finite(v) for v in bounds):
            raise ConfigError(f"{field}.{kind}", f"must be [LOW, HIGH], two finite numbers, got {shown(bounds)}")
        low, high = float(bounds[0]), float(bounds[1])
        floor = lo if kind == "uniform" else max(lo, 1e-9)
        if not (floor <= low < high <= hi):
            raise ConfigError(f"{field}.{kind}", f"must satisfy {floor:g} <= LOW < HIGH <= {hi:g} for {prop} "
                                                 f"(physical bounds), got {shown(bounds)}")
        return Uniform(low, high) if kind == "uniform" else LogUniform(low, high)
    if kind == "log_sd":
        if prop == "restitution":
            raise ConfigError(field, "a restitution is bounded by 1: give it a uniform prior, not log_sd")
        sd = data["log_sd"]
        if not _finite(sd) or not 0 < sd <= 5:
            raise ConfigError(f"{field}.log_sd", f"must be a number in (0, 5], got {shown(sd)}")
        median = data.get("median", given)
        if not _finite(median) or not (max(lo, 1e-9) <= median <= hi):
            raise ConfigError(f"{field}.median", f"must be a number in [{max(lo, 1e-9):g}, {hi:g}] for {prop} "
                                                 f"(the scene's value when left out), got {shown(median)}")
        return LogNormal(float(median), float(sd))
    raise ConfigError(field, f"unknown prior {shown(kind)}; choose uniform, log_uniform or log_sd")


def priors_to_dict(priors) -> dict:
    """An owner's priors as the scene format spells them (``mass_prior``, ...)."""
    return {PRIOR_FIELDS[prop]: prior.to_dict() for prop, prior in priors}


def priors_from_dict(data: dict, path: str, properties: tuple[str, ...], given: dict) -> tuple:
    """(property, prior) for each ``<property>_prior`` field of a scene's object or support ``data``
    (at ``path``); ``given``: its values, which a log-normal centres on (a mass given as a density:
    the density times the shape's volume), and ``static``. A SceneError names the field."""
    out = []
    for prop in properties:
        key = PRIOR_FIELDS[prop]
        if key not in data:
            continue
        where = f"{path}.{key}" if path else key
        if prop == "mass_kg" and given.get("static"):
            raise SceneError(where, "a static object does not move, so its mass plays no part; remove the prior")
        try:
            out.append((prop, prior_from_dict(data[key], where, prop, given.get(prop))))
        except ConfigError as exc:
            raise SceneError(exc.field, exc.problem) from None
    return tuple(out)


def _finite(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


@dataclass(frozen=True)
class PropertySpread:
    """Model-wide priors for every surface and dynamic body without a prior of its own (off at 0):
    a log-normal mass and friction around the scene's value (``*_log_sd``, log SD), a restitution
    uniform within +-``restitution_half_width`` of the scene's value, cut to [0, 1]."""

    mass_log_sd: float = 0.0
    friction_log_sd: float = 0.0
    restitution_half_width: float = 0.0

    def __post_init__(self) -> None:
        for name, top in (("mass_log_sd", 5.0), ("friction_log_sd", 5.0), ("restitution_half_width", 1.0)):
            value = getattr(self, name)
            if not _finite(value) or not 0 <= value <= top:
                raise ConfigError(name, f"must be a number in [0, {top:g}] (0: off), got {shown(value)}")

    def prior(self, prop: str, given: float, moves: bool) -> Prior | None:
        """The prior of a surface's or body's ``prop`` whose scene value is ``given`` (None: none);
        ``moves``: a dynamic body (a mass only matters there)."""
        if prop == "mass_kg":
            return LogNormal(given, self.mass_log_sd) if self.mass_log_sd and moves and given > 0 else None
        if prop == "friction":
            return LogNormal(given, self.friction_log_sd) if self.friction_log_sd and given > 0 else None
        w = self.restitution_half_width
        return Uniform(max(0.0, given - w), min(1.0, given + w)) if w else None


def uncertain_properties(scene, spread: PropertySpread | None) -> tuple[tuple[str, str, Prior], ...]:
    """Every (owner, property, prior) of ``scene`` that a sample draws, in a fixed order: the
    objects' (then the table's obstacles') own priors or the model-wide ``spread``, then the
    support's (owner ``"support"``)."""
    out = []
    obstacles = getattr(scene.support, "obstacles", ())
    for body in scene.objects + tuple(obstacles):
        own = dict(body.priors)
        for prop in PROPERTIES:
            given = body.resolved_mass_kg if prop == "mass_kg" else getattr(body, prop)
            prior = own.get(prop) or (spread.prior(prop, given, not body.static) if spread else None)
            if prior is not None:
                out.append((body.name, prop, prior))
    own = dict(scene.support.priors)
    for prop in SUPPORT_PROPERTIES:
        prior = own.get(prop) or (spread.prior(prop, getattr(scene.support, prop), False) if spread else None)
        if prior is not None:
            out.append(("support", prop, prior))
    return tuple(out)


def draw_uncertain(uncertain, seed: np.random.SeedSequence) -> tuple[float, ...]:
    """One value per ``uncertain`` property (``uncertain_properties``), each from its own stream of
    the sample's ``seed`` keyed by the owner's name and the property: a value does not depend on
    which other properties are uncertain or where its owner stands in the scene, so a robot
    question's variants (an object removed, one placed) draw the others' values unchanged."""
    values = []
    for owner, prop, prior in uncertain:
        key = (2, zlib.crc32(owner.encode("utf-8", "backslashreplace")), PROPERTIES.index(prop))
        u = np.random.default_rng(np.random.SeedSequence(seed.entropy, spawn_key=seed.spawn_key + key)).random()
        lo, hi = PROPERTY_BOUNDS[prop]
        values.append(float(min(max(prior.value(prior.z_from_uniform(u)), lo), hi)))
    return tuple(values)


def with_properties(scene, assigned: Mapping[tuple[str, str], float],
                    priors: Mapping[tuple[str, str], Prior] | None = None):
    """The scene with ``assigned`` ((owner name or "support", property) -> value) in place of its
    values (a mass replaces a density), and without the priors of what was assigned, unless
    ``priors`` (the same keys) gives new ones (a posterior, around the value assigned)."""
    priors = priors or {}

    def changed(owner, name):
        fields = {prop: float(value) for (who, prop), value in assigned.items() if who == name}
        if not fields:
            return owner
        if "mass_kg" in fields:
            fields["density_kg_m3"] = None
        kept = [(prop, prior) for prop, prior in owner.priors if prop not in fields]
        new = {prop: priors[(name, prop)] for prop in fields if (name, prop) in priors}
        fields["priors"] = tuple(sorted(kept + list(new.items()), key=lambda item: PROPERTIES.index(item[0])))
        return dataclasses.replace(owner, **fields)

    return _each_owner(scene, changed)


def without_priors(scene):
    """The scene with every value as given, exact (no priors)."""
    return _each_owner(scene, lambda owner, _name: dataclasses.replace(owner, priors=()) if owner.priors else owner)


def _each_owner(scene, change):
    """The scene with ``change(owner, name)`` applied to everything that has surface properties:
    its objects, the support (named "support") and a table's obstacles."""
    support = change(scene.support, "support")
    if getattr(support, "obstacles", ()):
        support = dataclasses.replace(support, obstacles=tuple(change(b, b.name) for b in support.obstacles))
    return dataclasses.replace(scene, objects=tuple(change(b, b.name) for b in scene.objects), support=support)


def posterior_prior(prop: str, median: float, low_90: float, high_90: float) -> Prior | None:
    """A prior that carries a posterior's 90% interval into predictions: log-normal around the median
    with the interval's log width (a mass, a friction), uniform over the interval (a restitution,
    bounded by 1); None for an interval that is a point."""
    if not high_90 > low_90:
        return None
    if prop == "restitution":
        return Uniform(max(0.0, low_90), min(1.0, high_90))
    if low_90 <= 0:
        return None
    return LogNormal(float(median), float(math.log(high_90 / low_90) / (2 * NormalDist().inv_cdf(0.95))))
