"""Kite geometry and mesh generation: :func:`build_kite` returns the unloaded design mesh in frame K.

Kites: ``"rhino16"`` (North Rhino 16 m^2 of the paper, built from the nominal dimensions of Fig. 3, see
:mod:`kite_env.geometry.rhino16`) and ``"v3"`` (TU Delft V3, from its public Surfplan export, see
:mod:`kite_env.geometry.v3`). The mesh contract is :class:`~kite_env.geometry.mesh.KiteMesh`.
"""

from __future__ import annotations

from .mesh import BEAM_LE, BEAM_STRUT, BEAM_TE, BEAM_TIP, KiteMesh
from .rhino16 import build_rhino16
from .v3 import build_v3

KITES = {"rhino16": build_rhino16, "v3": build_v3}


def build_kite(name: str, n_sections: int = 37, n_chord: int = 6) -> KiteMesh:
    """Design mesh of a named kite.

    Parameters
    ----------
    name : str
        ``"rhino16"`` or ``"v3"``.
    n_sections : int
        Spanwise sections, odd and >= 7 (the V3's eight struts need >= 11).
    n_chord : int
        Chordwise points per section, >= 3.

    Raises
    ------
    ValueError
        Unknown name (the message lists the known kites) or an invalid resolution.
    """
    try:
        builder = KITES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown kite {name!r}; known kites: {', '.join(sorted(KITES))}") from None
    return builder(n_sections, n_chord)


__all__ = ["BEAM_LE", "BEAM_STRUT", "BEAM_TE", "BEAM_TIP", "KITES", "KiteMesh", "build_kite"]
