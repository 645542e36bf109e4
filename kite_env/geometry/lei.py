"""Parametric leading-edge-inflatable (LEI) kite mesh builder.

A kite is described by :class:`LeiDesign`: "stations" along the RIGHT half of the wing (centre -> right tip) giving
the leading-edge tube centre point, the trailing-edge point, the canopy normal and the LE tube diameter, plus the
strut positions, the canopy camber and the rod/wire diameters. :func:`build_lei_mesh` turns it into a
:class:`~kite_env.geometry.mesh.KiteMesh` with any odd ``n_sec >= 7`` sections and ``m >= 3`` chordwise points:

1. The station data are mirrored to the full span and interpolated with cubic splines (LE, TE, normal) and a
   monotone PCHIP (tube diameter) over a parameter ``t`` (cumulative length of the LE station polyline).
2. Sections are placed uniformly in 3-D arc length of the interpolated LE tube centre line, the tips exactly at the
   tip stations; only the right half is evaluated, the left half is its exact mirror image (``y -> -y``).
3. Each section is a plane airfoil: chord unit vector ``e_x`` from the LE node to the TE node, canopy normal ``n``
   (the interpolated normal made perpendicular to ``e_x``). The chordwise points are evenly spaced in chord fraction
   ``xi_j = j / (m - 1)`` (node j=0 is the LE tube centre: the paper attaches the canopy to the tube centre line,
   Sect. IV.B), so the spacing is finer where the chord is shorter, i.e. at the tips (Sect. II.A). The camber line
   is ``h(xi) ~ xi (1 - xi)^p`` (maximum at ``xi = 1/(1+p)``), scaled so that the discrete camber of Eq. (6),
   ``kappa = max_j n . (r_ij - r_i1) / c`` with ``c = |r_im - r_i1| + d/2`` (Eq. 5), equals ``design.camber``.
4. The mesh is expressed in frame K computed from its own bridle points (:func:`kite_env.frames.kite_frame`).

Strut sections: a strut at arc fraction ``f`` of the half LE length (0 = centre, 1 = tip) is placed at the right-half
section ``round(f (n_sec - 1) / 2)`` counted from the centre, and mirrored; with ``n_c`` centre struts (0 or 1) and
``n_h`` struts per half, ``n_struts = n_c + 2 n_h``. Sections are evenly spaced, so "round" is the nearest section.
A ValueError is raised when two struts fall on one section or a strut falls on a tip (resolution too coarse).

Shell diagonals: in the strip between sections i and i+1 the quad (i,j), (i,j+1), (i+1,j+1), (i+1,j) is split along
(i+1,j)-(i,j+1) on the right half and along the mirrored diagonal (i,j)-(i+1,j+1) on the left half, so the
triangle pattern is symmetric about the x-z plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator

from kite_env.frames import kite_frame, to_frame

from .mesh import BEAM_LE, BEAM_STRUT, BEAM_TE, BEAM_TIP, KiteMesh, triangle_normals

_N_DENSE = 2001  # samples per half span for the arc-length integral of the LE spline


@dataclass(frozen=True, eq=False)
class LeiDesign:
    """Half-span description of an LEI kite (stations from the centre, index 0, to the right tip, index -1).

    Coordinates are in a frame with x aft (LE -> TE), y to the right tip and z up (convex side of the arc); the
    builder re-expresses the mesh in frame K from its bridle points, so the frame need not be exactly K.

    Parameters
    ----------
    name : str
    le : (n_st, 3) float [m]
        LE tube centre line points. If ``le[0, 1] == 0`` station 0 lies on the symmetry plane.
    te : (n_st, 3) float [m]
        Trailing-edge points.
    normal : (n_st, 3) float [-] or None
        Canopy normal (suction side) of each station's airfoil plane; made perpendicular to the chord. ``None``:
        each section plane is perpendicular to the LE tube centre line (normal = e_x x e_y with e_y the LE
        tangent towards the right tip, made perpendicular to e_x).
    tube_d : (n_st,) float [m]
        LE tube diameter.
    strut_frac : (n_struts_listed,) float [-]
        Strut positions as fractions of the half LE arc length (0 = centre strut, else one strut per side).
    strut_d : (n_struts_listed, 2) float [m]
        Strut tube diameter at its LE end and at its TE end (linear in between).
    camber : float [-]
        Discrete camber kappa of every section per Eq. (6).
    camber_pos : float [-]
        Chord fraction of the maximum of the continuous camber line (0 < camber_pos < 1).
    tip_rod_d : float [m]
        Diameter of the solid tip rods.
    te_wire_d : float [m]
        Diameter of the trailing-edge wire.
    info : dict
        Provenance / design numbers copied into the mesh info.
    """

    name: str
    le: np.ndarray
    te: np.ndarray
    normal: np.ndarray | None
    tube_d: np.ndarray
    strut_frac: np.ndarray
    strut_d: np.ndarray
    camber: float
    camber_pos: float
    tip_rod_d: float
    te_wire_d: float
    info: dict = field(default_factory=dict)


def _mirror(a: np.ndarray, has_centre: bool, flip_y: bool) -> np.ndarray:
    """Full-span array ordered right tip -> left tip from half-span data ordered centre -> right tip."""
    right = a[::-1]
    left = a[1:] if has_centre else a
    left = left.copy()
    if flip_y:
        left[:, 1] *= -1.0
    return np.concatenate([right, left], axis=0)


def _le_spline(le_half: np.ndarray) -> tuple[np.ndarray, CubicSpline, bool]:
    """Full-span cubic spline of the LE centre line over the polyline parameter t (right tip t = 0)."""
    has_centre = abs(le_half[0, 1]) < 1e-12
    le_f = _mirror(np.asarray(le_half, float), has_centre, True)
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(le_f, axis=0), axis=1))])
    return t, CubicSpline(t, le_f), has_centre


def _arc_length(sp: CubicSpline, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """Dense parameter samples on [t0, t1] and the cumulative 3-D arc length of the spline at them."""
    td = np.linspace(t0, t1, _N_DENSE)
    return td, np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(sp(td), axis=0), axis=1))])


def arc_fractions(le_half: np.ndarray) -> np.ndarray:
    """Arc-length fraction (0 centre, 1 right tip) of each half-span station along the interpolated LE line.

    Parameters
    ----------
    le_half : (n_st, 3) float [m]
        LE stations from the centre to the right tip (as in :class:`LeiDesign`).

    Returns
    -------
    (n_st,) float [-], the fractions the builder uses for ``strut_frac``.
    """
    t, sp, _ = _le_spline(le_half)
    td, sd = _arc_length(sp, 0.0, 0.5 * t[-1])
    t_st = t[: len(le_half)][::-1]  # the full-span data start with the right half reversed (tip first)
    return 1.0 - np.interp(t_st, td, sd) / sd[-1]


def _strut_sections(strut_frac: np.ndarray, n_sec: int) -> tuple[np.ndarray, np.ndarray]:
    """Section indices of the struts and the index (into strut_frac) each one comes from."""
    half = (n_sec - 1) // 2
    frac = np.asarray(strut_frac)
    k = np.floor(frac * half + 0.5).astype(int)  # sections counted from the centre
    if np.unique(k).size != k.size or np.any(k >= half) or np.any(k < 0) or np.any((k == 0) & (frac > 0)):
        raise ValueError(f"n_sec = {n_sec} is too coarse for struts at half-span fractions "
                         f"{[round(float(f), 3) for f in frac]}: nearest sections from the centre "
                         f"{[int(q) for q in k]} must be distinct, off the centre unless the fraction is 0, "
                         f"and inside the tips (< {half})")
    sec, src = [], []
    for q, kq in enumerate(k):
        sec.append(half - kq)
        src.append(q)
        if kq != 0:
            sec.append(half + kq)
            src.append(q)
    order = np.argsort(sec)
    return np.asarray(sec)[order], np.asarray(src)[order]


def build_lei_mesh(design: LeiDesign, n_sec: int = 37, m: int = 6) -> KiteMesh:
    """Build the FE/aero mesh of an LEI kite.

    Parameters
    ----------
    design : LeiDesign
    n_sec : int
        Number of spanwise sections, odd and >= 7.
    m : int
        Chordwise points per section, >= 3.

    Returns
    -------
    KiteMesh in frame K (identity frame from its own bridle points).
    """
    if int(n_sec) != n_sec or n_sec < 7 or n_sec % 2 == 0:
        raise ValueError(f"n_sec must be an odd integer >= 7, got {n_sec}")
    if int(m) != m or m < 3:
        raise ValueError(f"m (chordwise points) must be an integer >= 3, got {m}")
    if not 0.0 < design.camber_pos < 1.0:
        raise ValueError(f"camber_pos must lie in (0, 1), got {design.camber_pos}")
    n_sec, m = int(n_sec), int(m)
    half = (n_sec - 1) // 2

    # 1. full-span splines over the LE-polyline parameter t (symmetric data -> symmetric interpolants)
    t, sp_le, has_centre = _le_spline(design.le)
    t_mid = 0.5 * t[-1]
    sp_te = CubicSpline(t, _mirror(np.asarray(design.te, float), has_centre, True))
    sp_d = PchipInterpolator(t, _mirror(np.asarray(design.tube_d, float)[:, None], has_centre, False)[:, 0])

    # 2. right half: sections uniform in 3-D arc length from the right tip (t = 0) to the centre (t = t_mid)
    td, sd = _arc_length(sp_le, 0.0, t_mid)
    ts = np.interp(np.linspace(0.0, sd[-1], half + 1), sd, td)
    ts[0], ts[-1] = 0.0, t_mid
    le_r, te_r, d_r = sp_le(ts), sp_te(ts), sp_d(ts)
    le_r[-1, 1] = te_r[-1, 1] = 0.0  # centre section exactly on the symmetry plane

    # 3. airfoils: chord, normal, camber line (Eq. 5-6)
    chord_vec = te_r - le_r
    c_node = np.linalg.norm(chord_vec, axis=1)
    ex = chord_vec / c_node[:, None]
    if design.normal is None:  # section plane perpendicular to the LE line; e_y towards the right tip (-dt)
        ey = -sp_le.derivative()(ts)
        ey -= np.einsum("ij,ij->i", ey, ex)[:, None] * ex
        n_r = np.cross(ex, ey)
    else:
        n_r = CubicSpline(t, _mirror(np.asarray(design.normal, float), has_centre, True))(ts)
    n_r[-1, 1] = 0.0
    n_r = n_r - np.einsum("ij,ij->i", n_r, ex)[:, None] * ex
    n_r /= np.linalg.norm(n_r, axis=1)[:, None]
    xi = np.linspace(0.0, 1.0, m)
    p = 1.0 / design.camber_pos - 1.0
    shape = xi * (1.0 - xi) ** p
    shape /= shape.max()  # the discrete maximum (Eq. 6 uses the nodes) is 1
    c_eq5 = c_node + 0.5 * d_r  # Eq. (5)
    height = design.camber * c_eq5[:, None] * shape[None, :]  # Eq. (6): max_j height_j / c = camber
    pos_r = le_r[:, None, :] + (xi[None, :, None] * c_node[:, None, None]) * ex[:, None, :] \
        + height[:, :, None] * n_r[:, None, :]  # (half+1, m, 3)
    pos_l = pos_r[-2::-1].copy()
    pos_l[..., 1] *= -1.0
    n_l = n_r[-2::-1].copy()
    n_l[:, 1] *= -1.0
    pos = np.concatenate([pos_r, pos_l], axis=0)  # (n_sec, m, 3), right tip -> left tip
    normal = np.concatenate([n_r, n_l], axis=0)
    tube_d = np.concatenate([d_r, d_r[-2::-1]])
    sections = np.arange(n_sec * m).reshape(n_sec, m)
    nodes = pos.reshape(-1, 3)

    # 4. frame K from the mesh's own bridle points
    bridle = np.array([sections[0, 0], sections[0, -1], sections[-1, 0], sections[-1, -1]])
    origin, R = kite_frame(*nodes[bridle])
    nodes = to_frame(nodes - origin, R)
    normal = to_frame(normal, R)
    nodes[sections[half], 1] = 0.0
    pos = nodes[sections]

    # canopy triangles, mirrored diagonal pattern on the left half
    i, j = np.meshgrid(np.arange(n_sec - 1), np.arange(m - 1), indexing="ij")
    a, b = sections[i, j], sections[i, j + 1]  # section i, LE side / TE side
    c, d = sections[i + 1, j], sections[i + 1, j + 1]  # section i+1
    right = (i < half)[..., None]
    t1 = np.where(right, np.stack([a, c, b], -1), np.stack([a, c, d], -1))
    t2 = np.where(right, np.stack([c, d, b], -1), np.stack([a, d, b], -1))
    shells = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)], axis=0)

    # beams: LE chain, TE chain, struts, tips
    strut_sec, strut_src = _strut_sections(np.asarray(design.strut_frac, float), n_sec)
    le_b = np.stack([sections[:-1, 0], sections[1:, 0]], -1)
    te_b = np.stack([sections[:-1, -1], sections[1:, -1]], -1)
    chord_sec = np.concatenate([strut_sec, [0, n_sec - 1]])
    ch_b = np.stack([sections[chord_sec, :-1], sections[chord_sec, 1:]], -1).reshape(-1, 2)
    beams = np.concatenate([le_b, te_b, ch_b], axis=0)
    n_st = strut_sec.size
    kind = np.concatenate([np.full(n_sec - 1, BEAM_LE), np.full(n_sec - 1, BEAM_TE),
                           np.full(n_st * (m - 1), BEAM_STRUT), np.full(2 * (m - 1), BEAM_TIP)])
    xi_mid = 0.5 * (xi[:-1] + xi[1:])
    sd_le, sd_te = np.asarray(design.strut_d, float)[strut_src].T
    d_strut = sd_le[:, None] + (sd_te - sd_le)[:, None] * xi_mid[None, :]
    diameter = np.concatenate([0.5 * (tube_d[:-1] + tube_d[1:]), np.full(n_sec - 1, design.te_wire_d),
                               d_strut.ravel(), np.full(2 * (m - 1), design.tip_rod_d)])
    up_sec = np.concatenate([0.5 * (normal[:-1] + normal[1:]), 0.5 * (normal[:-1] + normal[1:]),
                             np.repeat(normal[chord_sec], m - 1, axis=0)])
    axis = nodes[beams[:, 1]] - nodes[beams[:, 0]]
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    up = up_sec - np.einsum("ij,ij->i", up_sec, axis)[:, None] * axis
    up /= np.linalg.norm(up, axis=1)[:, None]

    # strip widths from the LE node polyline (Eq. 7-9 use w); sum = LE polyline length
    seg = np.linalg.norm(np.diff(pos[:, 0], axis=0), axis=1)
    width = 0.5 * (np.concatenate([[0.0], seg]) + np.concatenate([seg, [0.0]]))

    info = dict(design.info)
    info.update(_mesh_numbers(nodes, shells, sections, width, tube_d, n_st))
    info.update(n_sec=n_sec, n_chord=m, camber_eq6=design.camber, camber_pos=design.camber_pos,
                strut_sections=[int(s) for s in strut_sec], tip_rod_d_m=design.tip_rod_d,
                te_wire_d_m=design.te_wire_d)
    return KiteMesh(name=design.name, nodes=nodes, shells=shells, beams=beams, beam_kind=kind,
                    beam_diameter=diameter, beam_up=up, sections=sections, section_width=width,
                    section_tube_d=tube_d, bridle=bridle, info=info)


def _mesh_numbers(nodes, shells, sections, width, tube_d, n_struts) -> dict:
    """Design numbers of a mesh (areas, spans, chords) for ``info``."""
    pos = nodes[sections]
    c_node = np.linalg.norm(pos[:, -1] - pos[:, 0], axis=1)
    c_eq5 = c_node + 0.5 * tube_d  # Eq. (5)
    nrm = triangle_normals(nodes, shells)
    flat_area = float(np.sum(width * c_eq5))
    span = float(np.sum(width))
    half = (len(width) - 1) // 2
    n_sec, m = sections.shape
    return dict(
        flat_area_m2=flat_area,  # sum of strip width x Eq.(5) chord (canopy from the tube front to the TE)
        canopy_mesh_area_m2=float(0.5 * np.linalg.norm(nrm, axis=1).sum()),  # triangles (from the tube centre)
        projected_area_m2=float(0.5 * np.abs(nrm[:, 2]).sum()),  # triangles projected onto the x_k-y_k plane
        flat_span_m=span,  # LE node polyline length
        flat_aspect_ratio=span**2 / flat_area,
        projected_span_m=float(np.ptp(nodes[:, 1])),
        arc_height_m=float(pos[half, 0, 2] - pos[0, 0, 2]),  # centre LE node above the tip LE nodes
        te_arc_height_m=float(pos[half, -1, 2] - pos[0, -1, 2]),
        chord_centre_node_m=float(c_node[half]), chord_tip_node_m=float(c_node[0]),
        chord_centre_eq5_m=float(c_eq5[half]), chord_tip_eq5_m=float(c_eq5[0]),
        tube_d_centre_m=float(tube_d[half]), tube_d_tip_m=float(tube_d[0]),
        dist_AC_m=float(np.linalg.norm(pos[0, 0] - pos[-1, 0])),
        dist_BD_m=float(np.linalg.norm(pos[0, -1] - pos[-1, -1])),
        n_struts=int(n_struts),
        counts=dict(nodes=n_sec * m, shells=2 * (n_sec - 1) * (m - 1),
                    beams=2 * (n_sec - 1) + (n_struts + 2) * (m - 1), dof=6 * n_sec * m),
    )
