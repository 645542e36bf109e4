"""North Rhino 16 m^2 (the paper's kite), built parametrically from the nominal dimensions of Fig. 3.

No public geometry of this kite was found. Fig. 3 of Bosch et al. gives six lengths of the FE
mesh: 5.80, 5.51, 0.634, 2.94, 3.20 and 1.93 m, plus 16 m^2 total area, five struts, and the nominal section angles
of attack 6.5 deg (both tips) and 12.7 deg (mid-wing) of the unloaded wing (Sect. II.A).

Interpretation (lengths are node-to-node distances of the FE mesh, since Fig. 3 draws the mesh)
-----------------------------------------------------------------------------------------------
* 5.80 m = |AC| (power-line attachments, LE tips) and 5.51 m = |BD| (steering lines, TE tips): the paper calls the
  ~1 m loaded tip-distance reduction "about 20% of the design value"; 0.634 m = |AB| = |CD|, the tip chord (tip
  beam). In frame K: A = (0, 2.90, 0), B = (0.617, 2.755, 0), i.e. the tip chords converge by 13.2 deg in plan.
* 1.93 m = centre chord; 2.94 m = height of the centre LE node above the line AC (LE arc height); 3.20 m = height
  of the centre TE node above the line BD. The centre chord is therefore pitched 7.74 deg nose-down relative to
  x_k, and alpha_mid = 12.7 deg fixes the design kite angle of attack alpha_k = 12.7 + 7.74 = 20.44 deg (free stream
  in the x_k-z_k plane, u = (cos a_k, 0, sin a_k)).

Evaluated alternatives (37 x 6 mesh, same laws below; flat area = sum of strip width x Eq. (5) chord; numbers from
``build_lei_mesh(rhino16_design(h_le=..., h_te=..., c0=...))``):

=============================================  ==========================================================
reading                                        result
=============================================  ==========================================================
(B) h_LE 2.94, h_TE 3.20, c0 1.93 (chosen)     flat area 15.69 m^2 (-1.9 %), flat span 9.56 m, AR 5.8,
                                               alpha_k 20.44 deg, tip curled 16.8 deg past vertical
(A) h_LE 3.20, h_TE 2.94, c0 1.93              alpha_k 4.96 deg; alpha_tip = 6.5 deg needs the tip
                                               dihedral 131.5 deg: no convex arc of height 3.20 m reaches
                                               it (radius of curvature < 0 at the tip) -> rejected
(C) c0 3.20, h_LE 2.94 (no pitch, 1.93 unused) flat area 25.8 m^2 (+61 %), AR 3.9 -> rejected
(D) c0 2.94, h_LE 3.20 (no pitch, 1.93 unused) flat area 24.9 m^2 (+56 %), AR 4.4 -> rejected
(E) c0 2.94 or 3.20, h_LE 1.93                 no convex arc of height 1.93 m reaches the tip -> rejected
(B0) as (B) but no pitch (3.20 unused)         flat area 15.78 m^2, but leaves one dimension unexplained
=============================================  ==========================================================

(B) is the only reading that uses all six numbers, gives a convex arc, and lands within 2 % of 16 m^2 with a
flat span of 9.6 m and AR 5.8. What does not fit: the flat area is 15.69 m^2, 1.9 % below the nominal 16 m^2
(not tuned: the chord law below is a fixed choice); the tips must be curled 17 deg past vertical for alpha_tip =
6.5 deg (a section whose plane contained x_k would see 13.2 deg at the tip for any alpha_k, because of the 13.2 deg
tip-chord convergence), so the outermost sections' span direction e_y points slightly to -y_k: a section frame
must orient e_y along the LE towards the right tip, not by the sign of its y_k component. The design sections are
exact planes and the angles above use the airfoil-plane normal as e_y (the paper: "perpendicular to the airfoil").
A spanwise direction taken from the neighbouring LE nodes instead (one-sided at the tips) deviates from it by up to
12 deg at the tip sections (the LE is swept back ~25 deg and curls over the last strip) and 4 deg at the next ones,
and then reads alpha_tip ~ 11.5 deg instead of 6.5 deg at 37 x 6.

Design laws (eta = fraction of the half LE arc projected on the y_k-z_k plane, 0 centre, 1 tip)
----------------------------------------------------------------------------------------------
* LE arc in the y-z plane: dihedral gamma (angle of the arc normal from z_k) from 0 to gamma_tip, radius of
  curvature rho(gamma) = R0 + R1 (gamma/gamma_tip)^2; R0, R1 solve "tip at (y, z) = (2.90, 0)" from the centre LE at
  z = 2.94. gamma_tip (106.4 deg), tip twist (12.7 deg) and toe follow from the tip triad (chord A->B, roll for
  alpha_tip).
* Section triad: h = cos(psi) x + sin(psi) e_y0, chord e_x = cos(theta) h - sin(theta) n0, normal
  n = sin(theta) h + cos(theta) n0, with n0 = (0, sin g, cos g), e_y0 = (0, cos g, -sin g) (ribs nearly streamwise),
  toe psi = psi_tip eta^2 (psi_tip = 3.8 deg, needed to meet B), twist theta chosen so that the section angle of
  attack at alpha_k is alpha(eta) = 6.5 + (12.7 - 6.5)(1 - eta^2) deg: theta = alpha - atan2(u.n0, u.h).
* Node chord: truncated ellipse c(eta) = 1.93 sqrt(1 - (eta/eta_e)^2), eta_e such that c(1) = 0.634 m (finite slope
  at the tip). Mid-chord points aligned at x = 0.308 m (unswept mid-chord line, as on the V3 whose rib mid-chords
  lie within 3 cm of one line, awegroup/TUDELFT_V3_KITE Surfplan export); this sweeps the LE back towards the tips.
* LE tube diameter: the V3 distribution versus LE arc fraction, scaled by the length ratio sqrt(16/25) = 0.8
  (centre 0.162 m, tip 0.090 m). Struts: centre + two per side at 1/3 and 2/3 of the half LE arc (equal panels;
  positions not published), diameter at the LE end 0.674 x local LE tube d and at the TE end 0.80 x that (mean
  ratios of the V3 struts, awegroup/TUDELFT_V3_KITE). Tip rod 10 mm (solid "thin stiff beam"), TE wire 2 mm.
* Camber kappa = 0.08 per Eq. (6) (a middle value; the deformed V3's sections in awegroup/Vortex-Step-Method's data span
  0.04-0.095), maximum of the camber line at 1/3 chord.
"""

from __future__ import annotations

import numpy as np

from .lei import LeiDesign, build_lei_mesh
from .mesh import KiteMesh
from .v3 import SURFPLAN_STRUTS, le_tube_profile, rib_tube_centres

# Fig. 3 nominal dimensions [m] and Sect. II.A nominal angles (seed paper)
DIST_AC = 5.80
DIST_BD = 5.51
TIP_CHORD = 0.634
H_LE = 2.94
H_TE = 3.20
CENTRE_CHORD = 1.93
ALPHA_MID_DEG = 12.7
ALPHA_TIP_DEG = 6.5
NOMINAL_AREA = 16.0  # [m^2]

STRUT_FRAC = (0.0, 1.0 / 3.0, 2.0 / 3.0)  # centre + 2 per side, equal LE-arc panels (choice)
LENGTH_SCALE = np.sqrt(16.0 / 25.0)  # Rhino / V3 (flat areas 16 and 25 m^2)
CAMBER = 0.08
CAMBER_POS = 1.0 / 3.0
TIP_ROD_D = 0.010  # [m]
TE_WIRE_D = 0.002  # [m]
_N_STATIONS = 161


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tip_triad(alpha_k: float, alpha_tip: float, a: float, b: float, c_tip: float):
    """Tip chord e_x (A -> B), the roll of the tip section giving alpha_tip, and its (gamma, theta, psi) angles."""
    ex = np.array([np.sqrt(c_tip**2 - (a - b) ** 2), -(a - b), 0.0]) / c_tip
    w = _unit(np.cross([0.0, 0.0, 1.0], ex))
    u = np.array([np.cos(alpha_k), 0.0, np.sin(alpha_k)])
    # alpha(phi) = atan2(u.n, u.ex) with n = cos(phi) z + sin(phi) w  ->  P cos(phi) + Q sin(phi) = C
    P, Q, C = u[2], u @ w, np.tan(alpha_tip) * (u @ ex)
    amp = np.hypot(P, Q)
    if abs(C) > amp:
        raise ValueError("tip angle of attack unreachable for this tip chord")
    phi = np.arctan2(Q, P) + np.arccos(C / amp)  # the root past 90 deg (C-shaped, curled tip)
    n = np.cos(phi) * np.array([0.0, 0.0, 1.0]) + np.sin(phi) * w
    theta = np.arctan2(n[0], ex[0])  # the arc normal n0 lies in the section plane and has no x component
    n0 = -np.sin(theta) * ex + np.cos(theta) * n
    gamma = np.arctan2(n0[1], n0[2])
    ey0 = np.array([0.0, np.cos(gamma), -np.sin(gamma)])
    h = (ex + np.sin(theta) * n0) / np.cos(theta)
    psi = np.arctan2(h @ ey0, h[0])
    return ex, phi, gamma, theta, psi


def _arc(gamma_t: float, a: float, h: float, gam: np.ndarray):
    """y, z of the LE arc with rho = R0 + R1 (gamma/gamma_t)^2 through (0, h) and (a, 0); returns y, z, s, R0, R1."""
    def integrals(g):
        s, c = np.sin(g), np.cos(g)
        g2 = gamma_t**2
        return s, 1.0 - c, (g**2 * s + 2 * g * c - 2 * s) / g2, (-(g**2) * c + 2 * g * s + 2 * c - 2) / g2

    ic, is_, ic2, is2 = integrals(gamma_t)
    R0, R1 = np.linalg.solve([[ic, ic2], [is_, is2]], [a, h])
    if R0 <= 0 or R0 + R1 <= 0:
        raise ValueError(f"no convex LE arc of height {h:.3f} m reaches the tip dihedral {np.degrees(gamma_t):.1f} deg "
                         f"(radius of curvature R0 = {R0:.3f}, R0 + R1 = {R0 + R1:.3f} m)")
    jc, js, jc2, js2 = integrals(gam)
    y = R0 * jc + R1 * jc2
    z = h - (R0 * js + R1 * js2)
    s = R0 * gam + R1 * gam**3 / (3 * gamma_t**2)
    return y, z, s, R0, R1


def rhino16_design(h_le: float = H_LE, h_te: float = H_TE, c0: float = CENTRE_CHORD) -> LeiDesign:
    """The Rhino 16 as an :class:`LeiDesign` for a reading of Fig. 3 (defaults: the chosen reading (B)).

    Parameters
    ----------
    h_le, h_te : float [m]
        Heights of the centre LE / TE nodes above the tip LE / TE lines.
    c0 : float [m]
        Centre node chord.

    Raises
    ------
    ValueError
        If the reading admits no convex LE arc.
    """
    a, b = 0.5 * DIST_AC, 0.5 * DIST_BD
    theta_c = np.arcsin((h_le - h_te) / c0)  # centre pitch, nose-up positive
    alpha_k = np.radians(ALPHA_MID_DEG) - theta_c  # centre section plane = x-z plane: alpha_mid = alpha_k + theta_c
    alpha_t, alpha_m = np.radians(ALPHA_TIP_DEG), np.radians(ALPHA_MID_DEG)
    ex_t, phi_t, gamma_t, theta_t, psi_t = _tip_triad(alpha_k, alpha_t, a, b, TIP_CHORD)

    gam = np.linspace(0.0, gamma_t, _N_STATIONS)
    y, z, s, R0, R1 = _arc(gamma_t, a, h_le, gam)
    eta = s / s[-1]
    n0 = np.stack([np.zeros_like(gam), np.sin(gam), np.cos(gam)], -1)
    ey0 = np.stack([np.zeros_like(gam), np.cos(gam), -np.sin(gam)], -1)
    psi = psi_t * eta**2
    h = np.cos(psi)[:, None] * np.array([1.0, 0.0, 0.0]) + np.sin(psi)[:, None] * ey0
    u = np.array([np.cos(alpha_k), 0.0, np.sin(alpha_k)])
    alpha = alpha_t + (alpha_m - alpha_t) * (1.0 - eta**2)
    theta = alpha - np.arctan2(n0 @ u, h @ u)
    ex = np.cos(theta)[:, None] * h - np.sin(theta)[:, None] * n0
    normal = np.sin(theta)[:, None] * h + np.cos(theta)[:, None] * n0
    eta_e = 1.0 / np.sqrt(1.0 - (TIP_CHORD / c0) ** 2)
    chord = c0 * np.sqrt(1.0 - (eta / eta_e) ** 2)
    x_mid = 0.5 * TIP_CHORD * ex_t[0]
    le = np.stack([x_mid - 0.5 * chord * ex[:, 0], y, z], -1)
    te = le + chord[:, None] * ex
    le[0, 1] = te[0, 1] = normal[0, 1] = 0.0
    # consistency of the tip with the imposed bridle geometry (A = (0, a, 0), B = A + c_tip e_x,tip)
    if not (np.allclose(ex[-1], ex_t, atol=1e-9) and np.allclose(le[-1], [0.0, a, 0.0], atol=1e-9)):
        raise ValueError("internal: tip section does not meet the bridle points")

    # LE tube and strut diameters from the V3, scaled by LENGTH_SCALE
    frac_le = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(le, axis=0), axis=1))])
    frac_le /= frac_le[-1]
    v3_frac, v3_d = le_tube_profile()
    tube_d = LENGTH_SCALE * np.interp(frac_le, v3_frac, v3_d)
    _, v3_rib_d = rib_tube_centres()
    ratio_le = np.mean(SURFPLAN_STRUTS[:, 1] / v3_rib_d[SURFPLAN_STRUTS[:, 0].astype(int) - 1])
    ratio_te = np.mean(SURFPLAN_STRUTS[:, 2] / SURFPLAN_STRUTS[:, 1])
    d_le_strut = ratio_le * np.interp(STRUT_FRAC, frac_le, tube_d)
    strut_d = np.stack([d_le_strut, ratio_te * d_le_strut], -1)

    info = dict(
        source="parametric, from the nominal dimensions of Bosch et al. Fig. 3 (see kite_env.geometry.rhino16)",
        interpretation=("|AC| = 5.80, |BD| = 5.51, |AB| = |CD| = 0.634 (tip chord), centre chord 1.93, centre LE "
                        "node 2.94 above AC, centre TE node 3.20 above BD (node-to-node distances)"),
        nominal=dict(dist_AC_m=DIST_AC, dist_BD_m=DIST_BD, tip_chord_m=TIP_CHORD, h_le_m=h_le, h_te_m=h_te,
                     centre_chord_m=c0, area_m2=NOMINAL_AREA, alpha_mid_deg=ALPHA_MID_DEG,
                     alpha_tip_deg=ALPHA_TIP_DEG),
        alpha_k_design_deg=float(np.degrees(alpha_k)),
        centre_pitch_deg=float(np.degrees(theta_c)),
        tip_roll_deg=float(np.degrees(phi_t)),  # angle of the tip canopy normal from z_k about the tip chord
        tip_dihedral_deg=float(np.degrees(gamma_t)),
        tip_twist_deg=float(np.degrees(theta_t)),
        tip_toe_deg=float(np.degrees(psi_t)),
        arc_R0_m=float(R0), arc_R1_m=float(R1),
        alpha_law="alpha(eta) = 6.5 + (12.7 - 6.5)(1 - eta^2) deg at alpha_k, eta = projected half-arc fraction",
        strut_frac=list(STRUT_FRAC),
        strut_diameter_ratios=dict(le_end_over_le_tube=float(ratio_le), te_end_over_le_end=float(ratio_te)),
        tube_d_scale=float(LENGTH_SCALE),
    )
    return LeiDesign(name="rhino16", le=le, te=te, normal=normal, tube_d=tube_d, strut_frac=np.asarray(STRUT_FRAC),
                     strut_d=strut_d, camber=CAMBER, camber_pos=CAMBER_POS, tip_rod_d=TIP_ROD_D,
                     te_wire_d=TE_WIRE_D, info=info)


def build_rhino16(n_sections: int = 37, n_chord: int = 6) -> KiteMesh:
    """Mesh of the North Rhino 16 m^2 in frame K (see the module docstring)."""
    mesh = build_lei_mesh(rhino16_design(), n_sections, n_chord)
    mesh.info["flat_area_vs_nominal"] = mesh.info["flat_area_m2"] / NOMINAL_AREA - 1.0
    return mesh


