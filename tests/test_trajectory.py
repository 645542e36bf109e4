import math

import numpy as np
import pytest

from kite_env.trajectory import (
    Lemniscate,
    TrajectoryConfig,
    _chart,
    azimuth,
    course_angle,
    elevation,
    geodesic_distance,
    heading_angle,
    sphere_basis,
    unit,
    wrap_angle,
)

#: the paper's figure (120 x 36 deg at 30 deg), which the single-figure tests below were measured on; the default is
#: sized for the model's turn rate (100 x 40 deg at 38 deg, kite_env/trajectory.py)
PAPER_FIGURE = TrajectoryConfig(width_deg=120.0, height_deg=36.0, elevation_deg=30.0)

CONFIGS = [
    TrajectoryConfig(),
    PAPER_FIGURE,
    TrajectoryConfig(width_deg=60.0, height_deg=16.0, elevation_deg=25.0, azimuth_deg=20.0),
    TrajectoryConfig(width_deg=100.0, height_deg=30.0, elevation_deg=35.0, azimuth_deg=-10.0, n_samples=500),
]


@pytest.fixture(scope="module")
def lem():
    return Lemniscate(PAPER_FIGURE)


def _sph(elev_deg, az_deg):
    b, p = math.radians(elev_deg), math.radians(az_deg)
    return np.array([math.cos(b) * math.cos(p), math.cos(b) * math.sin(p), math.sin(b)])


# ------------------------------------------------------------------------------------------ sphere helpers
def test_wrap_angle():
    a = np.array([0.5, math.pi, -math.pi, 3 * math.pi, -3.5, 7.0, -7.0, 2 * math.pi])
    w = wrap_angle(a)
    np.testing.assert_allclose(w, [0.5, math.pi, math.pi, math.pi, -3.5 + 2 * math.pi, 7.0 - 2 * math.pi,
                                   -7.0 + 2 * math.pi, 0.0], atol=1e-12)
    assert np.all((w > -math.pi) & (w <= math.pi))
    assert isinstance(wrap_angle(4.0), float) and wrap_angle(4.0) == pytest.approx(4.0 - 2 * math.pi)


def test_elevation_azimuth_and_basis():
    r = 80.0 * _sph(30.0, 0.0)
    assert elevation(r) == pytest.approx(math.radians(30.0)) and azimuth(r) == pytest.approx(0.0)
    assert math.degrees(azimuth([1.0, 1.0, 5.0])) == pytest.approx(45.0)
    x_s, y_s = sphere_basis(r)
    np.testing.assert_allclose(x_s, [-0.5, 0.0, math.sqrt(3) / 2], atol=1e-15)  # towards the zenith
    np.testing.assert_allclose(y_s, [0.0, -1.0, 0.0], atol=1e-15)  # towards decreasing azimuth
    # orthonormal, right-handed with R, at many points (vectorised)
    rng = np.random.default_rng(0)
    R = unit(rng.normal(size=(50, 3)))
    x_s, y_s = sphere_basis(R)
    np.testing.assert_allclose(np.linalg.norm(x_s, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.sum(x_s * y_s, axis=1), 0.0, atol=1e-14)
    np.testing.assert_allclose(np.sum(x_s * R, axis=1), 0.0, atol=1e-14)
    np.testing.assert_allclose(np.cross(x_s, y_s), R, atol=1e-14)
    # x_s is the direction of increasing elevation: finite difference of the spherical position
    for elev, az in ((20.0, 35.0), (60.0, -120.0)):
        d = _sph(elev + 1e-6, az) - _sph(elev - 1e-6, az)
        np.testing.assert_allclose(sphere_basis(_sph(elev, az))[0], d / np.linalg.norm(d), atol=1e-9)
        d = _sph(elev, az + 1e-6) - _sph(elev, az - 1e-6)  # increasing azimuth
        np.testing.assert_allclose(sphere_basis(_sph(elev, az))[1], -d / np.linalg.norm(d), atol=1e-9)
    # documented zenith fallback
    x_z, y_z = sphere_basis([0.0, 0.0, 2.0])
    np.testing.assert_allclose(x_z, [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(y_z, [0.0, -1.0, 0.0])
    with pytest.raises(ValueError):
        unit(np.zeros(3))


def test_heading_angle_hand_cases():
    r = 80.0 * _sph(30.0, 0.0)
    assert heading_angle(r, [0.0, 0.0, 1.0]) == pytest.approx(0.0, abs=1e-15)  # towards the zenith
    assert heading_angle(r, [0.0, 1.0, 0.0]) == pytest.approx(-math.pi / 2)  # increasing azimuth (+y_w)
    assert heading_angle(r, [0.0, -1.0, 0.0]) == pytest.approx(math.pi / 2)  # decreasing azimuth
    assert heading_angle(r, [0.0, 0.0, -1.0]) == pytest.approx(math.pi)  # down: +pi, not -pi
    assert heading_angle(r, [-0.5, -1.0, math.sqrt(3) / 2]) == pytest.approx(math.pi / 4)  # x_s + y_s
    # the radial component of v does not matter, neither does the length of r
    v = np.array([0.3, -2.0, 0.7])
    assert heading_angle(r, v + 5.0 * unit(r)) == pytest.approx(heading_angle(r / 80.0, v), abs=1e-14)
    # at azimuth 90 deg, increasing azimuth points along -x_w
    assert heading_angle(_sph(40.0, 90.0), [-1.0, 0.0, 0.0]) == pytest.approx(-math.pi / 2)
    # vectorised, and course angle = heading of the velocity
    R = np.stack([_sph(30.0, 0.0), _sph(30.0, 0.0)])
    np.testing.assert_allclose(course_angle(R, np.array([[0, 0, 1.0], [0, 1.0, 0]])), [0.0, -math.pi / 2], atol=1e-15)


def test_geodesic_distance():
    b, dp = math.radians(10.0), math.radians(25.0)  # spherical law of cosines
    expected = math.acos(math.cos(b) ** 2 * math.cos(dp) + math.sin(b) ** 2)
    assert geodesic_distance(_sph(10.0, 0.0), 3.0 * _sph(10.0, 25.0)) == pytest.approx(expected, rel=1e-12)
    assert geodesic_distance([1.0, 0, 0], [0, 2.0, 0]) == pytest.approx(math.pi / 2)
    assert geodesic_distance([1.0, 1e-9, 0], [1.0, 0, 0]) == pytest.approx(1e-9, rel=1e-6)  # robust when tiny


# ------------------------------------------------------------------------------------------ lemniscate
def test_chart_extents_match_stated_relation():
    s = np.linspace(0.0, 2 * math.pi, 200001)
    for a, b in ((0.3, 0.5), (0.6, 0.4), (0.5, 0.5)):
        lam, _, _, phi, _, _ = _chart(s, a, b)
        assert np.max(np.abs(lam)) == pytest.approx(b, rel=1e-12)
        assert np.max(np.abs(phi)) == pytest.approx(a * b / (2.0 * math.sqrt(a * a + b * b)), rel=1e-9)


@pytest.mark.parametrize("cfg", CONFIGS)
def test_spans_and_crossing_point(cfg):
    lem = Lemniscate(cfg)
    s = np.linspace(0.0, 2 * math.pi, 400001)
    p = lem.point(s)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-15)
    az = wrap_angle(azimuth(p) - math.radians(cfg.azimuth_deg))
    el = elevation(p)
    assert az.max() - az.min() == pytest.approx(math.radians(cfg.width_deg), abs=1e-6)
    assert el.max() - el.min() == pytest.approx(math.radians(cfg.height_deg), abs=1e-6)
    assert az.max() == pytest.approx(-az.min(), abs=1e-6)  # mirror symmetric about the mean azimuth
    for s_c in (0.0, math.pi):
        pc = lem.point(s_c)
        assert elevation(pc) == pytest.approx(math.radians(cfg.elevation_deg), abs=1e-14)
        assert azimuth(pc) == pytest.approx(math.radians(cfg.azimuth_deg), abs=1e-14)


@pytest.mark.parametrize("cfg", CONFIGS[:2])
def test_tangent_and_derivatives_against_finite_differences(cfg):
    lem = Lemniscate(cfg)
    s = np.linspace(0.0, 2 * math.pi, 37)
    h = 1e-6
    fd = (lem.point(s + h) - lem.point(s - h)) / (2 * h)
    np.testing.assert_allclose(lem.tangent(s), fd / np.linalg.norm(fd, axis=1, keepdims=True), atol=1e-8)
    p, dp, ddp = lem.derivatives(s)
    np.testing.assert_allclose(dp, fd, atol=1e-8)
    fd2 = (lem.derivatives(s + h)[1] - lem.derivatives(s - h)[1]) / (2 * h)
    np.testing.assert_allclose(ddp, fd2, atol=1e-7)
    np.testing.assert_allclose(np.sum(lem.tangent(s) * p, axis=1), 0.0, atol=1e-14)  # tangent to the sphere


def test_direction_of_travel_downloops_left_turn_first(lem):
    up = lambda s: float(np.dot(lem.tangent(s), sphere_basis(lem.point(s))[0]))  # noqa: E731
    assert up(0.0) > 0.3 and up(math.pi) > 0.3  # upward through the crossing
    assert up(math.pi / 2) < -0.9 and up(3 * math.pi / 2) < -0.9  # downward at the sides
    assert azimuth(lem.point(math.pi / 2)) < -0.5 < 0.5 < azimuth(lem.point(3 * math.pi / 2))  # first lobe: -y_w
    # left turn (kite's view, upper side away from the ground station) on the first half, right on the second:
    # the tangent rotates towards the left normal R x e_t
    s1 = np.linspace(0.1, math.pi - 0.1, 50)
    s2 = s1 + math.pi
    for s_half, sign in ((s1, 1.0), (s2, -1.0)):
        left = np.cross(lem.point(s_half), lem.tangent(s_half))
        turn = np.sum((lem.tangent(s_half + 1e-4) - lem.tangent(s_half - 1e-4)) * left, axis=1)
        assert np.all(sign * turn > 0)
        assert np.all(sign * lem.geodesic_curvature(s_half) > 0)


def test_length_and_period(lem):
    s = np.linspace(0.0, 2 * math.pi, 200001)
    polyline = np.sum(np.linalg.norm(np.diff(lem.point(s), axis=0), axis=1))
    assert lem.length == pytest.approx(polyline, rel=1e-8)
    assert lem.period_estimate(23.5, 80.0) == pytest.approx(polyline * 80.0 / 23.5, rel=1e-8)
    with pytest.raises(ValueError):
        lem.period_estimate(0.0, 80.0)


def test_nearest_recovers_points_moved_off_the_path(lem):
    for s0 in (0.6, 1.3, 2.2, 3.8, 4.6, 5.5):
        p0, t0 = lem.point(s0), lem.tangent(s0)
        left = np.cross(p0, t0)
        for d in (0.03, -0.02, 0.005, -1e-4):
            R = math.cos(d) * p0 + math.sin(d) * left  # geodesic offset by |d| along the normal
            for hint in (None, s0 + 0.3):
                near = lem.nearest(80.0 * R, s_hint=hint)
                assert near.s == pytest.approx(s0, abs=1e-9)
                assert near.distance_rad == pytest.approx(abs(d), abs=1e-11)
                np.testing.assert_allclose(near.point, p0, atol=1e-9)
                np.testing.assert_allclose(near.e_t, t0, atol=1e-9)
                np.testing.assert_allclose(near.e_n, -math.copysign(1.0, d) * left, atol=1e-9)  # towards the path
    # on the path: distance 0 and e_n = left normal point x e_t
    near = lem.nearest(lem.point(2.0))
    assert near.distance_rad < 1e-12
    np.testing.assert_allclose(near.e_n, np.cross(near.point, near.e_t), atol=1e-12)


def test_nearest_matches_brute_force_and_e_n_points_to_path(lem):
    s_dense = np.linspace(0.0, 2 * math.pi, 400000, endpoint=False)
    p_dense = lem.point(s_dense)
    rng = np.random.default_rng(7)
    s_rand = rng.uniform(0, 2 * math.pi, 25)
    R = unit(lem.point(s_rand) + rng.normal(scale=0.15, size=(25, 3)))
    for r in R:
        near = lem.nearest(r)
        brute = geodesic_distance(r, p_dense[np.argmax(p_dense @ r)])
        assert brute - 1e-7 < near.distance_rad <= brute + 1e-12
        assert near.distance_rad == pytest.approx(geodesic_distance(r, near.point), abs=1e-14)
        assert 0.0 <= near.s < 2 * math.pi
        assert np.dot(near.e_n, near.point - r) >= 0.0
        for v in (near.e_t, near.e_n):
            assert np.linalg.norm(v) == pytest.approx(1.0, abs=1e-14)
            assert abs(np.dot(v, near.point)) < 1e-13
        assert abs(np.dot(near.e_t, near.e_n)) < 1e-13


def test_hint_keeps_branch_at_crossing(lem):
    pc = lem.point(0.0)
    x_s = sphere_basis(pc)[0]
    for offset in (0.0, 1e-3, -2e-3):  # on the crossing and just above/below it, in the symmetry plane
        R = math.cos(offset) * pc + math.sin(offset) * x_s
        a = lem.nearest(R, s_hint=2 * math.pi - 0.05)  # coming along the branch through s = 0
        b = lem.nearest(R, s_hint=math.pi - 0.05)  # coming along the branch through s = pi
        assert abs(wrap_angle(a.s)) < 0.01 and abs(b.s - math.pi) < 0.01
        np.testing.assert_allclose(a.e_t, lem.tangent(a.s), atol=1e-12)
        assert np.dot(a.e_t, b.e_t) < 0.0  # the two branches cross at a large angle (up-left vs up-right)
        assert a.distance_rad == pytest.approx(b.distance_rad, abs=1e-12)
    # a hint whose window excludes the globally nearest point returns a point inside the window
    near = lem.nearest(lem.point(3.0), s_hint=1.0)
    ds = 2 * math.pi / lem.cfg.n_samples
    assert 0.4 - ds <= near.s <= 1.6 + ds
    assert lem.nearest(lem.point(3.0)).s == pytest.approx(3.0, abs=1e-9)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(width_deg=0.0), r"trajectory.width_deg must lie in \(0, 180\)"),
        (dict(width_deg=200.0), r"trajectory.width_deg must lie in \(0, 180\)"),
        (dict(height_deg=-5.0), "trajectory.height_deg must be positive"),
        (dict(elevation_deg=0.0), r"trajectory.elevation_deg must lie in \(0, 90\)"),
        (dict(elevation_deg=70.0, height_deg=25.0), "trajectory.height_deg too large"),
        (dict(n_samples=10), "trajectory.n_samples must be >= 64"),
        (dict(azimuth_deg=math.inf), "trajectory.azimuth_deg must be finite"),
    ],
)
def test_config_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TrajectoryConfig(**kwargs)


@pytest.mark.parametrize("w, h, e", [(40.0, 30.0, 30.0), (100.0, 44.0, 40.0), (110.0, 44.0, 40.0)])
def test_unreachable_height_is_reported(w, h, e):
    """One message naming the keys, also where the Newton iteration's Jacobian turns singular (100 x 44 at 40 deg
    raised numpy's bare 'Singular matrix')."""
    with pytest.raises(ValueError, match="not reachable"):
        Lemniscate(TrajectoryConfig(width_deg=w, height_deg=h, elevation_deg=e))


def test_heading_of_one_vector_equals_the_vectorised_formula():
    """The plain-float path for single vectors gives the array path's angles, at the zenith too."""
    rng = np.random.default_rng(3)
    r = rng.normal(size=(500, 3))
    v = rng.normal(size=(500, 3))
    r[0], v[0] = [0.0, 0.0, 7.0], [1.0, 0.5, 0.0]  # zenith: the documented fallback basis
    r[1], v[1] = [3.0, 0.0, 1.0], [0.0, 0.0, -1.0]  # heading exactly pi (flying down)
    one = np.array([heading_angle(ri, vi) for ri, vi in zip(r, v)])
    np.testing.assert_allclose(one, heading_angle(r, v), rtol=0, atol=1e-14)
    assert one[1] == pytest.approx(np.pi)
    assert isinstance(heading_angle(r[2], v[2]), float)


def test_parameter_of_fraction_draws_uniformly_from_the_straight_parts(lem):
    u = np.random.default_rng(3).random(4000)
    # unbounded: 2 pi u, bit for bit (the env's unbounded start draw is unchanged by the option)
    assert all(lem.parameter_of_fraction(x) == 2.0 * math.pi * x for x in u[:50])
    s = np.array([lem.parameter_of_fraction(x, 1.0) for x in u])
    k = np.abs(lem.geodesic_curvature(s))
    ds = 2.0 * math.pi / 4096
    assert k.max() <= 1.0 + 0.5 * ds * np.abs(np.gradient(lem.geodesic_curvature(s), s)).max() + 1e-9
    grid = np.linspace(0.0, 2.0 * math.pi, 200_000, endpoint=False)
    share = np.mean(np.abs(lem.geodesic_curvature(grid)) <= 1.0)
    assert 0.2 < share < 0.6  # a real restriction, not the whole path or a point
    # uniform over the admissible set: each admissible half (around the crossing at s = 0 and at s = pi) gets
    # half of the draws, and the draws are spread over the set like the set itself (two-sample KS distance)
    near_pi = np.abs(s - math.pi) < 0.5 * math.pi
    assert abs(near_pi.mean() - 0.5) < 0.04
    ref = np.sort(grid[np.abs(lem.geodesic_curvature(grid)) <= 1.0])
    ss = np.sort(s)
    cdf_s = np.arange(1, ss.size + 1) / ss.size
    cdf_ref = np.searchsorted(ref, ss, side="right") / ref.size
    assert np.max(np.abs(cdf_s - cdf_ref)) < 1.36 / math.sqrt(ss.size) + 0.005
    # a monotone map: a larger fraction is a later admissible parameter
    assert np.all(np.diff([lem.parameter_of_fraction(x, 1.0) for x in np.linspace(0.0, 0.999, 100)]) > 0)
    with pytest.raises(ValueError, match="no point of the figure-eight"):
        lem.parameter_of_fraction(0.5, 1e-9)
