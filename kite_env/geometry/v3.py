"""TU Delft V3 LEI kite (25 m^2) from its public Surfplan export.

Data: transcribed from awegroup/TUDELFT_V3_KITE
``data/geometry/surfplan_export/V3D_3d.txt`` [S6] (commit e021aa95). Surfplan frame: x spanwise, y up, z chordwise
with the LE at +z. The 12 half-span ribs (rib 1 = tip, rib 12 = next to the centre) give the canopy LE point (front
of the LE tube) and the TE point; the LE tube centre line and its diameter come from the same file.

Construction
------------
* Station k = rib k. The LE tube centre at a rib is the rib's LE point moved by d/2 along the rib chord towards the
  TE (for ribs 2-12 this reproduces the exported tube centre line points 9-19 to < 2 mm, checked in the tests); the
  Eq. (5) chord ``|r_im - r_i1| + d/2`` then equals the Surfplan rib chord.
* The tip section is rib 1 (chord 1.385 m); the exported tube centre line wraps around the tip from rib 2 to aft of
  rib 1 (points 1-8), which the paper's topology represents by the tip beam along the tip section.
* Frame: the half-span data (Surfplan x > 0) are mapped with X = -z_s (aft), Y = x_s, Z = y_s (up). This is a
  reflection of the Surfplan axes, applied to a mirror-symmetric kite it equals the proper rotation y_k = -x_s of the
  other half; the builder then re-expresses the mesh in frame K from its bridle points A, B, C, D (rib 1 LE/TE).
* Section planes are perpendicular to the LE tube centre line (no rib-orientation vectors are transcribed).
* Struts at ribs 2, 5, 8, 11 and mirrored (Surfplan "Strut 2/5/8/11"; no centre strut); strut tube diameter linear
  between the exported LE-end and TE-end values.
* Camber kappa = 0.095 per Eq. (6) (the single-value V3 airfoil of the Vortex-Step-Method test scripts,
awegroup/Vortex-Step-Method); maximum of the camber
  line at 1/3 chord (modelling choice, the rib profiles are not transcribed).
* Tip beam: the V3 has no separate tip rod (its tip is the LE tube itself, d = 0.112 m). The mesh contract models
  the tip as a thin stiff rod; we keep the same 10 mm rod as for the Rhino and flag the difference in ``info``.
  Trailing-edge wire 2 mm (bridle line diameters are 2-5 mm in awegroup/kite_fem's V3 data).

Published global properties for comparison (awegroup/TUDELFT_V3_KITE, data/properties.yaml): flat area 25 m^2,
projected area 19.753 m^2, flat span 11.18 m, projected span 8.32 m, LE 3-D length 11.302 m, 8 struts.
This mesh (37 x 6): flat area (sum of strip width x Eq. (5) chord) 25.15 m^2 (+0.6 %); LE node polyline 11.29 m
(published LE length 11.302 m); projected canopy area 19.15 m^2 (the mesh canopy starts at the tube centre, the
published 19.75 m^2 includes the front half of the tube, about d/2 x 8.3 m = 0.7 m^2); |AC| = |BD| = 8.31 m
(published projected span 8.32 m; the mesh's y-extent, 8.56 m, includes the canopy camber at the vertical tips).
n_sec >= 11 is needed to give the eight struts distinct sections.
"""

from __future__ import annotations

import numpy as np

from .lei import LeiDesign, arc_fractions, build_lei_mesh
from .mesh import KiteMesh

# awegroup/TUDELFT_V3_KITE Surfplan export (data/geometry/surfplan_export/V3D_3d.txt): ribs, half span: rib, LE (x, y,
# z), TE (x, y, z) [m]; rib 1 = tip
SURFPLAN_RIBS = np.array([
    [1, 4.156287, 0.916618, 0.520832, 4.156287, 0.916618, -0.864107],
    [2, 3.967978, 1.791356, 0.709238, 3.955506, 1.787553, -1.011852],
    [3, 3.805350, 2.209568, 0.790880, 3.789238, 2.199439, -1.189372],
    [4, 3.501223, 2.540205, 0.864219, 3.485499, 2.522089, -1.256822],
    [5, 3.134335, 2.796493, 0.929298, 3.116753, 2.773988, -1.310901],
    [6, 2.798300, 3.092998, 0.986158, 2.780285, 3.065722, -1.354755],
    [7, 2.393198, 3.288677, 1.034831, 2.380855, 3.254511, -1.390237],
    [8, 1.959729, 3.398648, 1.075348, 1.946587, 3.361473, -1.418530],
    [9, 1.553762, 3.587398, 1.107733, 1.540958, 3.547442, -1.440421],
    [10, 1.111239, 3.671702, 1.132004, 1.107796, 3.627957, -1.456442],
    [11, 0.664252, 3.658834, 1.148177, 0.660721, 3.613797, -1.466944],
    [12, 0.225013, 3.741837, 1.156262, 0.220752, 3.696209, -1.472144],
])

# awegroup/TUDELFT_V3_KITE Surfplan export: LE tube centre line, half span: point, x, y, z, d [m]. Points 9-19 lie at
# ribs 2-12;
# points 1-8 wrap around the tip (rib 1 uses the diameter of point 1).
SURFPLAN_LE_TUBE = np.array([
    [1, 4.047384, 0.902987, -0.806316, 0.112452],
    [9, 3.967429, 1.791188, 0.633460, 0.151561],
    [10, 3.804690, 2.209154, 0.709853, 0.162061],
    [11, 3.500590, 2.539476, 0.778809, 0.170831],
    [12, 3.133636, 2.795597, 0.840178, 0.178254],
    [13, 2.797590, 3.091923, 0.893902, 0.184529],
    [14, 2.392716, 3.287341, 0.939956, 0.189772],
    [15, 1.959218, 3.397202, 0.978330, 0.194060],
    [16, 1.553266, 3.585851, 1.009025, 0.197442],
    [17, 1.111106, 3.670013, 1.032043, 0.199952],
    [18, 0.664116, 3.657099, 1.047385, 0.201615],
    [19, 0.224849, 3.740081, 1.055068, 0.202418],
])

# awegroup/TUDELFT_V3_KITE Surfplan export: struts: rib, diameter at the LE end, diameter at the TE end [m]
SURFPLAN_STRUTS = np.array([
    [2, 0.1057, 0.0789],
    [5, 0.1105, 0.0981],
    [8, 0.1320, 0.1063],
    [11, 0.1408, 0.1060],
])

# awegroup/TUDELFT_V3_KITE, data/properties.yaml
PUBLISHED = dict(flat_area_m2=25.0, projected_area_m2=19.753, flat_span_m=11.18, projected_span_m=8.32,
                 le_length_m=11.302, flat_max_chord_m=2.63, n_struts=8)

CAMBER = 0.095  # Eq. (6) camber, VSM single-value V3 airfoil (Vortex-Step-Method test scripts)
CAMBER_POS = 1.0 / 3.0  # chord fraction of the maximum camber (modelling choice)
TIP_ROD_D = 0.010  # [m] thin stiff tip rod of the mesh contract (modelling choice, see module docstring)
TE_WIRE_D = 0.002  # [m] trailing-edge wire (bridle line range 2-5 mm, awegroup/kite_fem V3 data)


def _to_design_frame(p_s: np.ndarray) -> np.ndarray:
    """Surfplan (x span, y up, z chord with LE at +z) -> (x aft, y span, z up) for the x_s > 0 half."""
    return np.stack([-p_s[..., 2], p_s[..., 0], p_s[..., 1]], axis=-1)


def rib_tube_centres() -> tuple[np.ndarray, np.ndarray]:
    """LE tube centre and diameter at ribs 1..12 in the Surfplan frame.

    Returns
    -------
    centre : (12, 3) float [m], diameter : (12,) float [m]
    """
    le, te = SURFPLAN_RIBS[:, 1:4], SURFPLAN_RIBS[:, 4:7]
    d = SURFPLAN_LE_TUBE[:, 4]
    ec = (te - le) / np.linalg.norm(te - le, axis=1)[:, None]
    return le + 0.5 * d[:, None] * ec, d


def v3_design() -> LeiDesign:
    """The V3 as an :class:`LeiDesign` (stations = ribs 12 ... 1, centre -> right tip)."""
    centre, d = rib_tube_centres()
    le = _to_design_frame(centre)[::-1]
    te = _to_design_frame(SURFPLAN_RIBS[:, 4:7])[::-1]
    d = d[::-1]
    rib_of_station = SURFPLAN_RIBS[::-1, 0].astype(int)
    frac = arc_fractions(le)
    strut_frac = np.array([frac[rib_of_station == r][0] for r in SURFPLAN_STRUTS[:, 0].astype(int)])
    info = dict(
        source="TU Delft V3 Surfplan export (awegroup/TUDELFT_V3_KITE "
               "data/geometry/surfplan_export/V3D_3d.txt)",
        published=PUBLISHED,
        strut_ribs=[int(r) for r in SURFPLAN_STRUTS[:, 0]],
        strut_frac=[float(f) for f in strut_frac],
        note_tip_beam="V3 tip is the LE tube itself (d = 0.112 m); modelled as the contract's 10 mm tip rod",
        note_alpha="no design kite angle of attack is published for the V3",
    )
    return LeiDesign(name="v3", le=le, te=te, normal=None, tube_d=d, strut_frac=strut_frac,
                     strut_d=SURFPLAN_STRUTS[:, 1:3], camber=CAMBER, camber_pos=CAMBER_POS,
                     tip_rod_d=TIP_ROD_D, te_wire_d=TE_WIRE_D, info=info)


def le_tube_profile() -> tuple[np.ndarray, np.ndarray]:
    """V3 LE tube diameter versus half-span LE arc fraction (0 centre, 1 tip), ordered centre -> tip.

    Returns
    -------
    frac : (12,) float [-], d : (12,) float [m]
    """
    design = v3_design()
    return arc_fractions(design.le), np.asarray(design.tube_d)


def build_v3(n_sections: int = 37, n_chord: int = 6) -> KiteMesh:
    """Mesh of the TU Delft V3 kite in frame K (see the module docstring)."""
    return build_lei_mesh(v3_design(), n_sections, n_chord)
