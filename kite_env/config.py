"""Configuration: frozen dataclasses grouped by subsystem, loaded from YAML with ``section.key=value`` overrides.

Each key is declared once, with :func:`key`: its default, its meaning and unit, and what values it takes (a choice,
a range, a check). These declarations are the single source of truth: the checks of :func:`config_from_dict` read
them, and ``configs/default.yaml`` and ``docs/configuration.md`` are generated from them
(``python -m kite_env.config_reference --write``; a test fails when the committed files are not what it writes).

Errors: an unknown section or key, a retired key (:data:`RETIRED`: one that only chose a former default), a value of
the wrong type, or a physically invalid value (negative stiffness, pressure, ...) raises :class:`ConfigError` with one
message that names the offending key.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, TypeVar

import yaml

from kite_env.trajectory import TrajectoryConfig
from kite_env.wind import WindConfig


class ConfigError(ValueError):
    """Invalid configuration: the message names the key and what is wrong with it."""


_T = TypeVar("_T")


def key(default: _T, doc: str, unit: str = "", *, note: str = "", choices: tuple[Any, ...] | None = None,
        lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
        range_note: str = "", check: tuple[Callable[[Any], bool], str] | None = None, inf_ok: bool = False) -> _T:
    """One configuration key: a dataclass field with ``default`` whose metadata documents and validates it.

    ``doc``: its meaning in one line; ``unit``: its unit (``-`` dimensionless, empty for switches and names);
    ``note``: the longer explanation (sources, the measurements behind the default, the docs that discuss it).
    Validation (:func:`check_key`): ``choices``, the values allowed; ``lo``/``hi``, the bounds of a range (closed
    unless ``lo_open``/``hi_open``; ``range_note`` is said after the range in its error message); ``check``, a
    predicate and what it asks for (``"be odd and >= 7"``); ``inf_ok``: ``.inf`` is allowed (every other
    number must be finite). Checks that relate several keys stay in :func:`_validate`."""
    if choices is not None and default not in choices:
        raise TypeError(f"default {default!r} is not one of its choices {choices!r}")
    meta = {"doc": doc, "unit": unit, "note": note, "choices": choices, "lo": lo, "hi": hi, "lo_open": lo_open,
            "hi_open": hi_open, "range_note": range_note, "check": check, "inf_ok": inf_ok}
    return field(default=default, metadata=MappingProxyType(meta))


def _num(x: Any) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def allowed_values(meta: Mapping[str, Any]) -> str:
    """What a key takes, in words (``'a' or 'b'``, ``[0, 1]``, ``> 0``, ...), from its :func:`key` metadata; empty
    when anything of its type is allowed."""
    parts = []
    if meta.get("choices") is not None:
        names = [repr(c) if isinstance(c, str) else _num(c) for c in meta["choices"]]
        parts.append(names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}")
    lo, hi = meta.get("lo"), meta.get("hi")
    if hi is not None:
        lo_s = "-inf" if lo is None else _num(lo)
        interval = f"{'(' if meta['lo_open'] or lo is None else '['}{lo_s}, {_num(hi)}{')' if meta['hi_open'] else ']'}"
        parts.append(interval + (f" ({meta['range_note']})" if meta.get("range_note") else ""))
    elif lo is not None:
        parts.append("positive" if lo == 0 and meta["lo_open"] else f"{'>' if meta['lo_open'] else '>='} {_num(lo)}")
    if meta.get("check") is not None:
        parts.append(meta["check"][1].removeprefix("be "))
    if meta.get("inf_ok"):
        parts.append(".inf allowed")
    return "; ".join(parts)


def check_key(name: str, value: Any, meta: Mapping[str, Any]) -> None:
    """Raise :class:`ConfigError` naming ``name`` (``section.key``) when ``value`` breaks its :func:`key`
    metadata ``meta``: not one of its choices, outside its range, or failing its check."""
    choices = meta.get("choices")
    if choices is not None and value not in choices:
        raise ConfigError(f"config key '{name}' must be {allowed_values({'choices': choices})}, got {value!r}")
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is not None or hi is not None:
        above = lo is None or (value > lo if meta["lo_open"] else value >= lo)
        below = hi is None or (value < hi if meta["hi_open"] else value <= hi)
        if not (above and below):
            words = allowed_values({**meta, "choices": None, "check": None, "inf_ok": False})
            if hi is not None:
                raise ConfigError(f"config key '{name}' must lie in {words}, got {value}")
            raise ConfigError(f"config key '{name}' must be {words}, got {value!r}")
    if meta.get("check") is not None:
        predicate, wanted = meta["check"]
        if not predicate(value):
            raise ConfigError(f"config key '{name}' must {wanted}, got {value!r}")


#: wing models of the flight simulation (sim.fidelity)
FIDELITIES = ("fe", "surrogate")
#: aero.damping choices (fsi.SectionDamping; "eq3" is the paper's Eq. 3 as printed)
AERO_DAMPING = ("consistent", "eq3")
#: aero.rotation_point choices (aero.sections.apparent_wind): the paper's LE node, or the 3/4-chord point
ROTATION_POINTS = ("le_node", "three_quarter_chord")

#: observation terms of the Gymnasium environment (kite_env.envs), in the order they are stacked
OBSERVATION_TERMS = ("position", "heading", "line_forces", "path", "rates", "actuator")


def _observation_ok(value: str) -> bool:
    terms = [t.strip() for t in value.split(",") if t.strip()]
    return bool(terms) and all(t in OBSERVATION_TERMS for t in terms) and len(set(terms)) == len(terms)


@dataclass(frozen=True)
class KiteConfig:
    """The kite: its geometry and how finely its wing is meshed."""

    name: str = key("rhino16", "kite geometry: rhino16 | v3")
    n_sections: int = key(37, "spanwise sections", "-", check=(lambda n: n % 2 == 1 and n >= 7, "be odd and >= 7"))
    n_chord: int = key(6, "chordwise load points per section", "-", lo=3)


@dataclass(frozen=True)
class StructureConfig:
    """The wing's structure: canopy membrane, inflated tubes, tip rods and trailing edge, and the wing with inertia."""

    canopy_E_Pa: float = key(1.25e9, "canopy Young's modulus (paper)", "Pa", lo=0, lo_open=True,
                             note="canopy: isotropic linear ripstop (paper, Sect. II.A)")
    canopy_nu: float = key(0.3, "canopy Poisson ratio (paper)", "-", lo=-1, hi=0.5, lo_open=True, hi_open=True)
    canopy_thickness_m: float = key(0.08e-3, "canopy thickness (paper)", "m", lo=0, lo_open=True)
    wrinkling: bool = key(True, "tension-field canopy membrane (no compressive membrane stress)")
    canopy_shear_ratio: float = key(
        1.0, "canopy in-plane shear modulus / isotropic E/(2(1+nu)); <1: woven fabric, threads along chord and span",
        "-", lo=0, hi=1, lo_open=True, range_note="1: the isotropic canopy",
        note="1 = the paper's isotropic law; below 1 a balanced woven fabric with its threads along the chord (x of "
             "frame K) and span (kite_env.structure.shell_membrane.fabric_matrix, relaxed_general; docs/steering.md, "
             "\"Where a steering input goes\")")
    membrane_kinematics: str = key(
        "green_lagrange", "canopy membrane strain: green_lagrange (exact for any rotation) | von_karman (the paper's)",
        choices=("green_lagrange", "von_karman"),
        note="\"von_karman\" is the paper's (Sect. II.A: \"von Karman kinematic description\"): its tensioned canopy "
             "has no geometric stiffness against in-plane motion, and it strains an element turned in its plane by "
             "theta by cos(theta) - 1 (kite_env.structure.shell_membrane; docs/steering.md, \"The von Karman "
             "membrane\")")
    tube_pressure_Pa: float = key(
        0.3e5, "tube gauge pressure (0.3 bar)", "Pa", lo=0, lo_open=True,
        note="inflated tubes (LE, struts): Breukels' correlations (Breukels 2011); 0.3 bar = the V3's flight pressure "
             "in awegroup/kite_fem and kitesim")
    tube_wall_Et_N_per_m: float = key(
        2.0e5, "tube wall axial stiffness E*t (modelling choice)", "N/m", lo=0, lo_open=True,
        note="EA = pi d (E t)_fabric. No measured Dacron data is public: modelling choice of twice the canopy's "
             "membrane stiffness E h = 1e5 N/m (tube fabric is a heavier cloth)")
    tube_fold_onset_deg: float = key(
        90.0, "fold contact of a kinked tube from this element fold angle, closing at 180 deg; 0 = none", "deg",
        lo=0, hi=180, hi_open=True, range_note="0: no fold contact",
        note="kite_env.structure.tube.fold_contact, part of the conservative tube law: from this fold angle of an "
             "element (rms curvature times length) its legs press on each other and the fold closes at 180 deg "
             "instead of passing it (Breukels' collapsed tube is a hinge of no stiffness; the co-rotational element "
             "cannot represent a fold of 180 deg: docs/model.md, \"Section frame, fold contact, rotary inertia\")")
    tip_rod_E_Pa: float = key(
        30.0e9, "tip rod Young's modulus (glass fibre, modelling choice)", "Pa", lo=0, lo_open=True,
        note="tip beams (\"thin stiff beam\", Sect. II.A): a solid glass-fibre rod (modelling choice), diameter from "
             "the mesh")
    te_wire_E_Pa: float = key(
        5.5e8, "trailing-edge wire effective modulus", "Pa", lo=0, lo_open=True,
        note="Dyneema line, effective modulus of the kite_fem/kitesim bridle models (awegroup/kite_fem, "
             "awegroup/ASKITE)")
    te_hem_EI_Nm2: float = key(0.4, "bending stiffness of the trailing-edge hem (wire + seam tape), both axes "
                               "(modelling choice)", "N m^2", lo=0, lo_open=True)
    dynamic: bool = key(
        True, "the wing with inertia (nodal + added mass, generalized-alpha); false = the paper's quasi-static wing",
        note="dynamics/wing_dynamics.py: nodal masses (Table 1's 10 kg, 70 % on the LE tube) and the canopy's added "
             "mass, generalized-alpha in time, A-D wing nodes held by the bridle lines (docs/model.md, \"The wing "
             "with inertia\"; its verification: docs/validation.md, \"Time-step convergence\", \"Against the static "
             "wing\"); false = the paper's quasi-static wing on the particles A-D")
    rho_inf: float = key(0.8, "generalized-alpha spectral radius at infinite frequency (1 = no numerical damping)", "-",
                         lo=0, hi=1)
    added_mass_factor: float = key(
        1.0, "canopy added mass: factor on rho pi c^2/4 per span x AR/(1+AR); 0 = none", "-", lo=0,
        note="added mass normal to the canopy: this factor times rho pi c^2 / 4 per unit span with Lissaman & "
             "Brown's k_C = AR / (1 + AR) (AIAA-93-1236)")
    rotary_inertia_factor: float = key(
        1.0, "nodal rotary inertia: factor on m (a^2 + b^2) / 24 of the tributary rectangle; 0 = massless rotations",
        "-", lo=0,
        note="rotary inertia of the wing's nodes (dynamic wing): this factor times the second moment of each node's "
             "tributary rectangle (chordwise a, spanwise b) about the node, the mean of its two in-plane axes "
             "(lumped rotary inertia as in the HRZ lumping of Hinton, Rock & Zienkiewicz 1976, which gives a uniform "
             "beam's node m l^2 / 39); 0 = massless, quasi-static rotations (a slack canopy's trailing-edge rotations "
             "then have nothing to hold them, docs/model.md, \"Section frame, fold contact, rotary inertia\")")
    rayleigh_beta_s: float = key(
        1.6e-3, "structural damping beta K_T of the wing with inertia: 2 % of critical at 4 Hz; 0 = none", "s", lo=0,
        note="stiffness-proportional (Rayleigh) C = beta K_T on the nodal translations, beta = 2 zeta / omega_ref: 2 % "
             "of critical (the level of the paper's relative damping coefficients of the wing, Table 1: 0.015-0.02) "
             "at 4 Hz, the wing's lowest elastic mode in flight (its yaw/twist mode on the lines, 3.6-3.9 Hz), and "
             "more at every higher one (6.4e-4 s, 2 % at 10 Hz, gives 0.8 % at that mode; docs/model.md, "
             "\"Structural damping\")")
    rayleigh_tangent_period_s: float = key(
        0.02, "its tangent K_T refreshed when this old, held (turned with the frame) in between; 0 = every step", "s",
        lo=0,
        note="the time from the step end where the tangent was assembled to the current step's end: the damping "
             "matrix of the wing's shape at most this long ago. Assembling the full tangent at each step's Newton "
             "start cost 0.4 ms of a 5.5 ms step (docs/performance.md, \"The damping tangent held over 20 ms\")")
    membrane_forces: str = key(
        "averaged", "canopy forces in a step of the wing with inertia: averaged (generalized-alpha's averaged end "
        "forces) | energy_consistent (discrete gradient)", choices=("energy_consistent", "averaged"),
        note="\"energy_consistent\" = the discrete gradient of the stored energy between the step's ends (Gonzalez "
             "2000), whose work is the energy change at the wrinkling law's kinks, Green-Lagrange membrane only; "
             "\"averaged\" = generalized-alpha's averaged end forces, which pump energy into the canopy's fast "
             "membrane modes (a free wing gained 75 % of its kinetic energy in 0.3 s)")
    carry_residual: str = key(
        "sections", "wing with inertia: a step's unbalanced Newton residual carried into the next step's load: "
        "sections (its resultant on each section) | full", choices=("sections", "full"),
        note="the force residual that a step's Newton leaves (below fsi.tol_force_rel of the load) is added to the "
             "next step's load, so that its impulse is delivered one step late instead of lost (the unbalanced force "
             "correction; dropped, every step's residual was a small force on the wing that the flight integrated: "
             "the KCU lay 9.7 cm from the tightly converged flight after 10 s at 5 ms, 15 cm at 2.5 ms). "
             "\"sections\": the residual's resultant force and moments on each chordwise section, spread over its "
             "nodes like a rigid section's inertial load (1.4 cm, and Newton 1.59 instead of 1.68 iterations per "
             "step); \"full\": all of it (0.1 cm; 1.78 iterations: the part within a section is what a kept "
             "factorisation contracts worst) (docs/performance.md, \"The carried residual\")")


@dataclass(frozen=True)
class AeroConfig:
    """The aerodynamics of the wing's sections (Breukels' regression, paper Sect. II.B)."""

    rho_kg_m3: float = key(1.225, "air density (sea level, 15 deg C, ISA)", "kg/m^3", lo=0, lo_open=True)
    moment_chord_power: float = key(
        2.0, "p of Eq. (9) M = 1/2 rho CM c^p w V^2: 2 = dimensionally consistent; 1 = as printed in the paper", "-",
        choices=(1.0, 2.0))
    canopy_luffing: bool = key(
        True, "as a section's CL falls to 0 its load moves from the canopy to the LE tube and TE wire; false = the "
        "paper",
        note="a membrane cannot carry a reversed pressure (aero.loads.LUFFING_BAND_CL)")
    cm_regression_ref_over_c: float = key(
        0.0, "point / chord (from the nose) that Breukels' regression CM is taken about: 0 = the nose (the paper's "
        "trim), 0.25 = the quarter chord (the open VSM codes)", "-", lo=0, hi=1,
        note="the nose gives the paper's 7.5 deg mid-wing alpha (docs/model.md, \"Trim: the point Breukels' C_M is "
             "taken about\")")
    damping: str = key(
        "consistent", "damping of the wing's deformation velocity: consistent (section damping, PSD) | eq3 (Eq. 3 as "
        "printed)", choices=AERO_DAMPING,
        note="\"consistent\" = each section's quasi-steady force response to its own translation velocity, spread "
             "over its nodes (symmetric part positive semi-definite; fsi.SectionDamping); \"eq3\" = Eq. (3) as "
             "printed (mean LE/TE finite-difference velocity in the inflow): indefinite, unstable")
    rotation_point: str = key(
        "three_quarter_chord", "where the frame's rotation omega x r enters the inflow (Eq. 2): three_quarter_chord "
        "(Pistolesi's collocation point) | le_node (the paper's)", choices=ROTATION_POINTS)
    induced_drag: bool = key(
        False, "3-D induced drag C_D += C_L^2 / (pi e AR) per section; false = the paper's 2-D sections",
        note="aero.loads.section_loads; e from Raymer's estimate at the wing's projected aspect ratio. The paper names "
             "its 2-D sections as why its L/D exceeds ~6")
    negative_alpha: str = key(
        "bounded", "section coefficients below zero lift: bounded (by V3 2-D CFD) | breukels (the regression as is)",
        choices=("bounded", "breukels"),
        note="aero/breukels.py; the regression as is gives 4-5 times the measured negative lift")


@dataclass(frozen=True)
class FsiConfig:
    """The solver of the aeroelastic wing (fluid-structure coupling, Newton): tolerances and iteration limits."""

    tol_disp_m: float = key(1.0e-4, "coupling: max nodal position change between coupling iterations", "m",
                            lo=0, lo_open=True)
    tol_force_rel: float = key(1.0e-3, "coupling: change of the aero load vector relative to its norm", "-",
                               lo=0, lo_open=True)
    accept_force_rel: float = key(
        1.0e-2, "a stalled Newton solve is accepted (and flagged) below this relative force residual", "-",
        lo=0, lo_open=True,
        note="a monolithic Newton solve that stalls (chattering between taut and slack canopy states) is accepted at "
             "its best iterate (WingSolution.accepted)")
    max_coupling_iter: int = key(200, "coupling iterations per solve at most", "-", lo=0, lo_open=True)
    newton_per_coupling: int = key(4, "Newton iterations between two aero load updates", "-", lo=0, lo_open=True)
    max_bridle_step_m: float = key(0.02, "larger bridle-point moves are applied in converged sub-steps", "m",
                                   lo=0, lo_open=True)
    cold_load_steps: int = key(6, "dynamic-pressure ramp steps for a cold start from the unloaded wing", "-",
                               lo=0, lo_open=True)
    relax_initial: float = key(0.3, "first under-relaxation factor of the aero loads (Aitken thereafter)", "-",
                               lo=0, lo_open=True)
    relax_min: float = key(0.02, "lower bound of the Aitken relaxation factor", "-", lo=0, lo_open=True)
    max_newton_iter: int = key(30, "monolithic Newton iterations per solve", "-", lo=0, lo_open=True)
    max_retries: int = key(3, "retries of a failed solve: fresh start, damped Newton, then finer bridle sub-steps",
                           "-", lo=0)


@dataclass(frozen=True)
class DynamicsConfig:
    """The particle system of wing masses, bridle, KCU and tether (paper Sect. II.C, Fig. 5, Table 1), the ground
    station and the time integration of the flight."""

    mass_le_kg: float = key(3.5, "m_A = m_C, 70 % of the wing mass at the leading edge (Table 1)", "kg",
                            lo=0, lo_open=True)
    mass_te_kg: float = key(1.5, "m_B = m_D (Table 1)", "kg", lo=0, lo_open=True)
    mass_kcu_kg: float = key(3.0, "m_KCU (Table 1)", "kg", lo=0, lo_open=True)
    beta_ac: float = key(0.02, "relative damping A-C (Table 1), fraction of critical", "-", lo=0)
    beta_bd: float = key(0.002, "relative damping B-D (Table 1)", "-", lo=0)
    beta_diag: float = key(0.015, "relative damping A-D and B-C (Table 1)", "-", lo=0)
    line_diameter_m: float = key(0.0012, "bridle-line diameter d_c (Table 1)", "m", lo=0, lo_open=True)
    line_cd: float = key(1.1, "cylinder drag coefficient of a line in cross flow (awegroup/ASKITE, kitesim's "
                         "bridle-line drag)", "-", lo=0)
    line_stiffness_N_per_m: float = key(4.52e3, "k_c (Table 1)", "N/m", lo=0, lo_open=True)
    line_damping_Ns_per_m: float = key(251.7, "c_c (Table 1)", "N s/m", lo=0)
    power_line_length_m: float = key(25.0, "rest lengths L_A = L_C (Table 1)", "m", lo=0, lo_open=True)
    tether_length_m: float = key(80.0, "l_t = |r_KCU| (Table 1)", "m", lo=0, lo_open=True)
    tether_diameter_m: float = key(0.0, "tether drag (not in the paper's model); 0 = off", "m", lo=0)
    gravity_mps2: float = key(9.81, "gravitational acceleration", "m/s^2", lo=0)
    dt_s: float = key(0.005, "fixed RK4 time step (the paper's adaptive RK45 averaged 5.3 ms)", "s", lo=0, lo_open=True)
    baumgarte_1_per_s: float = key(20.0, "constraint stabilisation rate of the tether and tip constraints", "1/s",
                                   lo=0, lo_open=True)
    winch: str = key(
        "force", "ground station: force (holds the tether below winch_force_N, reels out above) | fixed (the paper's "
        "constant tether length, Table 1)", choices=("fixed", "force"),
        note="FlightSimulator, docs/model.md, \"The ground station\": \"force\" = a winch with an upper force limit: "
             "it holds the tether at its length while the tether force stays below winch_force_N and reels out above "
             "it (traction phase; no reel-in), the reel-out speed following (F_t - winch_force_N) / "
             "winch_damping_Ns_per_m within [0, winch_speed_max_mps] with the time constant winch_time_constant_s "
             "(after the winch models of Fechner et al. 2015, Renewable Energy 83, 705, and the force-limited "
             "reel-out of van der Vlugt et al. 2019, Renewable Energy 131, 83). The default: the paper's force "
             "controller (Eq. 18-19), meant \"to keep the tension in the tether between a minimum and maximum value\" "
             "(Sect. II.D), cannot depower this four-point wing, and the paper names the real system's force control "
             "as the ground station's (Sect. III); below the set force the flight is the paper's constant tether")
    winch_force_N: float = key(15000.0, "upper tether force limit of the ground station (a set point)", "N",
                               lo=0, lo_open=True)
    winch_damping_Ns_per_m: float = key(1000.0, "tether force rise per m/s of reel-out speed", "N s/m",
                                        lo=0, lo_open=True)
    winch_speed_max_mps: float = key(10.0, "largest reel-out speed of the ground station", "m/s", lo=0, lo_open=True)
    winch_time_constant_s: float = key(0.5, "lag of the reel-out speed behind its set value", "s", lo=0, lo_open=True)
    max_substep_halvings: int = key(
        4, "a step whose wing solve fails is split in halves, down to dt / 2**max_substep_halvings", "-", lo=0,
        note="FlightSimulator.step")
    tether: str = key(
        "rope", "tether between ground station and KCU: rope (pulls only) | rod (the paper's bilateral constraint)",
        choices=("rod", "rope"),
        note="\"rod\" = the paper's bilateral constraint |r_KCU| = l_t (Eq. 12-13; a tether that would have to push "
             "ends the flight as \"slack tether\"); \"rope\" = a unilateral constraint that only pulls: the KCU flies "
             "free inside the sphere when the tether would go slack, and its outward radial velocity is removed (an "
             "inelastic jerk) when it reaches the sphere again (dynamics/dynamic_simulator.py). The wing with "
             "inertia's tether (default: a tether cannot push, and with the rod random steering ended every episode "
             "within 0.4 s, docs/environment.md, \"Random steering\"); the quasi-static wing (structure.dynamic = "
             "false) always flies the paper's rod: a slack tether unloads the bridle, which that wing cannot follow")
    coupling: str = key(
        "explicit", "the wing's force over a step: explicit (held + condensed stiffness) | predictor_corrector",
        choices=("explicit", "predictor_corrector"))
    wing_point_mass_share: float = key(
        0.6, "share of Table 1's wing mass kept as the paper's four point masses at A-D (1 = the paper); the rest "
        "spread over the FE nodes and condensed", "-", lo=0, hi=1,
        note="the rest is spread over the FE nodes (70 % on the LE tube) and condensed onto A-D with the wing's "
             "static modes (dynamics/wing_mass.py). 0.6 is the smallest share for which the explicit RK4 step with "
             "the bridle-line dampers is stable up to dt = 10 ms (end masses m_B = m_D >= c_c dt / 2.78 = 0.9 kg; "
             "the condensed modes alone put 0.04 kg there); with structure.dynamic it must be below 1")


@dataclass(frozen=True)
class ControlConfig:
    """The paper's steering (Eq. 14-17) and force (Eq. 18-19) controllers and the steering-line actuator. The paper
    gives no gains: they are chosen for this model's steering authority (docs/model.md, "Controller gains and the
    force loop")."""

    k1_m_per_rad: float = key(1.0, "K1: heading error -> desired steering-line difference, Eq. (15)", "m/rad", lo=0)
    k2: float = key(3.0, "K2: steering-line length loops, Eq. (16-17)", "-", lo=0, lo_open=True)
    k3_m: float = key(0.5, "K3: force-ratio loop, Eq. (19)", "m", lo=0)
    k3i_per_s: float = key(2.0, "integral gain of the force-ratio loop (kite_env.control); 0 = the paper's "
                           "proportional Eq. (19)", "m/s", lo=0)
    force_integral_max_m: float = key(1.0, "anti-windup: |K3i I| at most this", "m", lo=0)
    mu_target: float = key(0.3, "desired force ratio mu* (Sect. III.B)", "-", lo=0)
    delta_l_max_m: float = key(1.5, "limit of the desired steering-line difference |dl*|", "m", lo=0, lo_open=True)
    beta_distance_deg: float = key(4.0, "blending: beta = 1/2 at this distance to the path (on the unit sphere)",
                                   "deg", lo=0, lo_open=True)
    beta_min: float = key(0.2, "blending: smallest weight of the path tangent", "-", lo=0, hi=1)
    control_dt_s: float = key(0.02, "controller update period", "s", lo=0, lo_open=True)
    line_speed_max_mps: float = key(
        2.0, "speed limit of each of the KCU's two motors: steering (half the difference of the steering lines' "
        "rest lengths) and depower (their mean); 0 = none (the paper's Eq. 16-17)", "m/s", lo=0,
        note="per controller period at most this times control_dt_s (kite_env.control.actuate), on each motor's axis "
             "as the KCU moves the lines (van der Vlugt et al., \"Design and experimental characterization of a "
             "pumping kite power system\", in Airborne Wind Energy, Springer 2013, ch. 23; Fechner et al., Renewable "
             "Energy 83, 705, 2015): a saturated steering command leaves the force loop's common change its own "
             "speed (docs/environment.md, \"The KCU's two motors\"). 2 m/s (the default with the wing with inertia: "
             "a held full input otherwise moves the lines by metres in one controller period) is above all the "
             "baseline asks after its first 0.1 s (1.45 m/s); a real KCU is slower (docs/model.md, \"Large steering "
             "inputs\")")


@dataclass(frozen=True)
class SimConfig:
    """A flight: its length, its start and the wing model that flies it."""

    duration_s: float = key(60.0, "simulated time", "s", lo=0, lo_open=True)
    warmup_s: float = key(3.0, "initial transient excluded from the metrics", "s", lo=0)
    initial_speed_mps: float = key(0.0, "initial flight speed along the path; 0 = initial_speed_per_wind times "
                                   "wind.speed_mps", "m/s", lo=0)
    initial_speed_per_wind: float = key(
        4.4, "the initial speed as a multiple of wind.speed_mps where initial_speed_mps is 0 (22 m/s at 5 m/s)", "-",
        lo=0,
        note="a kite's crosswind speed grows in proportion to the wind (Loyd 1980, J. Energy 4(3), 106); 4.4 gives "
             "the paper's 22 m/s at its 5 m/s. From 22 m/s at 10 m/s the wing starts at half its flight speed and "
             "folds in the acceleration (docs/environment.md, \"Starts\")")
    fidelity: str = key("fe", "wing model: fe (the aeroelastic FE wing) | surrogate (the reduced-order wing, "
                        "kite_env.surrogate)", choices=FIDELITIES)
    surrogate_path: str = key("", "surrogate weights (.npz); empty = the model shipped for kite.name")
    surrogate_start: str = key(
        "table", "the surrogate's start: table (the start table fitted to FE starts, else solved) | fe (solved with "
        "the FE wing) | table_only (a start the table lacks fails and the env redraws it: training)",
        choices=("table", "fe", "table_only"))
    surrogate_dt_s: float = key(
        0.01, "the RK4 step of the reduced-order wing's particle system; a whole number of them makes one control "
        "period", "s", lo=0, lo_open=True,
        note="10 ms flies the agreement flights within 0.1 % of the 5 ms step's traction at 5-10 m/s (1.6 % at 4 m/s) "
             "at half the cost; 20 ms leaves the fitted envelope within 10 s (docs/fast_fidelity.md, \"Time step\")")


@dataclass(frozen=True)
class EnvConfig:
    """The Gymnasium environments KiteFigureEight-v1 and KiteFigureEightFast-v1 (kite_env.envs): episode,
    observation, reward and the randomisation of the start."""

    max_episode_s: float = key(60.0, "simulated time limit of an episode (truncation); at least control.control_dt_s",
                               "s", lo=0, lo_open=True)
    force_controller: bool = key(True, "the paper's force controller (Eq. 18-19) runs inside the env")
    observation: str = key(
        "position,heading,line_forces,path,rates,actuator", "observation terms, comma-separated",
        check=(_observation_ok, f"list distinct terms of {', '.join(OBSERVATION_TERMS)} separated by commas"))
    force_scale_N: float = key(5000.0, "line and tether forces are observed divided by this", "N", lo=0, lo_open=True)
    w_tracking: float = key(1.0, "weight of the tracking reward exp(-(delta / tracking_scale)^2) per step", "-", lo=0)
    tracking_scale_deg: float = key(5.0, "distance to the figure-eight at which the tracking reward is 1/e", "deg",
                                    lo=0, lo_open=True)
    w_traction: float = key(0.5, "weight of the traction reward F_tether / traction_ref per step", "-", lo=0)
    traction_ref_N: float = key(5000.0, "tether force at which the traction reward is 1", "N", lo=0, lo_open=True)
    w_action_rate: float = key(0.1, "weight of the penalty (a_k - a_k-1)^2 per step", "-", lo=0)
    crash_penalty: float = key(50.0, "reward -crash_penalty on a physical failure (terminated)", "-", lo=0)
    slack_tether_N: float = key(50.0, "a tether force below this ends the episode (slack tether)", "N", lo=0)
    wind_speed_min_mps: float = key(5.0, "wind speed drawn uniformly per episode from [min, max]: min", "m/s", lo=0)
    wind_speed_max_mps: float = key(5.0, "wind speed drawn per episode: max", "m/s", lo=0)
    turbulence_intensity_min: float = key(0.0, "turbulence intensity drawn uniformly per episode from [min, max]: min",
                                          "-", lo=0)
    turbulence_intensity_max: float = key(0.0, "turbulence intensity drawn per episode: max", "-", lo=0)
    random_start: bool = key(False, "start at a random point of the figure-eight (else at the crossing, like "
                             "kite-eval)")
    start_curvature_max: float = key(
        math.inf, "random starts only where the path's geodesic curvature |kappa_g| is at most this (1: the straight "
        "segments)", "1/rad", lo=0, lo_open=True, inf_ok=True,
        note="the straight segments through the crossing: the start has neutral steering and no turn rate, and from "
             "there a start in a turn fails in the full model within ~0.2 s (the controller's steering step on the "
             "untwisted wing)")
    initial_speed_min_mps: float = key(22.0, "initial speed along the path drawn from [min, max]: min", "m/s",
                                       lo=0, lo_open=True)
    initial_speed_max_mps: float = key(22.0, "initial speed drawn: max", "m/s", lo=0, lo_open=True)
    initial_speed_per_wind_min: float = key(
        0.0, "> 0 (with _max): the initial speed is drawn from [min, max] times the drawn wind speed instead: min; "
        "0 = the m/s range", "-", lo=0,
        note="the crosswind speed of a kite grows with the wind, ~ L/D times it: 4.4 gives the 22 m/s at 5 m/s of the "
             "fixed start and keeps a start at 10 m/s from beginning at half its flight speed, a wing that does not "
             "converge at the start")
    initial_speed_per_wind_max: float = key(0.0, "initial speed per m/s of wind drawn: max (both 0 or both > 0)", "-",
                                            lo=0)
    reset_attempts: int = key(5, "draws of the start before reset() gives up (the wing must converge at the start)",
                              "-", lo=0, lo_open=True)
    randomize: bool = key(
        True, "false: no draws at all: the wind section as configured and the start at the crossing at "
        "sim.initial_speed_mps (kite-eval's conditions)",
        note="turbulence realisation wind.seed unless reset() gets options={\"wind_seed\": n}")


@dataclass(frozen=True)
class Config:
    kite: KiteConfig = field(default_factory=KiteConfig)
    structure: StructureConfig = field(default_factory=StructureConfig)
    aero: AeroConfig = field(default_factory=AeroConfig)
    fsi: FsiConfig = field(default_factory=FsiConfig)
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    env: EnvConfig = field(default_factory=EnvConfig)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return dataclasses.asdict(self)

    @property
    def start_speed_mps(self) -> float:
        """The flight's initial speed along the path [m/s]: ``sim.initial_speed_mps`` where that is set (> 0), else
        ``sim.initial_speed_per_wind`` times the wind speed."""
        v = self.sim.initial_speed_mps
        return v if v > 0.0 else self.sim.initial_speed_per_wind * self.wind.speed_mps

    @property
    def physics_dt_s(self) -> float:
        """The flight simulation's time step [s] in the fidelity ``sim.fidelity``: ``dynamics.dt_s`` for the FE wing,
        ``sim.surrogate_dt_s`` for the reduced-order wing."""
        return self.sim.surrogate_dt_s if self.sim.fidelity == "surrogate" else self.dynamics.dt_s



def _coerce(name: str, value: Any, default: Any, inf_ok: bool = False) -> Any:
    """Convert ``value`` to the type of ``default`` or raise a ConfigError naming ``name`` (``section.key``); a
    number must be finite (``inf_ok``: or ``.inf``)."""
    typ = type(default)
    if typ is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "yes", "no"):
            return value.lower() in ("true", "1", "yes")
        raise ConfigError(f"config key '{name}' expects true/false, got {value!r}")
    if typ is int:
        if isinstance(value, bool):
            raise ConfigError(f"config key '{name}' expects an integer, got {value!r}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"config key '{name}' expects an integer, got {value!r}") from None
        if not f.is_integer():
            raise ConfigError(f"config key '{name}' expects an integer, got {value!r}")
        return int(f)
    if typ is float:
        if isinstance(value, bool):
            raise ConfigError(f"config key '{name}' expects a number, got {value!r}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"config key '{name}' expects a number, got {value!r}") from None
        if not math.isfinite(f) and not (inf_ok and f == math.inf):
            raise ConfigError(f"config key '{name}' must be finite, got {value!r}")
        return f
    if typ is str:
        if not isinstance(value, str):
            raise ConfigError(f"config key '{name}' expects a string, got {value!r}")
        return value
    return value


def _parse_scalar(text: str) -> Any:
    """Parse the right-hand side of a ``--set key=value`` override like a YAML scalar."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


#: quantities the environment draws per episode (``env.randomize``) and their ranges: a layer of configuration (a file,
#: a dict, the overrides) that gives the quantity without its range pins the range to that value, so that the value
#: given is the value flown (and a range stays optional)
RANDOMISED = {
    "wind.speed_mps": ("env.wind_speed_min_mps", "env.wind_speed_max_mps"),
    "wind.turbulence_intensity": ("env.turbulence_intensity_min", "env.turbulence_intensity_max"),
    "sim.initial_speed_mps": ("env.initial_speed_min_mps", "env.initial_speed_max_mps",
                              "env.initial_speed_per_wind_min", "env.initial_speed_per_wind_max"),
    "sim.initial_speed_per_wind": ("env.initial_speed_per_wind_min", "env.initial_speed_per_wind_max"),
}


#: keys that only chose a former default, retired with it ("one key per quantity"): each ``section.key`` and the single
#: value every model now has. Those of :data:`MODEL_SECTIONS` stay in a model's record (:func:`fingerprint`), so that
#: an artefact made before they were retired keeps its fingerprint and one made at another value is refused
#: (:func:`check_model`); a configuration that still gives one is refused (:func:`config_from_dict`).
RETIRED: dict[str, Any] = {
    "structure.tube_curvature": "element_energy",
    "structure.te_hem_element": "rod",
    "structure.added_mass_force": "normal_velocity_rate",
    "fsi.extrapolate": True,
    "control.actuator_axes": "steer_depower",
}

#: what every model now does in place of each retired key (the message that refuses it)
RETIRED_NOW: dict[str, str] = {
    "structure.tube_curvature": "a tube element's Breukels law is taken at the element's root-mean-square curvature, "
                                "the gradient of a stored energy with an exact tangent (docs/model.md, \"The "
                                "conservative tube law\")",
    "structure.te_hem_element": "the trailing-edge hem is made of frame-free rods (docs/model.md, \"The "
                                "trailing-edge hem\")",
    "structure.added_mass_force": "the added mass exerts Theodorsen's non-circulatory force, M_a a plus the "
                                  "normal-rate part at the 3/4-chord point (docs/model.md, \"Theodorsen's force\")",
    "fsi.extrapolate": "a warm time step starts from the linear extrapolation of the last two steps",
    "control.actuator_axes": "control.line_speed_max_mps limits the KCU's steering and depower motors "
                             "(docs/environment.md, \"The KCU's two motors\")",
}


def _retired_model_keys() -> dict[str, Any]:
    """The retired keys of :data:`MODEL_SECTIONS` with their one value (:data:`RETIRED`)."""
    return {k: v for k, v in RETIRED.items() if k.split(".")[0] in MODEL_SECTIONS}


def without_retired(data: dict[str, Any]) -> dict[str, Any]:
    """A complete configuration recorded before keys were retired (``{section: {key: value}}``, e.g. a kite-train
    run's ``config.yml``) without its retired keys where they hold their one value (:data:`RETIRED`), ready for
    :func:`config_from_dict`; a retired key at another value is left in, so that the configuration is refused
    naming it (that model no longer exists)."""
    out = {s: dict(v) if isinstance(v, dict) else v for s, v in data.items()}
    for name, value in RETIRED.items():
        s, k = name.split(".")
        sec = out.get(s)
        if isinstance(sec, dict) and k in sec and sec[k] == value:
            del sec[k]
    return out


def _pins(data: dict) -> dict:
    """The range keys that the layer ``data`` pins (:data:`RANDOMISED`)."""
    given = {f"{s}.{k}" for s, v in data.items() if isinstance(v, dict) for k in v}
    out: dict = {}
    for key, ranges in RANDOMISED.items():
        if key not in given or any(r in given for r in ranges):
            continue
        s, k = key.split(".")
        value = data[s][k]
        if key == "sim.initial_speed_mps":
            try:
                if float(value) <= 0.0:  # 0: the start speed scales with the wind (sim.initial_speed_per_wind)
                    continue
            except (TypeError, ValueError):
                continue  # (the value's own check names it)
            pinned = dict(zip(ranges, (value, value, 0.0, 0.0)))
        else:
            pinned = dict(zip(ranges, (value, value)))
        for r, v in pinned.items():
            rs, rk = r.split(".")
            out.setdefault(rs, {})[rk] = v
    return out


def config_from_dict(data: dict[str, Any] | None, base: Config | None = None) -> Config:
    """Build a validated Config from nested ``{section: {key: value}}`` on top of ``base`` (defaults if None); a
    randomised quantity given without its range pins the range (:data:`RANDOMISED`)."""
    base = base or Config()
    data = data or {}
    if not isinstance(data, dict):
        raise ConfigError(f"config must be a mapping of sections, got {type(data).__name__}")
    pins = _pins(data)
    if pins:
        data = {s: dict(v) if isinstance(v, dict) else v for s, v in data.items()}
        for s, values in pins.items():
            data.setdefault(s, {}).update(values)
    sections = {f.name: getattr(base, f.name) for f in fields(base)}
    for sec_name, values in data.items():
        if sec_name not in sections:
            raise ConfigError(f"unknown config section '{sec_name}' (valid: {', '.join(sections)})")
        if values is None:
            continue
        if not isinstance(values, dict):
            raise ConfigError(f"config section '{sec_name}' must be a mapping, got {values!r}")
        sec = sections[sec_name]
        valid = {f.name: f for f in fields(sec)}
        updates = {}
        for key, value in values.items():
            if f"{sec_name}.{key}" in RETIRED:
                name, now = f"{sec_name}.{key}", RETIRED[f"{sec_name}.{key}"]
                raise ConfigError(f"config key '{name}' is retired, always {str(now).lower()} now: "
                                  f"{RETIRED_NOW[name]}; remove it from the configuration")
            if key not in valid:
                raise ConfigError(f"unknown config key '{sec_name}.{key}' (valid: {', '.join(valid)})")
            updates[key] = _coerce(f"{sec_name}.{key}", value, getattr(sec, key),
                                   inf_ok=valid[key].metadata.get("inf_ok", False))
        try:
            sections[sec_name] = dataclasses.replace(sec, **updates)
        except ValueError as exc:  # sections that validate themselves (wind, trajectory)
            raise ConfigError(str(exc)) from None
    cfg = Config(**sections)
    _validate(cfg)
    return cfg


def _validate(cfg: Config) -> None:
    """Check every key against its :func:`key` metadata (:func:`check_key`), then the relations between keys."""
    for sec_f in fields(cfg):
        sec = getattr(cfg, sec_f.name)
        for f in fields(sec):
            if "doc" in f.metadata:  # wind, trajectory: checked by their own validate()
                check_key(f"{sec_f.name}.{f.name}", getattr(sec, f.name), f.metadata)
    if cfg.structure.dynamic and cfg.dynamics.wing_point_mass_share >= 1.0:
        raise ConfigError("structure.dynamic=true spreads 1 - dynamics.wing_point_mass_share of the wing mass over "
                          "its nodes: a share of 1 leaves the canopy's nodes massless (use < 1, or "
                          "structure.dynamic=false for the paper's point masses alone)")
    if cfg.structure.membrane_kinematics == "von_karman" and cfg.structure.membrane_forces == "energy_consistent":
        raise ConfigError("structure.membrane_forces=energy_consistent takes the Green-Lagrange membrane only "
                          "(structure.membrane_kinematics=green_lagrange)")
    if cfg.sim.initial_speed_mps <= 0.0 and cfg.sim.initial_speed_per_wind <= 0.0:
        raise ConfigError("config keys 'sim.initial_speed_mps' and 'sim.initial_speed_per_wind' are both 0: set the "
                          "start speed [m/s] or its multiple of wind.speed_mps")
    env = cfg.env
    for lo, hi in (("wind_speed_min_mps", "wind_speed_max_mps"), ("initial_speed_min_mps", "initial_speed_max_mps"),
                   ("turbulence_intensity_min", "turbulence_intensity_max"),
                   ("initial_speed_per_wind_min", "initial_speed_per_wind_max")):
        if getattr(env, lo) > getattr(env, hi):
            raise ConfigError(f"config key 'env.{lo}' must not exceed 'env.{hi}', got {getattr(env, lo)} > "
                              f"{getattr(env, hi)}")
    if (env.initial_speed_per_wind_min > 0.0) != (env.initial_speed_per_wind_max > 0.0):
        raise ConfigError("config keys 'env.initial_speed_per_wind_min' and '_max' must both be > 0 (the start speed "
                          "per m/s of wind) or both 0 (env.initial_speed_min_mps/_max_mps), got "
                          f"{env.initial_speed_per_wind_min} and {env.initial_speed_per_wind_max}")
    n_fast = cfg.control.control_dt_s / cfg.sim.surrogate_dt_s
    if abs(n_fast - round(n_fast)) > 1e-9 * n_fast or round(n_fast) < 1:
        raise ConfigError("config key 'sim.surrogate_dt_s' must divide control.control_dt_s "
                          f"({cfg.control.control_dt_s}) into a whole number of steps, got {cfg.sim.surrogate_dt_s}")
    if env.max_episode_s < cfg.control.control_dt_s:
        raise ConfigError(f"config key 'env.max_episode_s' must be at least control.control_dt_s, "
                          f"got {env.max_episode_s}")


def parse_overrides(overrides: Iterable[str]) -> dict[str, dict[str, Any]]:
    """``["fsi.tol_disp_m=1e-5", ...]`` -> nested dict; malformed entries raise ConfigError."""
    if isinstance(overrides, (str, bytes)) or not isinstance(overrides, Iterable) or isinstance(overrides, dict):
        raise ConfigError(f"overrides must be a list of 'section.key=value' strings, got {type(overrides).__name__} "
                          f"{overrides!r}" + (" (wrap a single override in a list)" if isinstance(overrides, str)
                                              else ""))
    out: dict[str, dict[str, Any]] = {}
    for item in overrides:
        if not isinstance(item, str):
            raise ConfigError(f"override {item!r} must be a string 'section.key=value'")
        if "=" not in item:
            raise ConfigError(f"override '{item}' must look like section.key=value")
        lhs, rhs = item.split("=", 1)
        parts = lhs.strip().split(".")
        if len(parts) != 2 or not all(parts):
            raise ConfigError(f"override '{item}' must look like section.key=value")
        out.setdefault(parts[0], {})[parts[1]] = _parse_scalar(rhs.strip())
    return out


def load_config(path: str | Path | None = None, overrides: Iterable[str] = ()) -> Config:
    """Load defaults, then the YAML file at ``path`` (if given), then ``section.key=value`` overrides."""
    cfg = Config()
    if path is not None:
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"config file '{p}' does not exist")
        try:
            data = yaml.safe_load(p.read_text())
        except yaml.YAMLError as exc:
            raise ConfigError(f"config file '{p}' is not valid YAML: {exc}") from None
        if isinstance(data, dict) and any(k == "default" or "-v" in str(k) for k in data):
            raise ConfigError(f"config file '{p}' is a training recipe (keys {', '.join(sorted(map(str, data)))}), not "
                              f"a physics config: give it to kite-train with --recipe")
        cfg = config_from_dict(data, cfg)
    return config_from_dict(parse_overrides(overrides), cfg)


# ---------------------------------------------------------------------------------------------------- model identity
#: the sections that define the flying model: geometry, structure, aerodynamics, particle system and ground station,
#: controllers and actuator. ``fsi`` (solver tolerances), ``sim`` (run length, fidelity), ``wind``, ``trajectory``
#: and ``env`` (the task) are not the model: a reduced-order wing or an agent made on one model is used with any of
#: them.
MODEL_SECTIONS = ("kite", "structure", "aero", "dynamics", "control")

#: named models: each pins the model sections it changes from the defaults (dm_control's named constructors;
#: ``configs/<name>.yaml`` holds the same values for the command line). ``default``: the flying model.
#: ``paper``: every choice Bosch et al. state that the 60 s baseline flies with (configs/paper.yaml says which).
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "default": {},
    "paper": {
        "structure": {"dynamic": False, "membrane_kinematics": "von_karman"},
        "aero": {"moment_chord_power": 1.0, "canopy_luffing": False, "negative_alpha": "breukels"},
        "dynamics": {"tether": "rod", "winch": "fixed"},
        "control": {"k3i_per_s": 0.0, "line_speed_max_mps": 0.0},
    },
}


class ModelMismatch(ConfigError):
    """An artefact (reduced-order wing, start table, agent) made with another model than the one asked for."""


def model_keys(cfg: Config) -> dict[str, Any]:
    """Every key of :data:`MODEL_SECTIONS` as ``{"section.key": value}``."""
    d = cfg.to_dict()
    return {f"{s}.{k}": v for s in MODEL_SECTIONS for k, v in d[s].items()}


def preset_config(name: str) -> Config:
    """The configuration of the named model (:data:`PRESETS`)."""
    if name not in PRESETS:
        raise ConfigError(f"unknown model preset {name!r} (valid: {', '.join(PRESETS)})")
    return config_from_dict(PRESETS[name], Config())


def preset_name(cfg: Config) -> str:
    """The name of the preset whose model ``cfg`` is, or ``custom``."""
    keys = model_keys(cfg)
    for name in PRESETS:
        if model_keys(preset_config(name)) == keys:
            return name
    return "custom"


def fingerprint(cfg: Config) -> dict[str, Any]:
    """The model ``cfg`` flies: ``{"preset", "fingerprint", "keys"}``, the fingerprint the first 16 hex digits of the
    SHA-256 of the model keys (:func:`model_keys`, with the retired ones at their one value, :data:`RETIRED`) as
    sorted JSON. Stored with every artefact made from a model."""
    import hashlib
    import json

    keys = model_keys(cfg) | _retired_model_keys()
    digest = hashlib.sha256(json.dumps(keys, sort_keys=True, default=repr).encode()).hexdigest()[:16]
    return {"preset": preset_name(cfg), "fingerprint": digest, "keys": keys}


def check_model(record: dict | None, cfg: Config, what: str) -> None:
    """Raise :class:`ModelMismatch` naming the keys that differ when ``record`` (a :func:`fingerprint` stored with
    ``what``) is not the model of ``cfg``; a record without one is refused too (made before models were recorded).
    A retired key (:data:`RETIRED`) is compared with its one value: a record made at another value is refused."""
    if not record or "keys" not in record:
        raise ModelMismatch(f"{what} records no model (made before models were recorded); make it again for this "
                            f"model")
    now = model_keys(cfg) | _retired_model_keys()
    old = record["keys"]
    diff = sorted(k for k in set(now) | set(old) if now.get(k, "<absent>") != old.get(k, "<absent>"))
    if diff:
        shown = ", ".join(f"{k} ({old.get(k, '<absent>')!r} there, {now.get(k, '<absent>')!r} here)"
                          for k in diff[:8])
        more = f" and {len(diff) - 8} more" if len(diff) > 8 else ""
        raise ModelMismatch(f"{what} was made with model '{record.get('preset', '?')}' ({record.get('fingerprint')}), "
                            f"not this one '{preset_name(cfg)}': {len(diff)} key(s) differ: {shown}{more}")
