"""The kite's finite-element mesh: the data contract shared by the structure and the aerodynamics.

Topology (Bosch et al., Sect. II.A/B, Fig. 3-4): ``n_sec`` spanwise wing sections with ``m`` chordwise load points
each (node ``sections[i, j]``, ``j = 0`` on the leading-edge tube centre line, ``j = m-1`` at the trailing edge);
sections run from the RIGHT tip (index 0, ``y_k > 0``) to the LEFT tip. Counts for ``n_struts`` strut sections::

    n_nodes  = n_sec * m                                   (37 x 6: 222)
    n_shells = 2 (n_sec - 1)(m - 1)                        (360)
    n_beams  = 2 (n_sec - 1) + (n_struts + 2)(m - 1)       (LE + TE chains, struts, 2 tips; 5 struts: 107)
    n_dof    = 6 n_nodes                                   (1332)

Beam kinds: :data:`BEAM_LE` (leading-edge tube), :data:`BEAM_STRUT` (strut tube), :data:`BEAM_TIP` (tip rod),
:data:`BEAM_TE` (trailing-edge wire). The bridle points are ``[A, B, C, D] = [LE of section 0, TE of section 0,
LE of section n_sec-1, TE of section n_sec-1]``; all positions are given in the kite frame K
(:mod:`kite_env.frames`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

BEAM_LE = 0
BEAM_STRUT = 1
BEAM_TIP = 2
BEAM_TE = 3
BEAM_KIND_NAMES = {BEAM_LE: "leading edge", BEAM_STRUT: "strut", BEAM_TIP: "tip", BEAM_TE: "trailing edge"}

_TOL_UNIT = 1e-8  # tolerance on unit length / orthogonality of beam_up [-]


def triangle_normals(nodes: np.ndarray, shells: np.ndarray) -> np.ndarray:
    """Non-normalised triangle normals ``(x1 - x0) x (x2 - x0)``.

    Parameters
    ----------
    nodes : (n_nodes, 3) float [m]
    shells : (n_shells, 3) int

    Returns
    -------
    (n_shells, 3) float [m^2], twice the triangle area times the unit normal.
    """
    x = nodes[shells]
    return np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])


@dataclass(frozen=True, eq=False)
class KiteMesh:
    """Unloaded design mesh of an LEI kite in frame K.

    Attributes
    ----------
    name : str
    nodes : (n_nodes, 3) float [m]
        Design positions in frame K.
    shells : (n_shells, 3) int
        Canopy triangles; the normal ``(x1 - x0) x (x2 - x0)`` points to the +z_k (suction) side at mid-span.
    beams : (n_beams, 2) int
    beam_kind : (n_beams,) int
        ``BEAM_LE``, ``BEAM_STRUT``, ``BEAM_TIP`` or ``BEAM_TE``.
    beam_diameter : (n_beams,) float [m]
        Inflated-tube diameter (LE, strut) or rod/wire diameter (tip, TE).
    beam_up : (n_beams, 3) float [-]
        Unit vector perpendicular to the beam axis: the canopy normal at the beam.
    sections : (n_sec, m) int
        Node indices per section, LE (j = 0) to TE (j = m-1), right tip (index 0) to left tip.
    section_width : (n_sec,) float [m]
        Spanwise strip width w of each section (Eq. 7-9); sums to the length of the LE node polyline.
    section_tube_d : (n_sec,) float [m]
        LE tube diameter d at each section (thickness t = d / c, Eq. 5).
    bridle : (4,) int
        Node indices of the bridle points A, B, C, D.
    info : dict
        Provenance and design numbers (areas, spans, design angles, ...).

    Raises
    ------
    ValueError
        On construction, if the arrays are inconsistent (see :meth:`check`).
    """

    name: str
    nodes: np.ndarray
    shells: np.ndarray
    beams: np.ndarray
    beam_kind: np.ndarray
    beam_diameter: np.ndarray
    beam_up: np.ndarray
    sections: np.ndarray
    section_width: np.ndarray
    section_tube_d: np.ndarray
    bridle: np.ndarray
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.check()

    # ------------------------------------------------------------------ sizes
    @property
    def n_nodes(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def n_sec(self) -> int:
        return int(self.sections.shape[0])

    @property
    def n_chord(self) -> int:
        return int(self.sections.shape[1])

    @property
    def n_shells(self) -> int:
        return int(self.shells.shape[0])

    @property
    def n_beams(self) -> int:
        return int(self.beams.shape[0])

    @property
    def n_dof(self) -> int:
        return 6 * self.n_nodes

    # ------------------------------------------------------------------ helpers
    def mirror_nodes(self) -> np.ndarray:
        """(n_nodes,) int: the index of the node mirrored about the x-z plane (section i <-> n_sec-1-i)."""
        mirror = np.empty(self.n_nodes, dtype=int)
        mirror[self.sections] = self.sections[::-1]
        return mirror

    def beams_of_kind(self, kind: int) -> np.ndarray:
        """(n, 2) int: the beams of one kind."""
        return self.beams[self.beam_kind == kind]

    # ------------------------------------------------------------------ validation
    def check(self) -> None:
        """Validate shapes, index ranges and geometric consistency; raise ValueError naming the problem."""

        def fail(msg: str) -> None:
            raise ValueError(f"KiteMesh '{self.name}': {msg}")

        nodes = np.asarray(self.nodes)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or nodes.shape[0] < 4:
            fail(f"nodes must have shape (n_nodes >= 4, 3), got {nodes.shape}")
        if not np.all(np.isfinite(nodes)):
            fail("nodes contain non-finite coordinates")
        n = nodes.shape[0]
        for key, arr, cols in (("shells", self.shells, 3), ("beams", self.beams, 2), ("sections", self.sections, None)):
            arr = np.asarray(arr)
            if arr.ndim != 2 or (cols is not None and arr.shape[1] != cols) or arr.shape[0] == 0:
                fail(f"{key} must be a non-empty 2-D int array{'' if cols is None else f' with {cols} columns'}, "
                     f"got shape {arr.shape}")
            if not np.issubdtype(arr.dtype, np.integer):
                fail(f"{key} must be an integer array, got dtype {arr.dtype}")
            if arr.min() < 0 or arr.max() >= n:
                fail(f"{key} index out of range [0, {n}): min {arr.min()}, max {arr.max()}")
        n_sec, m = self.sections.shape
        if n_sec < 3 or m < 2:
            fail(f"sections must be at least (3, 2), got {self.sections.shape}")
        if n_sec * m != n or np.unique(self.sections).size != n:
            fail(f"sections {self.sections.shape} must list every node exactly once (n_nodes = {n})")
        n_b = self.beams.shape[0]
        if np.asarray(self.beam_kind).shape != (n_b,):
            fail(f"beam_kind must have shape ({n_b},), got {np.asarray(self.beam_kind).shape}")
        bad = ~np.isin(self.beam_kind, list(BEAM_KIND_NAMES))
        if bad.any():
            fail(f"beam_kind has unknown codes {np.unique(np.asarray(self.beam_kind)[bad])}; known {BEAM_KIND_NAMES}")
        if np.asarray(self.beam_diameter).shape != (n_b,) or not np.all(np.asarray(self.beam_diameter) > 0):
            fail(f"beam_diameter must be ({n_b},) and strictly positive")
        if np.asarray(self.beam_up).shape != (n_b, 3):
            fail(f"beam_up must have shape ({n_b}, 3), got {np.asarray(self.beam_up).shape}")
        for key, arr in (("section_width", self.section_width), ("section_tube_d", self.section_tube_d)):
            if np.asarray(arr).shape != (n_sec,) or not np.all(np.asarray(arr) > 0):
                fail(f"{key} must be ({n_sec},) and strictly positive")
        expected = [self.sections[0, 0], self.sections[0, -1], self.sections[-1, 0], self.sections[-1, -1]]
        if np.asarray(self.bridle).shape != (4,) or list(self.bridle) != [int(e) for e in expected]:
            fail(f"bridle must be [A, B, C, D] = [LE/TE of section 0, LE/TE of section {n_sec - 1}] = {expected}, "
                 f"got {list(np.asarray(self.bridle))}")
        if nodes[self.bridle[0], 1] <= nodes[self.bridle[2], 1]:
            fail("section 0 must be the RIGHT tip (y_A > y_C)")
        used = np.zeros(n, bool)
        used[self.shells.ravel()] = True
        if not used.all():
            fail(f"{np.count_nonzero(~used)} node(s) belong to no canopy triangle, "
                 f"e.g. node {np.flatnonzero(~used)[0]}")
        area2 = np.linalg.norm(triangle_normals(nodes, self.shells), axis=1)
        if area2.min() <= 0.0:
            fail(f"degenerate canopy triangle {int(np.argmin(area2))} (zero area)")
        axis = nodes[self.beams[:, 1]] - nodes[self.beams[:, 0]]
        length = np.linalg.norm(axis, axis=1)
        if length.min() <= 0.0:
            fail(f"zero-length beam {int(np.argmin(length))}")
        up = np.asarray(self.beam_up, dtype=float)
        if np.abs(np.linalg.norm(up, axis=1) - 1.0).max() > _TOL_UNIT:
            fail("beam_up vectors must be unit vectors")
        cosang = np.abs(np.einsum("ij,ij->i", up, axis)) / length
        if cosang.max() > _TOL_UNIT:
            fail(f"beam_up of beam {int(np.argmax(cosang))} is not perpendicular to its axis "
                 f"(cos = {cosang.max():.2e})")
