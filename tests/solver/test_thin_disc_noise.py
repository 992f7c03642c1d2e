"""Centre noise of a disc that is thin for its blur (solver.disc_noise.thin_disc_factor): the law,
the noise shapes it changes, solve_docking's ``edge_px`` input and the covariance that follows it.

Tolerances: 200 seeded frames give an RMS z to about 1 / sqrt(400) = 5 % (0.85-1.15 is three
standard errors)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from dockfactory.core.geometry import pose_components
from dockfactory.solver import InvalidSolverInput, solve_docking
from dockfactory.solver.disc_noise import (
    THIN_DISC_POWER,
    THIN_DISC_RATIO,
    noise_shapes,
    section_noise_shapes,
    thin_disc_factor,
)
from dockfactory.solver.synthetic import default_layout, docking_scene

from test_disc_noise import _image_centroids, _noise_cov  # sibling test module (rootdir on sys.path)

LAYOUT = default_layout()
CLASSES = np.array([0 if m.section == "A" else 1 for m in LAYOUT])


def test_factor_law():
    """1 without an edge width (NaN or 0), 2 where the minor semi-axis is THIN_DISC_RATIO edge
    widths, 1 + 2^THIN_DISC_POWER at half that, falling toward 1 for thick discs."""
    f = thin_disc_factor([5.0, 5.0, THIN_DISC_RATIO, THIN_DISC_RATIO / 2, 100.0], [np.nan, 0.0, 1.0, 1.0, 1.0])
    assert f[:2] == pytest.approx([1.0, 1.0])
    assert f[2] == pytest.approx(2.0) and f[3] == pytest.approx(1.0 + 2.0 ** THIN_DISC_POWER)
    assert 1.0 < f[4] < 1.02
    r = np.linspace(1, 20, 50)
    assert np.all(np.diff(thin_disc_factor(r, np.ones_like(r))) < 0)


def test_only_the_minor_axis_term_grows():
    """Semi-axes 12 and 3 px at 30 deg, edge width 1.5 px (r = 2): the variance along the major
    axis is unchanged, the one along the minor axis times the factor, no new correlation."""
    u = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    v = np.array([-u[1], u[0]])
    s = (144.0 * np.outer(u, u) + 9.0 * np.outer(v, v))[None]
    plain, thin = noise_shapes(s)[0], noise_shapes(s, np.array([1.5]))[0]
    assert u @ thin @ u == pytest.approx(u @ plain @ u, rel=1e-9)
    assert v @ thin @ v == pytest.approx(v @ plain @ v * thin_disc_factor(3.0, 1.5), rel=1e-9)
    assert u @ thin @ v == pytest.approx(0.0, abs=1e-9)
    assert noise_shapes(s, np.array([np.nan]))[0] == pytest.approx(plain, rel=1e-12)


def test_edge_widths_are_checked():
    sc = docking_scene(np.random.default_rng(1))
    uv = _image_centroids(sc)
    with pytest.raises(InvalidSolverInput, match="edge_px"):
        solve_docking(LAYOUT, sc.principal_point, detections=(CLASSES, uv), edge_px=-np.ones(len(uv)))
    with pytest.raises(InvalidSolverInput, match="edge_px"):
        solve_docking(LAYOUT, sc.principal_point, detections=(CLASSES, uv), edge_px=np.ones(len(uv) - 1))
    with pytest.raises(InvalidSolverInput, match="edge_px"):
        solve_docking(LAYOUT, sc.principal_point, correspondences={m.id: p for m, p in zip(LAYOUT, uv)},
                      edge_px=np.ones(len(uv)))


def _thin_frame(rng):
    """(scene, centres, edge widths): disc-shaped noise whose minor-axis term carries the thin
    disc factor of edge widths that make every disc 1.2-6 edge widths thick."""
    sc = docking_scene(rng)
    cams = {"A": sc.cam_from_d, "B": sc.cam_from_b}
    minor = np.array([np.sqrt(np.linalg.eigvalsh(
        section_ellipse(m, cams[m.section], sc.focal_px))[0]) for m in LAYOUT])
    edge = minor / rng.uniform(1.2, 6.0, len(LAYOUT))
    shapes = np.concatenate([section_noise_shapes([m], cams[m.section], sc.focal_px, edge[[k]])
                             for k, m in enumerate(LAYOUT)])
    chol = np.linalg.cholesky(_noise_cov(shapes, 0.1))
    return sc, _image_centroids(sc) + np.einsum("nij,nj->ni", chol, rng.normal(size=(len(LAYOUT), 2))), edge


def section_ellipse(marker, cam, focal_px):
    from dockfactory.solver.disc_noise import disc_ellipses
    centre = np.asarray(cam)[:3, :3] @ marker.center_mm + np.asarray(cam)[:3, 3]
    return disc_ellipses(centre[None], (np.asarray(cam)[:3, :3] @ marker.normal)[None], [marker.diameter_mm],
                         focal_px)[0]


@pytest.mark.slow   # 2 x 200 synthetic frames through the whole docking pipeline
def test_covariance_follows_thin_disc_noise_when_told_the_edge_widths():
    """Noise with the thin-disc factor: told the edge widths, the reported std gives RMS z of X,
    Y and alpha within 0.85-1.15 (measured 0.93 / 1.00 / 1.02); not told, at least one
    component leaves that band (measured 0.83 / 1.21 / 0.84: Y under-covered, as on the renders'
    blur)."""
    rng = np.random.default_rng(26)
    z = {True: [], False: []}
    for _ in range(200):
        sc, uv, edge = _thin_frame(rng)
        truth = pose_components(sc.d_from_b)
        for told in (True, False):
            r = solve_docking(LAYOUT, sc.principal_point, detections=(CLASSES, uv),
                              edge_px=edge if told else None)
            z[told].append([(getattr(r, k) - truth[k]) / r.std[k] for k in ("x_mm", "y_mm", "alpha_deg")])
    told, blind = (np.sqrt(np.mean(np.square(z[t]), axis=0)) for t in (True, False))
    assert np.all((told > 0.85) & (told < 1.15)), told
    assert np.any((blind < 0.85) | (blind > 1.15)), blind
