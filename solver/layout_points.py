"""The layout as arrays and correspondences split per section, on validated input.

Bottom layer of the solver (imports only core, :mod:`solver.checks` and :mod:`solver.errors`);
shared by the per-frame docking pipeline (:mod:`solver.docking`) and the docking-run solve
(:mod:`solver.sequence`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dockfactory.core.names import SECTIONS
from dockfactory.solver.checks import (
    MIN_POINTS,
    as_points,
    check_correspondences,
    layout_arrays,
)
from dockfactory.solver.errors import InvalidSolverInput, TooFewPoints

__all__ = ["LayoutArrays", "parse_correspondences", "checked_correspondences",
           "section_arrays"]


@dataclass(frozen=True)
class LayoutArrays:
    """The layout as arrays: ``ids`` (M,), ``sections`` (M,), ``points`` (M, 3) mm in each
    marker's section frame, ``index`` id -> row, ``by_id`` id -> Marker."""

    ids: tuple
    sections: tuple
    points: np.ndarray
    index: dict
    by_id: dict

    @classmethod
    def of(cls, markers) -> LayoutArrays:
        ids, sections, pts = layout_arrays(markers)
        return cls(ids, sections, pts, {mid: k for k, mid in enumerate(ids)},
                   {m.id: m for m in markers})


def parse_correspondences(correspondences):
    """(ids list (N,), points_2d (N, 2)) from a dict id -> (u, v) or a pair (ids, (N, 2))."""
    if isinstance(correspondences, dict):
        ids = [str(k) for k in correspondences]
        uv = as_points("correspondences", [correspondences[k] for k in correspondences], 2) \
            if ids else np.zeros((0, 2))
        return ids, uv
    try:
        ids, uv = correspondences
    except (TypeError, ValueError):
        raise InvalidSolverInput("correspondences: expected a dict id -> (u, v) or a pair "
                                 "(marker_ids (N,), points_2d (N, 2))") from None
    ids = [str(i) for i in np.asarray(ids).reshape(-1)]
    uv = as_points("correspondences points_2d", uv, 2)
    if len(ids) != uv.shape[0]:
        raise InvalidSolverInput(f"correspondences: {len(ids)} marker ids but {uv.shape[0]} "
                                 "points: shapes do not match")
    return ids, uv


def checked_correspondences(layout: LayoutArrays, correspondences):
    """:func:`parse_correspondences`, refusing unknown ids and ids given more than once."""
    ids, uv = parse_correspondences(correspondences)
    unknown = sorted({i for i in ids if i not in layout.index})
    if unknown:
        raise InvalidSolverInput(f"correspondences: unknown marker ids {unknown[:10]}")
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise InvalidSolverInput(f"correspondences: marker ids given more than once: "
                                 f"{dup[:10]}")
    return ids, uv


def section_arrays(layout: LayoutArrays, ids, used, uv):
    """Per section: input rows, points_3d (n, 3) mm and points_2d (n, 2) px of the rows with an
    id and ``used``; TooFewPoints when a section has fewer than MIN_POINTS."""
    rows = {s: [k for k, mid in enumerate(ids) if mid is not None and used[k]
                and layout.sections[layout.index[mid]] == s] for s in SECTIONS}
    p3, p2 = {}, {}
    for s in SECTIONS:
        if len(rows[s]) < MIN_POINTS:
            raise TooFewPoints(f"section {s}: {len(rows[s])} usable points, at least "
                               f"{MIN_POINTS} are needed")
        p3[s], p2[s] = check_correspondences(
            layout.points[[layout.index[ids[k]] for k in rows[s]]], uv[rows[s]],
            what=f"section {s}")
    return rows, p3, p2
