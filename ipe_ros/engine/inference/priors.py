"""A property's prior, as the observation's ``unknowns`` (and a refined scene) spell it.

Each prior maps its support onto the whole real line (a coordinate z): the sampler proposes and
adapts there (a Gaussian never strays outside a bounded prior), and weighs with the prior's density
in z, so the change of variable needs no Jacobian at the end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..errors import ConfigError, shown

#: what each property may be, whatever a prior says (the scene reader's own bounds)
PROPERTY_BOUNDS = {"mass_kg": (1e-6, 1e6), "friction": (0.0, 10.0), "restitution": (0.0, 1.0)}
PROPERTIES = tuple(PROPERTY_BOUNDS)


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
        sd = data["log_sd"]
        if not _finite(sd) or not 0 < sd <= 5:
            raise ConfigError(f"{field}.log_sd", f"must be a number in (0, 5], got {shown(sd)}")
        median = data.get("median", given)
        if not _finite(median) or not (max(lo, 1e-9) <= median <= hi):
            raise ConfigError(f"{field}.median", f"must be a number in [{max(lo, 1e-9):g}, {hi:g}] for {prop} "
                                                 f"(the scene's value when left out), got {shown(median)}")
        if prop == "restitution":
            raise ConfigError(field, "a restitution is bounded by 1: give it a uniform prior, not log_sd")
        return LogNormal(float(median), float(sd))
    raise ConfigError(field, f"unknown prior {shown(kind)}; choose uniform, log_uniform or log_sd")


def _finite(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
