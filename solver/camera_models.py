"""Camera models beyond the paper's pinhole, selected by name in the spirit of COLMAP's.

Every model estimates f (px); the further intrinsics, in the order ``EXTRA_NAMES`` (cx, cy, k1, k2, p1, p2):

- ``pinhole``: f only (the paper's camera; the default everywhere);
- ``k1``: f, k1; ``k1k2``: f, k1, k2;
- ``pp_k1``: f, cx, cy, k1; ``pp_k1_p``: f, cx, cy, k1, p1, p2.

A model's parameter vector (after the poses, see :mod:`solver.refine`) is ``(f, *free)``.
``AUTO`` ("auto") asks the estimators to choose the model from the data
(:mod:`solver.model_choice`).

Why and how: docs/solver.md, "Camera models".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.distortion import N_COEFFS, distort_normalized, distortion_jacobian
from dockfactory.solver.errors import InvalidSolverInput

__all__ = ["EXTRA_NAMES", "IntrinsicsModel", "MODELS", "MODEL_NAMES", "AUTO", "PINHOLE",
           "camera_model", "check_model_name", "Intrinsics", "project_normalized",
           "intrinsics_jacobian"]

EXTRA_NAMES = ("cx", "cy", "k1", "k2", "p1", "p2")
# where each extra parameter sits: ("pp", index into (cx, cy)) or ("dist", index into coeffs)
_SLOT = {"cx": ("pp", 0), "cy": ("pp", 1), "k1": ("dist", 0), "k2": ("dist", 1),
         "p1": ("dist", 2), "p2": ("dist", 3)}
AUTO = "auto"


@dataclass(frozen=True)
class IntrinsicsModel:
    """A camera model: its ``name`` and the extra intrinsics it estimates (``free``, a subset of
    ``EXTRA_NAMES`` in that order) besides the focal length."""

    name: str
    free: tuple

    @property
    def n_extra(self) -> int:
        return len(self.free)

    @property
    def n_intrinsics(self) -> int:
        """Estimated intrinsics: f and the free extras."""
        return 1 + len(self.free)

    def nests(self, other: IntrinsicsModel) -> bool:
        """True when ``other`` is this model with some free parameters fixed (strictly)."""
        return set(other.free) < set(self.free)


MODELS = {m.name: m for m in (
    IntrinsicsModel("pinhole", ()),
    IntrinsicsModel("k1", ("k1",)),
    IntrinsicsModel("k1k2", ("k1", "k2")),
    IntrinsicsModel("pp_k1", ("cx", "cy", "k1")),
    IntrinsicsModel("pp_k1_p", ("cx", "cy", "k1", "p1", "p2")),
)}
MODEL_NAMES = tuple(MODELS)
PINHOLE = MODELS["pinhole"]


def check_model_name(name, allow_auto: bool = True) -> str:
    """``name`` if it is a model name (or "auto" when allowed), else InvalidSolverInput."""
    allowed = MODEL_NAMES + ((AUTO,) if allow_auto else ())
    if not isinstance(name, str) or name not in allowed:
        raise InvalidSolverInput(f"camera_model must be one of {list(allowed)}, got {name!r}")
    return name


def camera_model(name) -> IntrinsicsModel:
    """The :class:`IntrinsicsModel` of a name (a IntrinsicsModel passes through)."""
    if isinstance(name, IntrinsicsModel):
        return name
    return MODELS[check_model_name(name, allow_auto=False)]


@dataclass(frozen=True)
class Intrinsics:
    """``focal_px``; ``principal_point`` (2,) px; ``coeffs`` (5,) (k1, k2, p1, p2, k3)."""

    focal_px: float
    principal_point: np.ndarray
    coeffs: np.ndarray

    @classmethod
    def pinhole(cls, focal_px: float, principal_point) -> Intrinsics:
        return cls(float(focal_px), np.array(principal_point, dtype=np.float64),
                   np.zeros(N_COEFFS))

    @property
    def distorted(self) -> bool:
        return bool(np.any(self.coeffs != 0.0))

    def value(self, name: str) -> float:
        kind, k = _SLOT[name]
        return float(self.principal_point[k] if kind == "pp" else self.coeffs[k])

    def values(self) -> dict:
        """{name: value} over ``EXTRA_NAMES``."""
        return {n: self.value(n) for n in EXTRA_NAMES}

    def extras(self, model: IntrinsicsModel) -> np.ndarray:
        """(e,) values of the model's free extra parameters."""
        return np.array([self.value(n) for n in model.free])

    def stepped(self, model: IntrinsicsModel, d_focal: float, d_extra) -> Intrinsics | None:
        """These intrinsics moved by ``d_focal`` and ``d_extra`` (e,) along the model's free
        parameters; None when the focal would not stay positive."""
        f_new = self.focal_px + d_focal
        if not f_new > 0.0:
            return None
        pp, co = self.principal_point.copy(), self.coeffs.copy()
        for name, d in zip(model.free, d_extra):
            kind, k = _SLOT[name]
            (pp if kind == "pp" else co)[k] += d
        return Intrinsics(f_new, pp, co)


def project_normalized(xn: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Pixels (N, 2) of undistorted normalised coordinates ``xn`` (N, 2) = (X / Z, Y / Z)."""
    xd = distort_normalized(xn, intr.coeffs) if intr.distorted else xn
    return intr.focal_px * xd + intr.principal_point


def intrinsics_jacobian(xn: np.ndarray, intr: Intrinsics, model: IntrinsicsModel):
    """Pixels and their derivatives at normalised coordinates ``xn`` (N, 2).

    Returns (uv (N, 2), d uv / d xn (N, 2, 2), d uv / d (f, *model.free) (N, 2, 1 + e)).
    """
    xd = distort_normalized(xn, intr.coeffs)
    j_xy, j_c = distortion_jacobian(xn, intr.coeffs)
    f = intr.focal_px
    n = xn.shape[0]
    j_int = np.zeros((n, 2, model.n_intrinsics))
    j_int[:, :, 0] = xd
    for col, name in enumerate(model.free, start=1):
        kind, k = _SLOT[name]
        if kind == "pp":
            j_int[:, k, col] = 1.0
        else:
            j_int[:, :, col] = f * j_c[:, :, k]
    return f * xd + intr.principal_point, f * j_xy, j_int
