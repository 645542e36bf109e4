"""Figure-eight target path on the unit sphere (paper, Sect. III.A, Fig. 7) and helpers on the sphere.

Unit sphere and angles (frame W: ``x_w`` downwind, ``z_w`` up, origin at the ground station)
    ``R = r / |r|``; elevation ``beta = atan2(R_z, sqrt(R_x^2 + R_y^2))`` (= asin R_z; 0 on the ground, pi/2 at the
    zenith); azimuth ``phi = atan2(R_y, R_x)`` (0 straight downwind, positive towards ``+y_w``, which is on the
    left for an observer at the ground station looking downwind).
Local tangent plane at ``R`` (:func:`sphere_basis`)
    ``x_s`` points to the zenith (direction of increasing elevation), ``y_s = R × x_s`` points towards DECREASING
    azimuth, so ``(x_s, y_s, R)`` is right-handed with the third axis pointing away from the ground station (like
    the kite's ``z_k``, towards the kite's upper side). A kite flying "up" has heading 0; flying towards
    decreasing azimuth it has heading +pi/2. At the zenith (and nadir) ``x_s`` is undefined; the formula used
    takes the limit from the ``x_w``-``z_w`` half plane of positive ``x_w`` (``x_s = -x_w`` at the zenith).
Heading / course (:func:`heading_angle`)
    ``psi = atan2(v . y_s, v . x_s)`` in (-pi, pi]: the angle of the tangent-plane projection of ``v`` measured
    from ``x_s`` towards ``y_s`` (paper, Sect. III.A step 4).

Lemniscate (awegroup/MegAWES, getPointOnBooth.m: the MegAWES parametrisation of the Bernoulli lemniscate on the sphere)
    ``lambda(s) = -b sin s / D``,  ``phi(s) = a sin s cos s / D``,  ``D = 1 + (a/b)^2 cos^2 s``,  s in [0, 2 pi)
    ``p_P = [cos lambda cos phi, sin lambda cos phi, sin phi]``,  ``p_W = R_z(azimuth) R_y(elevation) p_P``
    with ``R_y`` as in MegAWES (maps ``x_P`` to elevation ``beta0`` in the ``x_w``-``z_w`` plane).
This is MegAWES's curve with its parameter shifted by pi (``s -> s + pi`` flips the sign of lambda and
keeps phi), i.e. the same curve flown in the same direction, started on the other lobe. Travel is towards
increasing ``s``. The self-crossing is at ``s = 0`` and ``s = pi``, at exactly the configured mean elevation and
azimuth. The kite flies UPWARD through the crossing and DOWNWARD at the sides ("downloops"), as in the paper
(Sect. IV: "The kite flies towards the ground in the side regions ... and upwards in its center region").
From ``s = 0`` it enters the lobe at negative azimuth (towards ``-y_w``) and turns LEFT (seen by the kite, whose
upper side faces away from the ground station: positive geodesic curvature about ``R``) for ``s`` in (0, pi),
then RIGHT on the other lobe, as the paper's first and second halves of the figure (Sect. IV, Fig. 9).

Meaning of a, b. In the ``(lambda, phi)`` chart, ``max |lambda| = b`` (at ``s = pi/2, 3 pi/2``) and
``max |phi| = a b / (2 sqrt(a^2 + b^2))`` (at ``cos^2 s = 1 / (2 + (a/b)^2)``). After the tilt to the mean
elevation these are no longer the azimuth and elevation excursions (meridians converge towards the zenith), so
``a, b`` are solved numerically (Newton on the exact extrema) such that the curve's full azimuth span
(max - min) equals ``width_deg`` and its full elevation span equals ``height_deg``. The elevation extremes are not
symmetric about the mean elevation (the tops of the lobes lie lower than the crossing + half the height).
The elevation span cannot exceed about the half-width ``b`` (``max |phi| < b / 2``).

Default figure (the paper gives no dimensions; Fig. 9 flies one figure in T = 20 s at v_w = 5 m/s with a
constant 80 m tether and computed flight speeds of 18-28 m/s, Sect. IV): width 120 deg azimuth, height 36 deg
elevation, crossing at 30 deg elevation. The wing flies at the tether length plus the bridle (80 + 25 m), so the
path on the unit sphere (4.7 rad long) is about 490 m for the wing: one figure in about 19-22 s at the paper's
mean speeds of 22-25 m/s (:meth:`Lemniscate.period_estimate` with 105 m). This is wider than common AWE practice
(markschelbergen/awe-production-estimation, qsm.py, and aenarete/KiteControllers.jl: Schelbergen +-18.5-20 deg
azimuth, +-4 deg elevation; Fechner 36 deg width, 24 deg
elevation), which would give figures of 8-12 s at these speeds; the paper's 20 s figure needs the large one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from kite_env.frames import cross

_TWO_PI = 2.0 * math.pi
HINT_WINDOW = 0.6  # half width of the search window around s_hint [rad of s]


# ---------------------------------------------------------------------------------------------- sphere helpers
def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles [rad] to (-pi, pi]; float in, float out."""
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=float), _TWO_PI)
    w = np.where(w <= -np.pi, w + _TWO_PI, w)
    return float(w) if np.ndim(a) == 0 else w


def unit(r: np.ndarray) -> np.ndarray:
    """``r (..., 3)`` -> unit vectors ``R = r / |r|`` (..., 3); raises for a zero vector."""
    r = np.asarray(r, dtype=float)
    norm = np.linalg.norm(r, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError("cannot project the origin onto the unit sphere")
    return r / norm


def elevation(r: np.ndarray) -> np.ndarray | float:
    """Elevation angle [rad] of positions ``r (..., 3)`` (any length) -> (...)."""
    r = np.asarray(r, dtype=float)
    return np.arctan2(r[..., 2], np.hypot(r[..., 0], r[..., 1]))


def azimuth(r: np.ndarray) -> np.ndarray | float:
    """Azimuth angle [rad] in (-pi, pi] of positions ``r (..., 3)`` -> (...); 0 downwind, + towards +y_w."""
    r = np.asarray(r, dtype=float)
    return np.arctan2(r[..., 1], r[..., 0])


def sphere_basis(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent-plane basis at ``R = r/|r|``: ``x_s`` towards the zenith, ``y_s = R × x_s`` (decreasing azimuth).

    Parameters
    ----------
    r : (..., 3) float, position(s) in W (normalised inside)

    Returns
    -------
    x_s, y_s : (..., 3) float, unit vectors. ``x_s = (-sin b cos p, -sin b sin p, cos b)`` for elevation b and
    azimuth p = atan2(R_y, R_x); at the zenith atan2(0, 0) = 0 gives the documented fallback ``x_s = -x_w``.
    """
    R = unit(r)
    h = np.hypot(R[..., 0], R[..., 1])
    safe = h > 0.0
    h_safe = np.where(safe, h, 1.0)
    cp = np.where(safe, R[..., 0] / h_safe, 1.0)
    sp = np.where(safe, R[..., 1] / h_safe, 0.0)
    sb = R[..., 2]
    x_s = np.stack([-sb * cp, -sb * sp, h], axis=-1)
    y_s = cross(R, x_s)
    return x_s, y_s


def heading_angle(r: np.ndarray, v: np.ndarray) -> np.ndarray | float:
    """Angle [rad] in (-pi, pi] of the tangent-plane projection of ``v`` at ``R``, from ``x_s`` towards ``y_s``.

    Parameters
    ----------
    r : (..., 3) float, position(s) (normalised inside)
    v : (..., 3) float, any vector(s) (a velocity, the kite's heading axis, a desired direction)

    Returns
    -------
    (...) float [rad]: 0 towards the zenith, +pi/2 towards decreasing azimuth, -pi/2 towards increasing azimuth.
    """
    if np.ndim(r) == 1 and np.ndim(v) == 1:  # one vector: the same formulas in plain floats (~20x faster)
        rx, ry, rz = (float(c) for c in r)
        vx, vy, vz = (float(c) for c in v)
        n = math.sqrt(rx * rx + ry * ry + rz * rz)
        if n == 0.0:
            raise ValueError("cannot project the origin onto the unit sphere")
        rx, ry, rz = rx / n, ry / n, rz / n
        h = math.hypot(rx, ry)
        cp, sp = (rx / h, ry / h) if h > 0.0 else (1.0, 0.0)
        xs0, xs1, xs2 = -rz * cp, -rz * sp, h
        ys0, ys1, ys2 = ry * xs2 - rz * xs1, rz * xs0 - rx * xs2, rx * xs1 - ry * xs0
        psi = math.atan2(vx * ys0 + vy * ys1 + vz * ys2, vx * xs0 + vy * xs1 + vz * xs2)
        return math.pi if psi <= -math.pi else psi
    x_s, y_s = sphere_basis(r)
    v = np.asarray(v, dtype=float)
    return wrap_angle(np.arctan2(np.sum(v * y_s, axis=-1), np.sum(v * x_s, axis=-1)))


def course_angle(r: np.ndarray, v_kite: np.ndarray) -> np.ndarray | float:
    """Course angle [rad] = :func:`heading_angle` of the kite's velocity ``v_kite (..., 3)`` at ``r (..., 3)``."""
    return heading_angle(r, v_kite)


def geodesic_distance(r1: np.ndarray, r2: np.ndarray) -> np.ndarray | float:
    """Great-circle angle [rad] between the directions of ``r1`` and ``r2`` (..., 3), as atan2(|cross|, dot)."""
    a, b = unit(r1), unit(r2)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


# ---------------------------------------------------------------------------------------------- lemniscate
@dataclass(frozen=True)
class TrajectoryConfig:
    # sized from the model's turn rate (docs/model.md, "The figure-eight"): lobes from 15.2 to 55.2 deg
    # elevation, smallest radius 36.5 m on the 105 m sphere; the paper's 120 x 36 deg at 30 deg reaches 6.5 deg
    width_deg: float = 100.0  # full azimuth span of the figure-eight [deg]
    height_deg: float = 40.0  # full elevation span of the figure-eight [deg]
    elevation_deg: float = 38.0  # elevation of the crossing point [deg]
    azimuth_deg: float = 0.0  # azimuth of the crossing point [deg]
    n_samples: int = 2000  # precomputed samples for the global nearest-point search [-]

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first invalid field (``trajectory.<field> ...``)."""
        for name in ("width_deg", "height_deg", "elevation_deg", "azimuth_deg"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"trajectory.{name} must be finite, got {v!r}")
        if not 0.0 < self.width_deg < 180.0:
            raise ValueError(f"trajectory.width_deg must lie in (0, 180), got {self.width_deg!r}")
        if not self.height_deg > 0.0:
            raise ValueError(f"trajectory.height_deg must be positive, got {self.height_deg!r}")
        if not 0.0 < self.elevation_deg < 90.0:
            raise ValueError(f"trajectory.elevation_deg must lie in (0, 90), got {self.elevation_deg!r}")
        if self.elevation_deg + self.height_deg >= 90.0:
            raise ValueError("trajectory.height_deg too large: elevation_deg + height_deg must stay below 90 "
                             f"(the figure must not reach the zenith), got {self.elevation_deg + self.height_deg!r}")
        if self.n_samples < 64:
            raise ValueError(f"trajectory.n_samples must be >= 64, got {self.n_samples!r}")


class NearestPoint(NamedTuple):
    """Result of :meth:`Lemniscate.nearest`."""

    s: float  # path parameter of the nearest point, in [0, 2 pi)
    point: np.ndarray  # (3,) unit vector R* [-]
    distance_rad: float  # geodesic distance delta between R and R* (>= 0) [rad]
    e_t: np.ndarray  # (3,) unit tangent at R*, direction of travel
    e_n: np.ndarray  # (3,) unit normal at R*, tangent to the sphere, from the kite's side towards the path


def _chart(s: np.ndarray, a: float, b: float) -> tuple[np.ndarray, ...]:
    """lambda, phi and their first two derivatives with respect to s (see module docstring)."""
    s = np.asarray(s, dtype=float)
    c2 = (a / b) ** 2
    sn, cs = np.sin(s), np.cos(s)
    s2, c2s = np.sin(2.0 * s), np.cos(2.0 * s)
    d = 1.0 + c2 * cs * cs
    d1 = -c2 * s2
    d2 = -2.0 * c2 * c2s

    def quot(n0, n1, n2):
        f0 = n0 / d
        f1 = (n1 - f0 * d1) / d
        f2 = (n2 - 2.0 * f1 * d1 - f0 * d2) / d
        return f0, f1, f2

    lam = quot(-b * sn, -b * cs, b * sn)
    phi = quot(0.5 * a * s2, a * c2s, -2.0 * a * s2)
    return lam + phi


def _rotation(elev: float, azim: float) -> np.ndarray:
    """``R_z(azim) @ R_y(elev)`` with R_y as in MegAWES (x_P -> elevation ``elev``)."""
    ce, se, ca, sa = math.cos(elev), math.sin(elev), math.cos(azim), math.sin(azim)
    r_y = np.array([[ce, 0.0, -se], [0.0, 1.0, 0.0], [se, 0.0, ce]])
    r_z = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    return r_z @ r_y


def _curve(s: np.ndarray, a: float, b: float, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """p, dp/ds, d2p/ds2 in W, each (..., 3)."""
    lam, lam1, lam2, phi, phi1, phi2 = _chart(s, a, b)
    cl, sl, cp, sp = np.cos(lam), np.sin(lam), np.cos(phi), np.sin(phi)
    p = np.stack([cl * cp, sl * cp, sp], axis=-1)
    p_l = np.stack([-sl * cp, cl * cp, np.zeros_like(cp)], axis=-1)
    p_f = np.stack([-cl * sp, -sl * sp, cp], axis=-1)
    p_ll = np.stack([-cl * cp, -sl * cp, np.zeros_like(cp)], axis=-1)
    p_lf = np.stack([sl * sp, -cl * sp, np.zeros_like(cp)], axis=-1)
    l1, f1 = lam1[..., None], phi1[..., None]
    dp = p_l * l1 + p_f * f1
    ddp = p_ll * l1**2 + 2.0 * p_lf * l1 * f1 - p * f1**2 + p_l * lam2[..., None] + p_f * phi2[..., None]
    return p @ rot.T, dp @ rot.T, ddp @ rot.T


def _cross3(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross product of two (3,) vectors (np.cross costs ~10x more for single vectors)."""
    u0, u1, u2 = u
    v0, v1, v2 = v
    return np.array([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0])


def _curve_scalar(s: float, a: float, b: float, rot: np.ndarray) -> np.ndarray:
    """Same as :func:`_curve` for one float ``s`` (plain floats, one matrix product): rows p, dp/ds, d2p/ds2."""
    c2 = (a / b) ** 2
    sn, cs = math.sin(s), math.cos(s)
    s2, c2s = 2.0 * sn * cs, cs * cs - sn * sn
    d = 1.0 + c2 * cs * cs
    d1 = -c2 * s2
    d2 = -2.0 * c2 * c2s
    lam = -b * sn / d
    lam1 = (-b * cs - lam * d1) / d
    lam2 = (b * sn - 2.0 * lam1 * d1 - lam * d2) / d
    phi = 0.5 * a * s2 / d
    phi1 = (a * c2s - phi * d1) / d
    phi2 = (-2.0 * a * s2 - 2.0 * phi1 * d1 - phi * d2) / d
    cl, sl, cp, sp = math.cos(lam), math.sin(lam), math.cos(phi), math.sin(phi)
    l11, f11, lf = lam1 * lam1, phi1 * phi1, 2.0 * lam1 * phi1
    m = np.array([
        [cl * cp, sl * cp, sp],
        [-sl * cp * lam1 - cl * sp * phi1, cl * cp * lam1 - sl * sp * phi1, cp * phi1],
        [-cl * cp * l11 + sl * sp * lf - cl * cp * f11 - sl * cp * lam2 - cl * sp * phi2,
         -sl * cp * l11 - cl * sp * lf - sl * cp * f11 + cl * cp * lam2 - sl * sp * phi2,
         -sp * f11 + cp * phi2],
    ])
    return m @ rot.T


def _extremum(fun, s_grid: np.ndarray, values: np.ndarray, sign: float) -> float:
    """Refine the largest of ``sign * values`` on the periodic grid by golden-section search on ``fun``."""
    i = int(np.argmax(sign * values))
    ds = s_grid[1] - s_grid[0]
    lo, hi = s_grid[i] - ds, s_grid[i] + ds
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = sign * fun(x1), sign * fun(x2)
    while hi - lo > 1e-11:
        if f1 > f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1 = sign * fun(x1)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2 = sign * fun(x2)
    return sign * max(f1, f2, sign * values[i])


def lemniscate_spans(a: float, b: float, elev: float, n_grid: int = 2048) -> tuple[float, float]:
    """Exact full azimuth and elevation spans [rad] of the tilted lemniscate with chart parameters ``a, b``."""
    rot = _rotation(elev, 0.0)
    s_grid = np.linspace(0.0, _TWO_PI, n_grid, endpoint=False)
    p = _curve(s_grid, a, b, rot)[0]

    def az(s):
        x, y, _ = _curve_scalar(s, a, b, rot)[0]
        return math.atan2(y, x)

    def el(s):
        x, y, z = _curve_scalar(s, a, b, rot)[0]
        return math.atan2(z, math.hypot(x, y))

    az_v, el_v = azimuth(p), elevation(p)
    az_span = _extremum(az, s_grid, az_v, 1.0) - _extremum(az, s_grid, az_v, -1.0)
    el_span = _extremum(el, s_grid, el_v, 1.0) - _extremum(el, s_grid, el_v, -1.0)
    return az_span, el_span


def solve_chart_parameters(width: float, height: float, elev: float) -> tuple[float, float]:
    """Chart parameters ``(a, b)`` [rad] giving full spans ``width`` (azimuth), ``height`` (elevation) [rad].

    Newton iteration with a finite-difference Jacobian, started from the small-figure approximations
    ``b = atan(tan(width/2) cos elev)``, ``height = a b / sqrt(a^2 + b^2)``; raises ``ValueError`` if ``height`` is
    not reachable for this width (the elevation span saturates at about ``b`` as ``a -> inf``).
    """
    b = math.atan(math.tan(0.5 * width) * math.cos(elev))
    h = min(height, 0.95 * b)
    a = h * b / math.sqrt(b * b - h * h)
    target = np.array([width, height])
    for _ in range(60):
        f0 = np.array(lemniscate_spans(a, b, elev)) - target
        if np.max(np.abs(f0)) < 1e-12:
            return a, b
        eps = 1e-7
        jac = np.empty((2, 2))
        jac[:, 0] = (np.array(lemniscate_spans(a + eps, b, elev)) - target - f0) / eps
        jac[:, 1] = (np.array(lemniscate_spans(a, b + eps, elev)) - target - f0) / eps
        try:
            step = np.linalg.solve(jac, -f0)
        except np.linalg.LinAlgError:  # the spans stopped responding to a, b: the height is out of reach
            break
        # damping: keep a, b positive and moves moderate
        scale = min(1.0, 0.5 * a / max(abs(step[0]), 1e-300), 0.5 * b / max(abs(step[1]), 1e-300))
        a, b = a + scale * step[0], b + scale * step[1]
        if a > 1e3 * b:
            break
    raise ValueError(f"trajectory.height_deg={math.degrees(height):.6g} is not reachable with "
                     f"width_deg={math.degrees(width):.6g} at elevation_deg={math.degrees(elev):.6g}: "
                     "the lemniscate's elevation span is limited to about half its width")


class Lemniscate:
    """The figure-eight target path on the unit sphere (see the module docstring for the definition).

    Parameters
    ----------
    cfg : TrajectoryConfig

    Attributes
    ----------
    a, b : float [rad], chart parameters solved from the configured spans
    elevation, azimuth : float [rad], position of the crossing point
    length : float [rad], path length on the unit sphere (multiply by the tether length for metres)
    """

    def __init__(self, cfg: TrajectoryConfig | None = None) -> None:
        cfg = cfg or TrajectoryConfig()
        cfg.validate()
        self.cfg = cfg
        self.elevation = math.radians(cfg.elevation_deg)
        self.azimuth = math.radians(cfg.azimuth_deg)
        self.a, self.b = solve_chart_parameters(math.radians(cfg.width_deg), math.radians(cfg.height_deg),
                                                self.elevation)
        self.rotation = _rotation(self.elevation, self.azimuth)
        n = cfg.n_samples
        self.ds = _TWO_PI / n
        self.s_samples = np.arange(n) * self.ds
        self.samples = self.point(self.s_samples)  # (n, 3)
        # periodic trapezoid rule: spectrally accurate for the smooth periodic speed |dp/ds|
        s_q = np.linspace(0.0, _TWO_PI, 4096, endpoint=False)
        self.length = float(np.mean(np.linalg.norm(self.derivatives(s_q)[1], axis=-1)) * _TWO_PI)
        self._cells: dict[tuple[float, int], np.ndarray] = {}  # parameter_of_fraction's admissible cells

    # ------------------------------------------------------------------ curve
    def derivatives(self, s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``p(s), dp/ds, d2p/ds2``, each (..., 3), for ``s`` (...) [rad]."""
        return _curve(s, self.a, self.b, self.rotation)

    def point(self, s: np.ndarray | float) -> np.ndarray:
        """Unit vectors on the path, ``s (...)`` -> ``(..., 3)``."""
        return self.derivatives(s)[0]

    def tangent(self, s: np.ndarray | float) -> np.ndarray:
        """Unit tangents (direction of increasing ``s``), ``s (...)`` -> ``(..., 3)``."""
        dp = self.derivatives(s)[1]
        return dp / np.linalg.norm(dp, axis=-1, keepdims=True)

    def geodesic_curvature(self, s: np.ndarray | float) -> np.ndarray:
        """Signed geodesic curvature [1/rad] = ``p . (p' × p'') / |p'|^3``; > 0 for a left turn."""
        p, dp, ddp = self.derivatives(s)
        return np.sum(p * np.cross(dp, ddp), axis=-1) / np.linalg.norm(dp, axis=-1) ** 3

    def parameter_of_fraction(self, u: float, curvature_max: float = math.inf, n_cells: int = 4096) -> float:
        """The path parameter [rad] at the fraction ``u`` in [0, 1) of the parameter range where the geodesic curvature
        satisfies ``|kappa_g| <= curvature_max`` [1/rad]: ``u`` uniform gives ``s`` uniform over that set (resolved
        on ``n_cells`` equal cells of [0, 2 pi), each in or out by its midpoint). Without a bound, ``2 pi u``.
        Raises ValueError when no cell qualifies."""
        if not math.isfinite(curvature_max):
            return _TWO_PI * u
        key = (float(curvature_max), int(n_cells))
        cells = self._cells.get(key)
        if cells is None:
            ds = _TWO_PI / n_cells
            mid = (np.arange(n_cells) + 0.5) * ds
            cells = np.flatnonzero(np.abs(self.geodesic_curvature(mid)) <= curvature_max)
            if cells.size == 0:
                kmin = float(np.min(np.abs(self.geodesic_curvature(mid))))
                raise ValueError(f"no point of the figure-eight has |geodesic curvature| <= {curvature_max} 1/rad "
                                 f"(the smallest is {kmin:.3g})")
            self._cells[key] = cells
        x = u * cells.size
        j = min(int(x), cells.size - 1)
        return float((cells[j] + (x - j)) * (_TWO_PI / n_cells))

    def period_estimate(self, speed_mps: float, tether_length_m: float) -> float:
        """Time [s] for one figure at constant flight speed [m/s] on a tether of the given length [m]."""
        if not (speed_mps > 0 and tether_length_m > 0):
            raise ValueError("speed_mps and tether_length_m must be positive")
        return self.length * tether_length_m / speed_mps

    # ------------------------------------------------------------------ nearest point
    def nearest(self, r: np.ndarray, s_hint: float | None = None) -> NearestPoint:
        """Point of the path with the shortest geodesic distance to ``R = r/|r|`` (paper, Sect. III.A step 1-2).

        Parameters
        ----------
        r : (3,) float, kite position in W (any length; projected onto the unit sphere)
        s_hint : float or None [rad]
            Path parameter of the previous nearest point. If given, only the samples with
            ``|s - s_hint| <= 0.6`` (periodic) are searched (the local refinement may move the result by less than
            one sample spacing beyond), which keeps the branch at the self-crossing; otherwise the whole path.

        Returns
        -------
        NearestPoint(s, point, distance_rad, e_t, e_n). ``e_n`` is tangent to the sphere at ``point``,
        perpendicular to ``e_t`` and points from the kite's side towards the path (``e_n . (point - R) >= 0``);
        at distance 0 it is the left normal ``point × e_t``.
        """
        R = np.asarray(r, dtype=float).reshape(3)
        norm = math.sqrt(R @ R)
        if norm == 0.0:
            raise ValueError("cannot project the origin onto the unit sphere")
        R = R / norm
        n = self.s_samples.shape[0]
        dots = self.samples @ R
        if s_hint is None:
            i = int(np.argmax(dots))
        else:
            w = int(HINT_WINDOW / self.ds)
            centre = int(round((float(s_hint) % _TWO_PI) / self.ds))
            idx = (centre + np.arange(-w, w + 1)) % n
            i = int(idx[np.argmax(dots[idx])])
        s = self._refine(R, float(self.s_samples[i]), float(dots[i]))
        p, dp, _ = _curve_scalar(s, self.a, self.b, self.rotation)
        e_t = dp / math.sqrt(dp @ dp)
        left = _cross3(p, e_t)
        cr = _cross3(R, p)
        dist = math.atan2(math.sqrt(cr @ cr), float(R @ p))
        side = float(R @ left)  # > 0: the kite is on the left of the path
        e_n = -left if side > 1e-12 else left
        return NearestPoint(float(s % _TWO_PI), p, dist, e_t, e_n)

    def _refine(self, R: np.ndarray, s0: float, f0: float) -> float:
        """Maximise ``R . p(s)`` near the sample ``s0`` by safeguarded Newton on ``g = R . p'(s) = 0``."""
        a, b, rot = self.a, self.b, self.rotation
        lo, hi = s0 - self.ds, s0 + self.ds
        g_lo = float(_curve_scalar(lo, a, b, rot)[1] @ R)
        g_hi = float(_curve_scalar(hi, a, b, rot)[1] @ R)
        if not (g_lo >= 0.0 >= g_hi):  # not bracketed (far from the path): keep the sample
            return s0
        s = s0
        for _ in range(60):
            _, g, dg = _curve_scalar(s, a, b, rot) @ R
            if g > 0.0:
                lo = s
            else:
                hi = s
            step = -g / dg if dg < 0.0 else math.inf
            if abs(step) < 1e-13:  # converged (|dp/ds| ~ 0.2-1, so the point is converged to ~1e-13 rad)
                s += step
                break
            s_new = s + step
            if not lo < s_new < hi:  # Newton left the bracket: bisect
                s_new = 0.5 * (lo + hi)
            if hi - lo < 1e-13:
                s = s_new
                break
            s = s_new
        return s if float(_curve_scalar(s, a, b, rot)[0] @ R) >= f0 else s0
