"""Numerical health of a rollout: divergence is a named error, never a silent wrong answer."""

from __future__ import annotations

import numpy as np

from ..errors import PhysicsError

_FIX = "use a smaller time step or more solver iterations"


def speed_limit_m_s(gravity_m_s2: float, horizon_s: float, push_m_s2: float, push_duration_s: float) -> float:
    """The fastest any box can honestly move: free fall for the whole horizon plus the push's dv.

    Anything faster means the solver injected energy (diverged).
    """
    return 2.0 * (gravity_m_s2 * horizon_s + push_m_s2 * min(push_duration_s, horizon_s)) + 1.0


def check_speeds(speeds_m_s: np.ndarray, limit_m_s: float, t_s: float) -> None:
    """Raise PhysicsError for a non-finite speed or one above the physical bound."""
    if not np.all(np.isfinite(speeds_m_s)):
        raise PhysicsError(f"non-finite velocity at t = {t_s:.3f} s; {_FIX}")
    if speeds_m_s.max() > limit_m_s:
        raise PhysicsError(f"a box reached {speeds_m_s.max():.3g} m/s at t = {t_s:.3f} s,"
                           f" above the physical bound {limit_m_s:.3g} m/s (solver divergence); {_FIX}")


def check_final_poses(positions_m: np.ndarray, orientations_xyzw: np.ndarray) -> None:
    if not (np.all(np.isfinite(positions_m)) and np.all(np.isfinite(orientations_xyzw))):
        raise PhysicsError(f"non-finite final pose; {_FIX}")
