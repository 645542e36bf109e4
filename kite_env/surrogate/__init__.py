"""Reduced-order wing (the fast fidelity): samples of the full aeroelastic wing, the MLP fitted to them
(:mod:`.model`) and the start table of the reset (:mod:`.start`).

The fitted files of a kite ship in ``kite_env/surrogate/data/`` as ``<kite>.npz`` (weights with provenance and
held-out errors) and ``<kite>_start.npz`` (start table); ``scripts/build_surrogate.py`` regenerates both.
"""

from __future__ import annotations

from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent / "data"


def _shipped() -> list[str]:
    return sorted(p.stem for p in DATA_DIR.glob("*.npz") if not p.stem.endswith("_start"))


def _path(kite_name: str, suffix: str, what: str) -> Path:
    path = DATA_DIR / f"{kite_name}{suffix}.npz"
    if not path.is_file():
        raise FileNotFoundError(f"no shipped reduced-order wing {what} for kite '{kite_name}' ({path} missing; "
                                f"shipped kites: {_shipped() or 'none'}); build one with scripts/build_surrogate.py "
                                "--out-dir runs/surrogate --install")
    return path


def default_surrogate_path(kite_name: str) -> Path:
    """Path of the shipped weights of ``kite_name`` (raises FileNotFoundError when none ship)."""
    return _path(kite_name, "", "weights")


def default_start_path(kite_name: str) -> Path:
    """Path of the shipped start table of ``kite_name`` (raises FileNotFoundError when none ships)."""
    return _path(kite_name, "_start", "start table")


def load_default(kite_name: str):
    """The shipped :class:`~kite_env.surrogate.model.SurrogateWing` of ``kite_name``."""
    from kite_env.surrogate.model import SurrogateWing

    return SurrogateWing.load(default_surrogate_path(kite_name))


def load_default_start(kite_name: str):
    """The shipped :class:`~kite_env.surrogate.start.StartTable` of ``kite_name``."""
    from kite_env.surrogate.start import StartTable

    return StartTable.load(default_start_path(kite_name))
