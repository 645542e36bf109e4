"""Wing-section geometry and local flow conditions (Bosch et al., Sect. II.B, Eq. 2-6, Fig. 4).

The wing is cut into ``n_sec`` spanwise sections, each a 2-D membrane airfoil whose ``m`` load points are structural
nodes, ordered from the leading-edge (LE) node ``r_i1`` (j = 0, on the LE tube centre line) to the trailing-edge (TE)
node ``r_im`` (j = m-1). All vectors are in the kite frame K (:mod:`kite_env.frames`), whose origin is ``r_k``, so
node positions are already the "position vectors relative to r_k" of Eq. (2).

Section frame (Fig. 4; frame definitions in COMMON brief / :mod:`kite_env.frames`)
    origin ``r_i1``; ``e_x`` from the LE node to the TE node; ``e_y`` perpendicular to the airfoil plane, oriented
    towards the right tip (+y_k side) for every section; ``e_z = e_x × e_y``. The paper only says "perpendicular to
    the airfoil"; we take the normal of the section's own airfoil plane, spanned by the chord ``e_x`` and the mean
    offset of the section nodes from the chord line, oriented like the LE line towards the right tip. Where the
    section is nearly flat (mean offset below 2 % of the chord, the plane is then undefined) ``e_y`` blends smoothly
    into the spanwise tangent of the LE line (central differences of the neighbouring LE nodes, one-sided at the
    tips), orthogonalised against ``e_x``. So it does where that plane is far from the section's, its normal more than
    30 deg from the LE tangent (fully at 60 deg): a mean offset along the span, as of the nodes of a slack, wrinkled
    canopy, spans no airfoil plane, and the orientation of its normal flips where it crosses 90 deg, which without
    this blend made ``e_y`` and the angle of attack jump (by 12 deg in a sideways-bent section: Newton then cycled
    between the two sides of the jump; docs/model.md, "Section frame, fold contact, rotary inertia"). The LE tangent
    alone would be wrong at the
    strongly curved tips of a C-shaped wing, where the section planes are not perpendicular to the LE line (12 deg on
    the rhino16 tips).

Our reading of the partly garbled equations of Sect. II.B (fragments of the extracted seed text in brackets):

* Eq. (2) ["via = vk + ωk × ri1 + ui − vw , (2)"]: ``v_a^i = v_k + ω_k × r_i1 + u_i - v_w``, the velocity of
  the section relative to the air; the flow seen by the airfoil is ``-v_a``.
* Eq. (3) ["qim − qim 1 qi1 − qi1 0 0 ui = + . (3) 2 ∆t ∆t", text: "finite difference using the displacements of
  the leading and rear edge nodes"]: the deformation velocity is the *average* of the finite-difference velocities
  of the LE and the TE node, ``u_i = ((r_im - r_im^prev) + (r_i1 - r_i1^prev)) / (2 dt)`` (q - q^0 is the
  displacement increment over the step, equal to the position increment). The paper notes that this average
  captures translation *and rotation* of the section relative to K.
* Projection (text before Eq. 4): ``v_a,xz = v_a - (v_a · e_y) e_y``; the spanwise component is dropped. The angle
  of attack is the angle between ``v_a,xz`` and the chord line: ``alpha = atan2(u · e_z, u · e_x)`` with
  ``u = -v_a,xz`` (positive for flow from the -e_z side, lift towards +e_z).
* Eq. (4) ["c= b", "d", "i1 + r − rim", "2" on separate lines]: ``c = |r_i1 - r_im| + d/2``. The LE node sits on
  the tube centre line, the airfoil's leading edge ("nose") lies d/2 in front of it on the chord line (Fig. 4
  shows the chord c from the front of the tube to the TE).
* Eq. (5): ``t = d / c``.
* Eq. (6) ["κ = max", "j=1,...,m", ") eiz · (ri j − ri1 ) . c"]: ``kappa = max_j e_z · (r_ij - r_i1) / c``, the
  largest canopy height above the chord line through the LE node and the TE node (the nose is on the same line,
  so the height is the same above the nose-TE chord). j = 1 and j = m give 0, hence kappa >= 0: a canopy bulging
  to -e_z gives kappa = 0 (Breukels' regression is for positive camber only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kite_env.frames import cross  # noqa: F401  (re-exported: used here and by kite_env.aero.loads)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product along the last axis."""
    return np.einsum("...k,...k->...", a, b)


@dataclass(frozen=True)
class SectionGeometry:
    """Geometry of the wing sections (Eq. 4-6, Fig. 4), all in frame K.

    Attributes
    ----------
    frames : (n_sec, 3, 3) float [-]
        Rotation matrices with columns ``e_x, e_y, e_z`` (section components -> K components); right-handed,
        ``e_z = e_x × e_y``. Also available as the properties ``e_x``, ``e_y``, ``e_z`` (n_sec, 3).
    chord : (n_sec,) float [m]
        ``c = |r_im - r_i1| + d/2`` (Eq. 4).
    t : (n_sec,) float [-]
        Thickness ``d / c`` (Eq. 5).
    kappa : (n_sec,) float [-]
        Camber ``max_j e_z · (r_ij - r_i1) / c`` (Eq. 6).
    r_le : (n_sec, 3) float [m]
        LE node ``r_i1`` (origin of the section frame, on the LE tube centre line).
    zeta : (n_sec, m) float [-]
        Height of each node above the chord line over the chord, ``e_z · (r_ij - r_i1) / c``.
    tube_d : (n_sec,) float [m]
        LE tube diameter d.
    local : (n_sec, m, 3) float [m]
        Node coordinates in the section frame, ``(e_x, e_y, e_z) · (r_ij - r_i1)``.

    Properties ``r_nose`` (n_sec, 3) [m], the airfoil leading edge ``r_i1 - (d/2) e_x`` (front of the LE tube), and
    ``xi`` (n_sec, m) [-], the chordwise node coordinate from the airfoil leading edge over the chord,
    ``e_x · (r_ij - r_nose) / c`` (``d/(2c)`` at the LE node, 1 at the TE node).
    """

    frames: np.ndarray
    chord: np.ndarray
    t: np.ndarray
    kappa: np.ndarray
    r_le: np.ndarray
    zeta: np.ndarray
    tube_d: np.ndarray
    local: np.ndarray

    @property
    def e_x(self) -> np.ndarray:
        return self.frames[:, :, 0]  # contiguous rows (frames is the transpose of a row-stacked array)

    @property
    def e_y(self) -> np.ndarray:
        return self.frames[:, :, 1]

    @property
    def e_z(self) -> np.ndarray:
        return self.frames[:, :, 2]

    @property
    def r_nose(self) -> np.ndarray:
        return self.r_le - 0.5 * self.tube_d[:, None] * self.e_x

    @property
    def xi(self) -> np.ndarray:
        return (self.local[:, :, 0] + 0.5 * self.tube_d[:, None]) / self.chord[:, None]


#: Mean node offset from the chord line (fraction of the chord) above which e_y is the airfoil-plane normal.
_FLAT_FRACTION = 0.02
#: |cos| of the angle between the airfoil-plane normal and the LE tangent: at and above ``_PLANE_COS_FULL`` (30 deg)
#: e_y is the plane normal, at and below ``_PLANE_COS_NONE`` (60 deg) the LE tangent, smoothstep in between.
_PLANE_COS_FULL = 0.8660254037844386
_PLANE_COS_NONE = 0.5


def spanwise_directions(r_le: np.ndarray) -> np.ndarray:
    """Spanwise tangents of the LE line, pointing towards the right tip (+y_k side); not normalised.

    Central differences of the LE node positions, one-sided at the two end sections. The orientation is fixed for
    the whole wing by the section ordering (the end whose LE node has the larger y_k is the right tip), so that
    tangents at strongly curved tips (mostly along z_k) are still oriented along the arc towards the right tip.
    A single section gets ``y_k``.

    Parameters
    ----------
    r_le : (n_sec, 3) float [m]
        LE node positions in spanwise order (either direction).

    Returns
    -------
    tangent : (n_sec, 3) float [m]
        Direction only (length = distance between the neighbours used); not orthogonalised against the chord.
    """
    if r_le.shape[0] == 1:
        return np.array([[0.0, 1.0, 0.0]])
    tan = np.concatenate((r_le[1:2] - r_le[:1], r_le[2:] - r_le[:-2], r_le[-1:] - r_le[-2:-1]))
    if r_le[0, 1] > r_le[-1, 1]:  # sections ordered from the right tip to the left tip (mesh convention)
        tan = -tan
    return tan


def section_geometry(x_sec: np.ndarray, tube_d: np.ndarray, spanwise: np.ndarray | None = None) -> SectionGeometry:
    """Section frames, chord, thickness and camber of all sections (Eq. 4-6).

    Parameters
    ----------
    x_sec : (n_sec, m, 3) float [m]
        Current node positions of the sections in frame K, LE node (j = 0) to TE node (j = m-1); sections in
        spanwise order (the mesh orders them from the right tip to the left tip).
    tube_d : (n_sec,) float [m]
        LE tube diameter at each section.
    spanwise : (n_sec, 3) float [m], optional
        Spanwise LE-line directions to use instead of :func:`spanwise_directions` of ``x_sec`` (the load Jacobian
        evaluates perturbed copies of the sections stacked in one array, where neighbours are not spanwise
        neighbours; it holds the LE-line tangent of the unperturbed wing fixed).

    Returns
    -------
    SectionGeometry
    """
    x_sec = np.asarray(x_sec, dtype=float)
    d = np.asarray(tube_d, dtype=float)
    if d.shape != x_sec.shape[:1]:
        d = np.broadcast_to(d, x_sec.shape[:1]).copy()
    r_le = x_sec[:, 0]
    chord_vec = x_sec[:, -1] - r_le
    chord_nodes = np.sqrt(dot(chord_vec, chord_vec))
    axes = np.empty((x_sec.shape[0], 3, 3))  # rows e_x, e_y, e_z (contiguous rows)
    e_x, e_y = axes[:, 0], axes[:, 1]
    np.divide(chord_vec, chord_nodes[:, None], out=e_x)
    tan = spanwise_directions(r_le) if spanwise is None else np.asarray(spanwise, dtype=float)
    tan = tan - dot(tan, e_x)[:, None] * e_x  # orthogonalised against the chord
    tan /= np.sqrt(dot(tan, tan))[:, None]
    # normal of the airfoil plane: chord e_x and the mean offset h of the nodes from the chord line
    h = (x_sec - r_le[:, None, :]).mean(axis=1)
    h -= dot(h, e_x)[:, None] * e_x
    h_len = np.sqrt(dot(h, h))
    n_pl = cross(h, e_x) / np.maximum(h_len, 1e-300)[:, None]
    cos_pl = dot(n_pl, tan)
    n_pl *= np.where(cos_pl < 0.0, -1.0, 1.0)[:, None]  # oriented towards the right tip like the LE line
    # blend to the LE tangent when the section is nearly flat (plane undefined): weight 1 above 2 % of the chord
    u = np.clip(h_len / (_FLAT_FRACTION * chord_nodes), 0.0, 1.0)
    # and when the "plane" is far from the section's (a mean offset along the span, of a slack canopy): the sign
    # above flips where the normal crosses 90 deg from the LE tangent, so its weight must vanish before that
    v = np.clip((np.abs(cos_pl) - _PLANE_COS_NONE) / (_PLANE_COS_FULL - _PLANE_COS_NONE), 0.0, 1.0)
    wgt = (u * u * (3.0 - 2.0 * u) * v * v * (3.0 - 2.0 * v))[:, None]
    ey = wgt * n_pl + (1.0 - wgt) * tan
    ey -= dot(ey, e_x)[:, None] * e_x
    np.divide(ey, np.sqrt(dot(ey, ey))[:, None], out=e_y)
    axes[:, 2] = cross(e_x, e_y)
    frames = axes.transpose(0, 2, 1)  # columns e_x, e_y, e_z
    c = chord_nodes + 0.5 * d  # Eq. (4)
    local = (x_sec - r_le[:, None, :]) @ frames  # (s, y, z) of each node from the LE node
    zeta = local[:, :, 2] / c[:, None]
    return SectionGeometry(
        frames=frames,
        chord=c,
        t=d / c,  # Eq. (5)
        kappa=zeta.max(axis=1),  # Eq. (6)
        r_le=r_le,
        zeta=zeta,
        tube_d=d,
        local=local,
    )


def skew(w: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix, ``skew(w) @ r = w × r``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def apparent_wind(
    x_sec: np.ndarray,
    v_kite: np.ndarray,
    omega: np.ndarray,
    v_wind: np.ndarray,
    x_sec_prev: np.ndarray | None = None,
    dt: float | None = None,
    geometry: SectionGeometry | None = None,
    rotation_point_over_c: float | None = None,
) -> np.ndarray:
    """Apparent wind velocity of every section, Eq. (2) with the deformation velocity of Eq. (3).

    Parameters
    ----------
    x_sec : (n_sec, m, 3) float [m]
        Current section node positions in K.
    v_kite : (3,) float [m/s]
        Velocity of the kite frame origin r_k, components in K.
    omega : (3,) float [rad/s]
        Angular velocity of frame K, components in K.
    v_wind : (3,) or (n_sec, 3) float [m/s]
        Wind velocity, components in K.
    x_sec_prev : (n_sec, m, 3) float [m], optional
        Section node positions at the previous time step; with ``dt`` enables Eq. (3).
    dt : float [s], optional
        Time step for Eq. (3).
    geometry : SectionGeometry, optional
        The sections' geometry; needed with ``rotation_point_over_c``.
    rotation_point_over_c : float, optional [-]
        None (the paper's Eq. 2): the frame rotation ``omega × r`` is taken at the LE node ``r_i1``. A value ``x_p``:
        at the point ``x_p c`` behind the airfoil nose along ``e_x`` (0.75: the 3/4-chord point where thin-airfoil
        theory evaluates the downwash of a rotating section, Pistolesi's theorem; Katz & Plotkin, *Low-Speed
        Aerodynamics*, 2nd ed., Sect. 11.1, the lumped-vortex element). At the LE node, which lies almost on the
        kite's yaw axis, a yaw rate changes no section's angle of attack; at 3/4 chord the tips feel it like fins.

    Returns
    -------
    v_a : (n_sec, 3) float [m/s]
        Velocity of each section relative to the air (the airfoil sees the flow ``-v_a``).
    """
    x_sec = np.asarray(x_sec, dtype=float)
    r1 = x_sec[:, 0]
    omega = np.asarray(omega, dtype=float)
    if rotation_point_over_c is None:
        v_a = r1 @ skew(omega).T  # omega × r_i1
    else:
        s_p = rotation_point_over_c * geometry.chord - 0.5 * geometry.tube_d  # from the LE node along e_x
        v_a = (r1 + s_p[:, None] * geometry.e_x) @ skew(omega).T
    v_a += np.asarray(v_kite, dtype=float) - np.asarray(v_wind, dtype=float)  # Eq. (2)
    if x_sec_prev is not None and dt:
        prev = np.asarray(x_sec_prev, dtype=float)
        # Eq. (3): average of the LE and TE node finite-difference velocities
        v_a += ((x_sec[:, -1] - prev[:, -1]) + (r1 - prev[:, 0])) / (2.0 * dt)
    return v_a


def inflow(v_a: np.ndarray, geom: SectionGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Angle of attack and projected inflow speed of each section (text between Eq. 3 and 4).

    The flow seen by the airfoil is ``u = -v_a``; only its projection onto the airfoil plane,
    ``u_xz = -(v_a - (v_a · e_y) e_y)``, is used.

    Parameters
    ----------
    v_a : (n_sec, 3) float [m/s]
        Apparent wind (section velocity relative to the air), Eq. (2).
    geom : SectionGeometry

    Returns
    -------
    u_loc : (n_sec, 3) float [m/s]
        Section-frame components ``(u · e_x, u · e_y, u · e_z)`` of the flow ``u = -v_a``; ``u_xz`` is
        ``u_loc[:, 0] e_x + u_loc[:, 2] e_z``.
    alpha : (n_sec,) float [rad]
        ``atan2(u · e_z, u · e_x)``, in (-pi, pi]; without in-plane flow the signed zeros give -pi or 0 (the
        loads are zero either way).
    """
    u_loc = -(v_a[:, None, :] @ geom.frames)[:, 0, :]
    return u_loc, np.arctan2(u_loc[:, 2], u_loc[:, 0])
