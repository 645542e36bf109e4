"""The simulator factory: the flight simulator of a config's fidelity and wing model, above the simulators it
chooses from (:mod:`kite_env.dynamics.simulator`, :mod:`kite_env.dynamics.dynamic_simulator`,
:mod:`kite_env.dynamics.fast`)."""

from __future__ import annotations

from kite_env.config import Config
from kite_env.dynamics.dynamic_simulator import DynamicFlightSimulator
from kite_env.dynamics.fast import SurrogateFlightSimulator
from kite_env.dynamics.simulator import FlightSimulator
from kite_env.fsi import AeroelasticWing
from kite_env.surrogate import surrogate_for


def make_simulator(cfg: Config, wind, wing: AeroelasticWing | None = None):
    """The flight simulator of ``cfg.sim.fidelity``: :class:`~kite_env.dynamics.simulator.FlightSimulator` (``"fe"``;
    :class:`~kite_env.dynamics.dynamic_simulator.DynamicFlightSimulator` with ``structure.dynamic``) or
    :class:`kite_env.dynamics.fast.SurrogateFlightSimulator` (``"surrogate"``, the weights of ``sim.surrogate_path``
    or the model shipped for ``kite.name``)."""
    if cfg.sim.fidelity == "surrogate":
        sw, path = surrogate_for(cfg)
        return SurrogateFlightSimulator(cfg, wind, surrogate=sw, wing=wing, surrogate_path=path,
                                        start=cfg.sim.surrogate_start)
    if cfg.structure.dynamic:
        return DynamicFlightSimulator(cfg, wind, wing)
    return FlightSimulator(cfg, wind, wing)
