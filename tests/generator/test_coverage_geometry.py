"""The markers' coverage computed from their geometry (no render): the filter's integral, the
shares against sampling, the section's feet under the ring, the check of a region's own samples,
and where the geometry is not used."""
import dataclasses

import numpy as np
import pytest

from dockfactory.core.config import ConfigError, config_from_dict
from dockfactory.core.scene import MotionParams
from dockfactory.generator import coverage_geometry as cg
from dockfactory.generator.marker_regions import Region, marker_regions
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.sampler import frame_plan, sample_frame

WIDTH = 1.5


def _mc_shares(polygon, pixels, n, seed):
    """Monte Carlo: the share of ``n`` filter-distributed samples of each pixel inside the convex
    ``polygon`` (its edges' half-planes); the offsets drawn by inverting the filter's CDF."""
    rng = np.random.default_rng(seed)
    grid = np.linspace(-WIDTH, WIDTH, 20001)
    cdf = cg.filter_cdf(grid, WIDTH)
    out = []
    for px, py in pixels:
        x = px + np.interp(rng.random(n), cdf, grid)
        y = py + np.interp(rng.random(n), cdf, grid)
        a, b = polygon, np.roll(polygon, -1, axis=0)
        cross = (b[:, 0] - a[:, 0]) * (y[:, None] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (x[:, None] - a[:, 0])
        inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
        out.append(inside.mean())
    return np.array(out)


def _ellipse(cx, cy, a, b, angle, k=96):
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    c, s = np.cos(angle), np.sin(angle)
    x, y = a * np.cos(t), b * np.sin(t)
    return np.stack([cx + c * x - s * y, cy + s * x + c * y], axis=1)


def test_the_filter_s_cdf_and_quadrature_are_the_blackman_harris_window_s():
    """CDF 0 / 0.5 / 1 at -W / 0 / W and increasing; it matches the density's numerical
    integral to 1e-6; the quadrature's weights sum to 1 and give the window's variance."""
    u = np.linspace(-WIDTH, WIDTH, 2001)
    f = cg.filter_cdf(u, WIDTH)
    assert f[0] == pytest.approx(0.0, abs=1e-12) and f[-1] == pytest.approx(1.0, abs=1e-12)
    assert cg.filter_cdf(0.0, WIDTH) == pytest.approx(0.5, abs=1e-12)
    assert np.all(np.diff(f) > 0)
    dens = cg.filter_density(u / WIDTH)
    numeric = np.concatenate([[0], np.cumsum((dens[1:] + dens[:-1]) / 2 * np.diff(u))])
    assert np.max(np.abs(numeric / numeric[-1] - f)) < 1e-6
    x, w = cg.filter_quadrature(WIDTH)
    assert w.sum() == pytest.approx(1.0)
    assert np.sum(w * x ** 2) == pytest.approx(np.sum(np.diff(f) * ((u[1:] + u[:-1]) / 2) ** 2), rel=1e-4)


def test_a_pixel_on_a_straight_edge_is_half_covered_either_way_round():
    """A square 40 px wide: pixels whose centres lie on its left or its top edge (an edge the
    horizontal slices see end on) are 0.5 covered, those 2 px inside 1, 2 px outside 0."""
    square = np.array([[10.0, 10.0], [50.0, 10.0], [50.0, 50.0], [10.0, 50.0]])
    got = cg.shares(square, Region(0, 0, 60, 60), WIDTH)
    assert got[30, 10] == pytest.approx(0.5, abs=1e-6)
    assert got[10, 30] == pytest.approx(0.5, abs=1e-6)
    assert got[30, 12] == pytest.approx(1.0, abs=1e-9) and got[30, 8] == pytest.approx(0.0, abs=1e-9)
    assert got[12, 30] == pytest.approx(1.0, abs=1e-9) and got[8, 30] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("angle", [0.0, 0.3, 1.2])
def test_the_shares_of_an_ellipse_match_sampling(angle):
    """A slanted ellipse (13 x 6 px, a disc seen obliquely): at 40 of its edge pixels the shares
    agree with 40,000 filter-distributed samples each within 4 sampling sigmas (at most 0.01)."""
    poly = _ellipse(30.3, 28.7, 13.0, 6.0, angle)
    got = cg.shares(poly, Region(10, 10, 52, 48), WIDTH)
    edge = np.argwhere((got > 0.05) & (got < 0.95))
    pick = edge[np.random.default_rng(1).choice(len(edge), 40, replace=False)]
    mc = _mc_shares(poly, [(10 + c, 10 + r) for r, c in pick], 40000, seed=2)
    want = got[pick[:, 0], pick[:, 1]]
    sigma = np.sqrt(want * (1 - want) / 40000)
    assert np.all(np.abs(mc - want) < 4 * sigma + 1e-4), np.max(np.abs(mc - want) / sigma)


def test_the_ring_s_walls_stand_on_the_section_s_faces():
    """The feet of a marker's ring walls lie on the section body's flat faces (distance from the
    axis along the face's normal = its apothem), below the ring's top and within the base."""
    cfg = config_from_dict({"markers": {"form": "puck"}}, "t")
    static = static_scene(cfg)
    m = static.markers[2]
    top = cg._circle(m, m.diameter_mm / 2 + 2.5, cg.RING_SEGMENTS, cg.RING_TOP_MM)
    feet = cg._down_to_cylinder(top, m.normal, static.radius_mm, static.marker_base_depth_mm + cg.RING_TOP_MM)
    step = 2 * np.pi / cg.SECTION_FACETS
    mid = (np.floor(np.arctan2(feet[:, 1], feet[:, 2]) / step) + 0.5) * step
    along = feet[:, 1] * np.sin(mid) + feet[:, 2] * np.cos(mid)
    assert np.allclose(along, static.radius_mm * np.cos(step / 2), atol=1e-9)
    drop = (top - feet) @ np.asarray(m.normal)
    assert np.all(drop > 0) and np.all(drop <= static.marker_base_depth_mm)


def _binomial(exact, samples, rng):
    return rng.binomial(samples, np.clip(exact, 0, 1)) / samples


def test_a_region_s_own_samples_agree_with_its_geometry_unless_something_hides_it():
    """Samples drawn from the exact shares (32 a pixel, independent: more spread than Cycles'
    stratified ones) agree; an occluder over part of the disc (a settled pixel with samples
    elsewhere), or the marker 0.3 px off where the geometry puts it, do not."""
    disc = _ellipse(30.0, 30.0, 12.0, 9.0, 0.4)
    ring = _ellipse(30.0, 30.0, 14.0, 10.5, 0.4)
    region = Region(10, 10, 50, 50)
    exact = np.stack([cg.shares(disc, region, WIDTH), cg.shares(ring, region, WIDTH) - cg.shares(disc, region, WIDTH)], -1)
    rng = np.random.default_rng(3)
    sampled = np.stack([_binomial(exact[..., k], 32, rng) for k in range(2)], -1)
    assert cg.samples_agree(sampled, exact, 32)
    hidden = sampled.copy()
    hidden[18:22, 18:22, 0] = 0.0
    assert not cg.samples_agree(hidden, exact, 32)
    moved = [cg.shares(p + [0.3, 0.0], region, WIDTH) for p in (disc, ring)]
    off = np.stack([_binomial(moved[0], 32, rng), _binomial(moved[1] - moved[0], 32, rng)], -1)
    assert not cg.samples_agree(off, exact, 32)


def _frame(**render):
    cfg = config_from_dict({"dataset": {"frames": 2}}, "t")
    frame = sample_frame(cfg, frame_plan(cfg)[0])
    return cfg, dataclasses.replace(frame, render=dataclasses.replace(frame.render, **render))


def test_the_geometry_is_not_used_where_it_does_not_model_the_frame():
    """Depth of field: no marker; B moving: B's markers only, and a region they reach is left to
    the render (None), the others get their shares."""
    cfg, frame = _frame()
    static = static_scene(cfg)
    assert all(cg.geometry_applies(frame, static, m) for m in static.markers)
    dof = dataclasses.replace(frame, camera=dataclasses.replace(frame.camera, f_number=4.0))
    assert not any(cg.geometry_applies(dof, static, m) for m in static.markers)
    moving = dataclasses.replace(frame, motion=MotionParams(velocity_mm_s=(5.0, 0.0, 0.0), exposure_ms=10.0))
    got = [cg.geometry_applies(moving, static, m) for m in static.markers]
    assert got == [m.section == "A" for m in static.markers]


def test_geometry_coverages_gives_shares_where_the_samples_agree_and_none_elsewhere():
    """Every region of a frame, its own samples drawn from the geometry's shares: all computed;
    one region's samples hidden by an occluder: that one None."""
    cfg, frame = _frame(marker_samples=32, marker_coverage_samples=128, marker_coverage_source="geometry")
    static = static_scene(cfg)
    regions = marker_regions(frame, static)
    outlines = cg.frame_outlines(frame, static)
    exact = [cg.region_coverage(outlines, r, WIDTH) for r in regions]
    rng = np.random.default_rng(4)
    sampled = [np.stack([_binomial(e[..., k], 32, rng) for k in range(2)], -1) for e in exact]
    got = cg.geometry_coverages(frame, static, regions, sampled)
    assert all(g is not None and np.array_equal(g, e) for g, e in zip(got, exact))
    disc = np.argwhere(exact[0][..., 0] == 1.0)[0]
    sampled[0][disc[0], disc[1], 0] = 0.5
    got = cg.geometry_coverages(frame, static, regions, sampled)
    assert got[0] is None and all(g is not None for g in got[1:])


def test_the_coverage_source_is_checked_and_inert_without_a_coverage_correction():
    with pytest.raises(ConfigError, match="marker_coverage_source"):
        config_from_dict({"render": {"marker_coverage_source": "guess"}}, "t")
    off = config_from_dict({"render": {"marker_coverage_samples": 0}}, "t")
    assert off.render.marker_coverage_source == "render"
    assert "marker_coverage_source" not in off.to_dict()["render"]
    assert config_from_dict({}, "t").to_dict()["render"]["marker_coverage_source"] == "geometry"
