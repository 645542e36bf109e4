"""Reduced-order wing (the fast fidelity): the wing (:mod:`.model`) and its inputs and outputs (:mod:`.samples`), the
start table of the reset (:mod:`.start`) and the shipped files. It stands below the dynamics, which fly it
(:mod:`kite_env.dynamics.fast`); how it is made (flights of the full model recorded step by step, the fit, the
agreement of the two fidelities) is :mod:`kite_env.fitting`, above the environment, and the start table is built by
:mod:`kite_env.dynamics.start_table`.

The fitted files of a kite ship in ``kite_env/surrogate/data/`` as ``<kite>.npz`` (weights with the model they were
fitted to, provenance and held-out errors) and ``<kite>_start.npz`` (start table); ``kite-fit`` makes both for any
model. A wing or start table made with another model than the one asked for is refused (:func:`surrogate_for`).
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
                                f"shipped kites: {_shipped() or 'none'}); make one with kite-fit (sample, fit, "
                                "start-table)")
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


def surrogate_for(cfg):
    """``(wing, path)``: the reduced-order wing of ``cfg``'s model, ``sim.surrogate_path`` or the one shipped for
    ``kite.name``. One fitted to another model raises :class:`kite_env.config.ModelMismatch` naming the keys that
    differ (the fast fidelity is never a silent extrapolation to another model)."""
    from kite_env.config import check_model
    from kite_env.surrogate.model import SurrogateWing

    path = Path(cfg.sim.surrogate_path) if cfg.sim.surrogate_path else default_surrogate_path(cfg.kite.name)
    wing = SurrogateWing.load(path)
    check_model(wing.meta.get("model"), cfg, f"reduced-order wing '{path}'")
    return wing, path
