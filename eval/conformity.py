"""Conformity of one measured pose with a tolerance, by the guarded rule of ISO 14253-1.

A single measurement y of a component with standard uncertainty u (1 sigma) is compared with a
symmetric tolerance zone [-T, T] about the nominal docked pose (X = Y = Z = 0 mm, alpha = beta =
gamma = 0 deg: B's frame coincides with D when the sections are perfectly docked,
conventions.md). The guard band is the expanded uncertainty U = k u (coverage factor k, 2 for
about 95 % under a Gaussian):

- IN when |y| + U <= T (conformity proven: the whole interval y +- U is in the zone);
- OUT when |y| - U > T (non-conformity proven: the whole interval is outside);
- UNDECIDED otherwise (the interval straddles a limit), and when a value or its uncertainty is not finite.

Why and how: docs/acceptance.md, "Conformity of one pose".
"""
from __future__ import annotations

import math

from dockfactory.eval.gate_statistic import gate_statistic
from dockfactory.core.errors import DockfactoryError
from dockfactory.core.names import POSE_KEYS
from dockfactory.eval.acceptance import EXIT_NOT_PROVEN, AcceptanceSpec

IN, OUT, UNDECIDED = "IN", "OUT", "UNDECIDED"
COVERAGE_K = 2.0   # k of U = k u: about 95 % coverage for a Gaussian (JCGM 100, 6.3)
EXIT_STATUS = {IN: 0, OUT: 1, UNDECIDED: EXIT_NOT_PROVEN}
_RANK = {IN: 0, UNDECIDED: 1, OUT: 2}   # OUT is the worst: it proves a defect


def expanded(u: float, k: float = COVERAGE_K) -> float:
    """U = k u (the unit of u)."""
    return k * u


def conformity(value, std, tolerance: float, k: float = COVERAGE_K) -> str:
    """IN, OUT or UNDECIDED of a measured ``value`` with standard uncertainty ``std`` (1 sigma,
    same unit) against the zone [-tolerance, tolerance] with guard band U = k std.

    ``tolerance`` must be a finite number > 0 and ``k`` >= 0 (ValueError otherwise: a spec's
    thresholds are checked when it is loaded, so this is a programming error)."""
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"conformity: tolerance must be a finite number > 0, got {tolerance!r}")
    if not (math.isfinite(k) and k >= 0):
        raise ValueError(f"conformity: k must be a finite number >= 0, got {k!r}")
    if value is None or std is None or not (math.isfinite(value) and math.isfinite(std)) or std < 0:
        return UNDECIDED
    band = expanded(std, k)
    if abs(value) + band <= tolerance:
        return IN
    if abs(value) - band > tolerance:
        return OUT
    return UNDECIDED


def worst(decisions) -> str:
    """The worst of several decisions: OUT over UNDECIDED over IN (IN for none)."""
    return max(decisions, key=_RANK.__getitem__, default=IN)


def exit_status(decision: str) -> int:
    """0 IN, 1 OUT, EXIT_NOT_PROVEN (3) UNDECIDED: the convention of eval.acceptance's verdict."""
    return EXIT_STATUS[decision]


def pose_tolerances(spec: AcceptanceSpec, source: str = "acceptance spec") -> dict[str, float]:
    """{pose name ("x_mm", "alpha_deg", ...): tolerance T (mm, deg)} of the components the spec's
    ``[localization]`` table gates (module docstring): the RMS its statistic's threshold stands
    for under the Gaussian model (eval.gate_statistic ``to_rms``); DockfactoryError naming
    ``source`` when it gates none (a single pose would be judged on nothing)."""
    gate = spec.localization
    thresholds = gate.thresholds()
    if not thresholds:
        raise DockfactoryError(f"{source}: [localization] gates no component: a single pose has no tolerance "
                               "to be judged against (give x, y or alpha there)")
    stat = gate_statistic(gate.statistic)
    return {POSE_KEYS[c]: stat.to_rms(t) for c, t in thresholds.items()}


def coverage_k(spec: AcceptanceSpec) -> float:
    """The guard band's k under the spec's decision rule: COVERAGE_K (guarded) or 0 (simple)."""
    return COVERAGE_K if spec.decision_rule == "guarded" else 0.0


def pose_conformity(pose: dict, std: dict, tolerances: dict, k: float = COVERAGE_K) -> dict:
    """One pose's conformity with its tolerances under ISO 14253-1 (the uncertainty counted).

    Parameters
    ----------
    pose, std : dict
        Pose name -> value and its standard uncertainty (mm, deg; None: not known).
    tolerances : dict
        Pose name -> tolerance T (same units).
    k : float
        The coverage factor of the expanded uncertainty U = k u.

    Returns
    -------
    dict
        ``{"components": {name: {"value", "u", "U", "tolerance", "decision"}}, "decision": the
        worst, "k"}``.

    Raises
    ------
    ValueError
        A tolerance or uncertainty that is not a finite number above 0.
    """
    rows = {}
    for name, tol in tolerances.items():
        v, u = pose.get(name), std.get(name)
        rows[name] = {"value": v, "u": u, "U": None if u is None else expanded(u, k), "tolerance": tol,
                      "decision": conformity(v, u, tol, k)}
    return {"components": rows, "decision": worst(r["decision"] for r in rows.values()), "k": k}
