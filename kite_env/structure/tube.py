"""Inflated-tube section law: bending and torsion stiffness of a pressurised tube (Breukels 2011).

The paper models the LE tube and struts with beam elements whose bending stiffness ``EI(p, d, q)`` depends on the
inflation pressure ``p``, the tube diameter ``d`` and the deflection ``q`` (Sect. II.A, "correlations derived in
[9] by fitting to experimental data"). The correlations are those of Breukels' thesis for a 1 m inflated cantilever
(Breukels 2011, as coded in awegroup/kite_fem, src/kite_fem/BeamElement.py, and awegroup/Billow,
src/billow/elements/inflatable.py); the constants C1..C19 are transcribed below.

Units: Breukels' fits take the gauge pressure in **bar** and the radius ``r = d/2`` in m. Everything outside this
module is SI: pressures in Pa are converted here and nowhere else.

Moment-curvature reading (Billow's energy-consistent re-interpretation, awegroup/Billow): a 1 m cantilever with a
tip load ``P`` and tip deflection ``v`` has root moment ``M = P L`` and root curvature ``kappa = 3 v / L``. The
load-deflection law ``P(v) = D (1 - exp(-(N/D) v))`` therefore becomes::

    M(kappa) = M_max (1 - exp(-EI0 kappa / M_max)),    EI0 = N / 3,   M_max = D * 1 m
    T(phi)   = c1 arctan(c2 phi)                        GJ0 = c1 c2    (phi = twist per metre)

The beam element uses the *secant* stiffness ``EI = M(kappa) / kappa`` and ``GJ = T(phi) / phi`` of its current
curvature and twist, updated at every iterate (the paper's "deflection-dependent cross-sectional properties"). The
law is evaluated at the element's root-mean-square curvature (:func:`element_curvature`), which makes the secant law
the gradient of the stored energy ``L0 (W(kappa) + W_t(phi))`` (:func:`bending_energy_density`,
:func:`torsion_energy_density`), so the tubes are elastic and their tangent (:func:`secant_material_terms`) is
exact; the larger end curvature, which a cold solve's continuation takes, is not a gradient (docs/model.md, "The
conservative tube law"). Collapse (local wrinkling through the tube) is flagged when the
equivalent cantilever deflection ``v = kappa L^2 / 3`` exceeds ``v_collapse``; the beam model cannot represent the
post-collapse state. Beyond it the law is a hinge of constant moment ``M_max``, and nothing in it stops a fold: the
fold contact of :func:`fold_contact` (``structure.tube_fold_onset_deg``) closes a kinked element's fold at pi, where
its legs meet (docs/model.md, "Section frame, fold contact, rotary inertia").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PA_PER_BAR = 1.0e5

# Breukels' inflated-beam constants (Breukels 2011; awegroup/kite_fem BeamElement.py, awegroup/Billow inflatable.py)
C1, C2, C3, C4 = 6582.82, -272.43, 40852.38, 14.31
C5, C6, C7, C8 = 271865251.42, 215.93, 14021.79, -589.05
C9, C10, C11, C12 = 322.55, 0.0239, 5.3833, 0.0461
C13, C14, C15, C16, C17, C18, C19 = 1467.0, 40.908, -191.8, 47.406, -17703.0, 358.05, 0.0918

#: Length of Breukels' calibration cantilever [m].
L_CAL = 1.0
#: Curvature [1/m] and twist [rad/m] below which the secant equals the initial stiffness (avoids 0/0).
_TINY = 1e-9


@dataclass(frozen=True)
class TubeProperties:
    """Pressure- and diameter-dependent constants of Breukels' correlations, per tube element.

    Attributes (all ``(n,)`` float): ``M_max`` [N m] limit bending moment, ``EI0`` [N m^2] initial bending
    stiffness, ``kappa_collapse`` [1/m] curvature at collapse, ``c1`` [N m], ``c2`` [m/rad] torsion constants,
    ``GJ0`` [N m^2] initial torsion stiffness; ``kappa_fold``, ``kappa_closed`` [1/m] the element curvatures at
    which the fold contact of a kinked tube sets in and at which the fold closes (:func:`fold_contact`; infinite:
    none, Breukels' law alone).
    """

    M_max: np.ndarray
    EI0: np.ndarray
    kappa_collapse: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    GJ0: np.ndarray
    kappa_fold: np.ndarray = field(default=None)
    kappa_closed: np.ndarray = field(default=None)

    def __post_init__(self):
        inf = np.full(np.shape(self.M_max), np.inf)
        if self.kappa_fold is None:
            object.__setattr__(self, "kappa_fold", inf)
        if self.kappa_closed is None:
            object.__setattr__(self, "kappa_closed", inf.copy())


def tube_properties(pressure_pa: float | np.ndarray, diameter_m: np.ndarray, element_length_m=None,
                    fold_onset_rad: float | None = None) -> TubeProperties:
    """Evaluate Breukels' correlations for tubes of diameter ``diameter_m`` [m] at gauge pressure ``pressure_pa`` [Pa].

    With ``element_length_m`` (the beam elements' unloaded lengths, (n,) [m]) and ``fold_onset_rad`` the elements
    get the fold contact of :func:`fold_contact`: it sets in at the fold angle ``fold_onset_rad`` (the element's
    rms curvature times its length) and closes the fold at pi; without them Breukels' law alone.

    Raises ``ValueError`` where the fit gives a non-physical (non-positive) stiffness or strength: Breukels' fits
    degrade for small tubes (C2, C8 < 0; the fits are calibrated on 1 m tubes of 0.1-0.3 m diameter), and silently
    clipping would hide that.
    """
    p = np.asarray(pressure_pa, dtype=float) / PA_PER_BAR  # Breukels' fits use bar
    d = np.asarray(diameter_m, dtype=float)
    if np.any(p <= 0.0):
        raise ValueError(f"tube pressure must be positive, got {np.min(p) * PA_PER_BAR:g} Pa")
    if np.any(d <= 0.0):
        raise ValueError(f"tube diameter must be positive, got {np.min(d):g} m")
    r = 0.5 * d
    D = (C1 * r + C2) * p**2 + (C3 * r**3 + C4)  # limit tip load of the 1 m cantilever [N] (2.1)
    N = (C5 * r**5 + C6) * p + (C7 * r + C8)  # initial slope dP/dv [N/m] (2.1)
    v_col = (C9 * r**4 + C10) * p + C11 * r**2 + C12  # collapse tip deflection [m] (2.2)
    c1 = (C13 * r + C14) * p + (C15 * r + C16)  # [N m] (2.3)
    c2 = C17 * r**4 * np.log(p) + (C18 * r**3 + C19)  # [m/rad] (2.3)
    D, N, v_col, c1, c2 = np.broadcast_arrays(D, N, v_col, c1, c2)
    bad = (D <= 0) | (N <= 0) | (c1 <= 0) | (c2 <= 0) | (v_col <= 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad.ravel())[0])
        raise ValueError(
            f"Breukels' tube correlations are non-physical for d = {np.broadcast_to(d, D.shape).ravel()[i]:.4f} m at "
            f"p = {np.broadcast_to(p, D.shape).ravel()[i]:.3f} bar (limit load {D.ravel()[i]:.3g} N, "
            f"slope {N.ravel()[i]:.3g} N/m, torsion c1 {c1.ravel()[i]:.3g}, c2 {c2.ravel()[i]:.3g}); "
            "the fits are calibrated for ~0.1-0.3 m tubes at 0.1-1 bar"
        )
    EI0 = N * L_CAL**3 / 3.0  # cantilever: v = P L^3 / (3 EI)
    k_fold = k_closed = None
    if element_length_m is not None and fold_onset_rad is not None:
        L = np.broadcast_to(np.asarray(element_length_m, dtype=float), D.shape)
        if np.any(L <= 0.0) or not 0.0 < fold_onset_rad < np.pi:
            raise ValueError(f"fold contact: element lengths must be positive and the onset fold angle within "
                             f"(0, pi) rad, got {np.min(L):g} m and {fold_onset_rad:g} rad")
        k_fold, k_closed = fold_onset_rad / L, np.pi / L
    return TubeProperties(
        M_max=D * L_CAL,
        EI0=EI0,
        kappa_collapse=3.0 * v_col / L_CAL**2,
        c1=c1,
        c2=c2,
        GJ0=c1 * c2,
        kappa_fold=k_fold,
        kappa_closed=k_closed,
    )


#: share of the span from the fold contact's onset to its closure beyond which the contact moment is continued
#: linearly (C1): the law stays finite for a Newton iterate beyond the closure
_FOLD_LINEAR = 0.9


def fold_contact(props: TubeProperties, kappa: np.ndarray):
    """Contact moment of a kinked tube whose fold closes, its derivative and its energy per length, each (n,).

    Breukels' law saturates at ``M_max``: a collapsed tube is a hinge of no stiffness (Breukels 2011, ch. 3), and
    nothing stops its fold. A real fold stops when its two legs meet: a kinked tube folded by pi lies on itself
    (and the co-rotational element, whose frame is the mean of its end triads, cannot represent a fold of pi:
    :mod:`kite_env.structure.beam`). Modelling choice (no measured law of a closing fold is public): from the fold
    angle ``Delta_c`` (``kappa_fold`` times the length) the legs press on each other with the moment
    ``M_c = M_max (x / (a - x))^2``, ``x = kappa - kappa_fold``, ``a = kappa_closed - kappa_fold``: 0 with zero slope
    at the onset, ``M_max`` half-way, unbounded as the fold closes (``kappa_closed = pi / L0``), continued linearly
    from ``x = 0.9 a``. Its energy per length is ``M_max (a x / (a - x) + x + 2 a ln(1 - x / a))`` (the integral of
    ``M_c``), so the law stays the gradient of a stored energy. Returns ``(M_c, dM_c/dkappa, W_c)`` at ``|kappa|``."""
    k = np.abs(np.asarray(kappa, dtype=float))
    kf, kc = np.broadcast_arrays(props.kappa_fold, props.kappa_closed)
    finite = np.isfinite(kf)
    kf0 = np.where(finite, kf, 0.0)
    a = np.where(finite, kc, 1.0) - kf0
    x = np.where(finite, np.maximum(k - kf0, 0.0), 0.0)
    xe = _FOLD_LINEAR * a
    xi = np.minimum(x, xe)
    u = a - xi
    Mm = props.M_max
    M = Mm * (xi / u) ** 2
    dM = Mm * 2.0 * xi * a / u**3
    W = Mm * (a * xi / u + xi + 2.0 * a * np.log1p(-xi / a))
    beyond = np.maximum(x - xe, 0.0)
    W = W + M * beyond + 0.5 * dM * beyond**2
    M = M + dM * beyond
    return M, dM, W


def bending_moment(props: TubeProperties, kappa: np.ndarray) -> np.ndarray:
    """Bending moment [N m] at curvature ``kappa`` [1/m] (odd in kappa)."""
    k = np.asarray(kappa, dtype=float)
    return np.sign(k) * (props.M_max * (1.0 - np.exp(-props.EI0 * np.abs(k) / props.M_max))
                         + fold_contact(props, k)[0])


def torque(props: TubeProperties, phi: np.ndarray) -> np.ndarray:
    """Torque [N m] at twist per unit length ``phi`` [rad/m]."""
    return props.c1 * np.arctan(props.c2 * np.asarray(phi, dtype=float))


def secant_EI(props: TubeProperties, kappa: np.ndarray) -> np.ndarray:
    """Secant bending stiffness ``M(kappa)/kappa`` [N m^2] (with the fold contact, :func:`fold_contact`); equals
    ``EI0`` as ``kappa -> 0``."""
    k = np.abs(np.asarray(kappa, dtype=float))
    x = props.EI0 * k / props.M_max
    # (1 - exp(-x)) / x with its series for small x
    ratio = np.where(x < 1e-6, 1.0 - 0.5 * x, -np.expm1(-np.maximum(x, 1e-300)) / np.maximum(x, 1e-300))
    M_c = fold_contact(props, k)[0]
    return props.EI0 * ratio + np.where(M_c > 0.0, M_c / np.maximum(k, 1e-300), 0.0)


def secant_GJ(props: TubeProperties, phi: np.ndarray) -> np.ndarray:
    """Secant torsion stiffness ``T(phi)/phi`` [N m^2]; equals ``GJ0`` as ``phi -> 0``."""
    y = props.c2 * np.abs(np.asarray(phi, dtype=float))
    ratio = np.where(y < 1e-6, 1.0 - y**2 / 3.0, np.arctan(y) / np.maximum(y, 1e-300))
    return props.GJ0 * ratio


#: curvature measures of a tube element for the secant law: the conservative law's, and the larger end curvature that
#: the continuation of a cold solve takes (kite_env.fsi.AeroelasticWing.solve) and FEModel's secant tubes
CURVATURE_MEASURES = ("element_energy", "max_end")


def element_curvature(theta1: np.ndarray, theta2: np.ndarray, L0: np.ndarray, measure: str = "element_energy"):
    """Curvature [1/m] of cubic (Hermite) beam elements that the secant law is evaluated at, ``(n,)``.

    ``theta1``, ``theta2`` (n, 3) [rad] local end rotations (x: twist, y/z: bending), ``L0`` (n,) [m]. The element's
    curvature runs linearly from ``-(4 th1 + 2 th2) / L0`` to ``(2 th1 + 4 th2) / L0`` (each bending component).

    * ``"element_energy"``: the root-mean-square curvature over the element, ``kappa^2 = (1/L0) int |kappa|^2 dx =
      4 (|th1|^2 + th1 . th2 + |th2|^2) / L0^2`` (y and z). The element's bending energy is then
      ``L0 W(kappa)`` with ``W(kappa) = int_0^kappa M`` (:func:`bending_energy_density`), and its gradient is exactly
      the secant law ``M(kappa)/kappa`` times the linear element's moments: the tube forces are conservative
      (a hyperelastic law is the gradient of its stored energy: Holzapfel, Nonlinear Solid Mechanics, Wiley 2000,
      ch. 6).
    * ``"max_end"``: the larger magnitude of the two end curvatures (the path of a cold solve's continuation, whose
      secant iteration converges from the unloaded wing). It is not a function of the element's energy, so
      ``EI(kappa) K theta`` is not a gradient: on a closed path of the element's rotations its forces do net work (a
      free wing flown with it gained kinetic energy from nothing).
    """
    t1, t2 = np.asarray(theta1, dtype=float)[:, 1:], np.asarray(theta2, dtype=float)[:, 1:]
    L0 = np.asarray(L0, dtype=float)
    if measure == "element_energy":
        s = np.einsum("ni,ni->n", t1, t1) + np.einsum("ni,ni->n", t1, t2) + np.einsum("ni,ni->n", t2, t2)
        return 2.0 * np.sqrt(np.maximum(s, 0.0)) / L0
    if measure == "max_end":
        return np.maximum(np.linalg.norm(-(4 * t1 + 2 * t2), axis=1), np.linalg.norm(2 * t1 + 4 * t2, axis=1)) / L0
    raise ValueError(f"tube curvature measure must be one of {CURVATURE_MEASURES}, got {measure!r}")


def secant_material_terms(props: TubeProperties, kappa: np.ndarray, phi: np.ndarray, L0: np.ndarray):
    """Material part of the tangent of the secant law at the element curvature ``kappa`` [1/m] (``"element_energy"``)
    and twist per length ``phi`` [rad/m], both (n,), for elements of length ``L0`` [m].

    The local moments of an element are ``m = EI_s(kappa) A theta`` (bending, ``A`` the linear element's matrix per
    unit EI) with ``kappa^2 = theta^T A theta / L0``, so ``dm/dtheta = EI_s A + g_b m m^T`` with
    ``g_b = (EI_t - EI_s) / (kappa^2 L0 EI_s^2)``, ``EI_t = dM/dkappa = EI0 exp(-EI0 kappa / M_max)`` the tangent
    stiffness; likewise ``g_t = (GJ_t - GJ_s) / (phi^2 L0 GJ_s^2)`` with ``GJ_t = dT/dphi = c1 c2 / (1 + (c2 phi)^2)``.
    Both are <= 0 where the law softens; the fold contact (:func:`fold_contact`) adds ``dM_c/dkappa - M_c/kappa``
    to ``EI_t - EI_s`` and makes ``g_b`` positive where it stiffens. Returns ``(g_b, g_t)`` [1/(N m)], 0 where the
    element is undeformed."""
    k = np.abs(np.asarray(kappa, dtype=float))
    f = np.abs(np.asarray(phi, dtype=float))
    L0 = np.asarray(L0, dtype=float)
    x = props.EI0 * k / props.M_max
    y = props.c2 * f
    xs, ys = np.maximum(x, 1e-300), np.maximum(y, 1e-300)
    dx = np.where(x < 1e-4, -0.5 * x + x**2 / 3.0 - x**3 / 8.0, np.exp(-xs) + np.expm1(-xs) / xs)
    dy = np.where(y < 1e-4, -2.0 * y**2 / 3.0 + 4.0 * y**4 / 5.0, 1.0 / (1.0 + y**2) - np.arctan(ys) / ys)
    EIs, GJs = secant_EI(props, k), secant_GJ(props, f)
    M_c, dM_c, _ = fold_contact(props, k)
    ks = np.maximum(k, 1e-300)
    num = props.EI0 * dx + np.where(M_c > 0.0, dM_c - M_c / ks, 0.0)  # EI_t - EI_s
    g_b = np.where(x > 1e-12, num / (ks**2 * L0 * EIs**2), 0.0)
    g_t = np.where(y > 1e-12, props.GJ0 * dy / (np.maximum(f, 1e-300) ** 2 * L0 * GJs**2), 0.0)
    return g_b, g_t


def bending_energy_density(props: TubeProperties, kappa: np.ndarray) -> np.ndarray:
    """Stored bending energy per length [J/m], ``W(kappa) = int_0^|kappa| M(s) ds``
    ``= M_max (|kappa| - (M_max / EI0) (1 - exp(-EI0 |kappa| / M_max)))`` plus the fold contact's
    (:func:`fold_contact`)."""
    k = np.abs(np.asarray(kappa, dtype=float))
    r = props.M_max / props.EI0
    return props.M_max * (k + r * np.expm1(-k / r)) + fold_contact(props, k)[2]


def torsion_energy_density(props: TubeProperties, phi: np.ndarray) -> np.ndarray:
    """Stored torsion energy per length [J/m], ``int_0^|phi| T(s) ds = c1 (phi atan(c2 phi) - ln(1 + c2^2 phi^2) /
    (2 c2))``."""
    y = props.c2 * np.abs(np.asarray(phi, dtype=float))
    return props.c1 / props.c2 * (y * np.arctan(y) - 0.5 * np.log1p(y * y))


def collapsed(props: TubeProperties, kappa: np.ndarray) -> np.ndarray:
    """True where the curvature exceeds Breukels' collapse curvature (tube wrinkles through)."""
    return np.abs(np.asarray(kappa, dtype=float)) > props.kappa_collapse
