"""Configuration: frozen dataclasses grouped by subsystem, loaded from YAML with ``section.key=value`` overrides.

Every value carries its unit in its name (``_m``, ``_Pa``, ``_deg`` ...) or in its comment. The defaults here are
the single source of truth; ``configs/default.yaml`` lists them for reading and is checked against them in the tests.

Errors: an unknown section or key, a value of the wrong type, or a physically invalid value (negative stiffness,
pressure, ...) raises :class:`ConfigError` with one message that names the offending key.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from kite_env.trajectory import TrajectoryConfig
from kite_env.wind import WindConfig


class ConfigError(ValueError):
    """Invalid configuration: the message names the key and what is wrong with it."""


@dataclass(frozen=True)
class KiteConfig:
    name: str = "rhino16"  # kite geometry: rhino16 | v3
    n_sections: int = 37  # spanwise sections (odd) [-]
    n_chord: int = 6  # chordwise load points per section [-]


@dataclass(frozen=True)
class StructureConfig:
    # canopy: isotropic linear ripstop (paper, Sect. II.A)
    canopy_E_Pa: float = 1.25e9  # Young's modulus [Pa]
    canopy_nu: float = 0.3  # Poisson ratio [-]
    canopy_thickness_m: float = 0.08e-3  # [m]
    wrinkling: bool = True  # tension-field membrane (no compressive membrane stress)
    # in-plane shear modulus of the canopy fabric as a fraction of the isotropic E / (2 (1 + nu)): 1 = the paper's
    # isotropic law; below 1 a balanced woven fabric with its threads along the chord (x of frame K) and span
    # (kite_env.structure.shell_membrane.fabric_matrix, relaxed_general; docs/steering.md, "Where a steering input
    # goes") [-]
    canopy_shear_ratio: float = 1.0
    # the canopy membrane's strain: "green_lagrange" (exact for any rotation) or "von_karman", the paper's (Sect.
    # II.A: "von Karman kinematic description"), whose tensioned canopy has no geometric stiffness against in-plane
    # motion and which strains an element turned in its plane by theta by cos(theta) - 1
    # (kite_env.structure.shell_membrane; docs/steering.md, "The von Karman membrane")
    membrane_kinematics: str = "green_lagrange"
    # inflated tubes (LE, struts): Breukels' correlations (Breukels 2011); 0.3 bar = the V3's flight pressure in
    # awegroup/kite_fem and kitesim
    tube_pressure_Pa: float = 0.3e5  # gauge pressure [Pa]
    # Axial stiffness of a tube wall, EA = pi d (E t)_fabric. No measured Dacron data is public:
    # modelling choice of twice the canopy's membrane stiffness E h = 1e5 N/m (tube fabric is a heavier cloth).
    tube_wall_Et_N_per_m: float = 2.0e5  # [N/m]
    # curvature of a tube element that Breukels' secant law is evaluated at: "element_energy" = the element's
    # root-mean-square curvature (the law is then the gradient of a stored energy, with an exact tangent;
    # kite_env.structure.tube.element_curvature); "max_end" = the larger end curvature (the former default: not the
    # gradient of an energy, not conservative, its tangent 4 % off, and it over-softens an S-bent element: the
    # folding struts of the high-wind random episodes; docs/model.md, "Energy", "The conservative tube law")
    tube_curvature: str = "element_energy"
    # fold contact of a kinked tube (kite_env.structure.tube.fold_contact, with element_energy only): from this fold
    # angle of an element (rms curvature times length) its legs press on each other and the fold closes at 180 deg
    # instead of passing it (Breukels' collapsed tube is a hinge of no stiffness; the co-rotational element cannot
    # represent a fold of 180 deg: docs/model.md, "Section frame, fold contact, rotary inertia"); 0 = none [deg]
    tube_fold_onset_deg: float = 90.0
    # tip beams ("thin stiff beam", Sect. II.A): a solid glass-fibre rod (modelling choice), diameter from the mesh
    tip_rod_E_Pa: float = 30.0e9  # [Pa]
    # trailing-edge wire: Dyneema line, effective modulus of the kite_fem/kitesim bridle models (awegroup/kite_fem,
    # awegroup/ASKITE)
    te_wire_E_Pa: float = 5.5e8  # [Pa]
    te_hem_EI_Nm2: float = 0.4  # bending stiffness of the trailing-edge hem (wire + seam tape), both axes [N m^2]
    # the trailing-edge hem's element: "rod" = a frame-free rod with the beam's axial, bending and (bounded)
    # torsional stiffness (kite_env.structure.hem); "beam" = the co-rotational beam of the tubes (the former default),
    # whose element frame and rotation logarithm are singular when a slack canopy turns its trailing-edge nodes by
    # 90-180 deg against the hem: its energy jumps there, and the nodes' rotations spin up
    # (docs/model.md, "The trailing-edge hem")
    te_hem_element: str = "rod"
    # the wing with inertia (dynamics/wing_dynamics.py): nodal masses (Table 1's 10 kg, 70 % on the LE tube) and
    # the canopy's added mass, generalized-alpha in time, A-D wing nodes held by the bridle lines (docs/model.md,
    # "The wing with inertia"; its verification: docs/validation.md, "Time-step convergence", "Against the static
    # wing"); false = the paper's quasi-static wing on the particles A-D
    dynamic: bool = True
    rho_inf: float = 0.8  # generalized-alpha spectral radius at infinite frequency (1 = no numerical damping) [-]
    # added mass normal to the canopy: this factor times rho pi c^2 / 4 per unit span with Lissaman & Brown's
    # k_C = AR / (1 + AR) (AIAA-93-1236); 0 = none [-]
    added_mass_factor: float = 1.0
    # rotary inertia of the wing's nodes (dynamic wing): this factor times the second moment of each node's
    # tributary rectangle (chordwise a, spanwise b) about the node, J = m (a^2 + b^2) / 24, the mean of its two
    # in-plane axes (lumped rotary inertia as in the HRZ lumping of Hinton, Rock & Zienkiewicz 1976, which gives a
    # uniform beam's node m l^2 / 39); 0 = massless, quasi-static rotations (a slack canopy's
    # trailing-edge rotations then have nothing to hold them, docs/model.md, "Section frame, fold contact, rotary
    # inertia") [-]
    rotary_inertia_factor: float = 1.0
    # structural damping of the wing with inertia: stiffness-proportional (Rayleigh) C = beta K_T on the nodal
    # translations, beta = 2 zeta / omega_ref: 2 % of critical (the level of the paper's relative damping
    # coefficients of the wing, Table 1: 0.015-0.02) at 4 Hz, the wing's lowest elastic mode in flight (its
    # yaw/twist mode on the lines, 3.6-3.9 Hz), and more at every higher one (6.4e-4 s, 2 % at 10 Hz,
    # gives 0.8 % at that mode; docs/model.md, "Structural damping"); 0 = none [s]
    rayleigh_beta_s: float = 1.6e-3
    # the tangent K_T of that damping is refreshed when it is this old (time from the step end where it was
    # assembled to the current step's end) and held, turned with the step's frame, in between: the damping matrix
    # of the wing's shape at most this long ago. 0 = every step. Assembling the full tangent at each
    # step's Newton start cost 0.4 ms of a 5.5 ms step (docs/performance.md, "The damping tangent held over 20 ms") [s]
    rayleigh_tangent_period_s: float = 0.02
    # the canopy's membrane forces in a time step of the wing with inertia: "energy_consistent" = the discrete
    # gradient of the stored energy between the step's ends (Gonzalez 2000), whose work is the energy change at the
    # wrinkling law's kinks; "averaged" = generalized-alpha's averaged end forces (default), which pump energy
    # into the canopy's fast membrane modes (a free wing gained 75 % of its kinetic energy in 0.3 s)
    membrane_forces: str = "averaged"
    # the wing with inertia: the force residual that a step's Newton leaves (below fsi.tol_force_rel of the load) is
    # added to the next step's load, so that its impulse is delivered one step late instead of lost (the unbalanced
    # force correction). Dropped ("none"), every step's residual is a small force on the wing that
    # the flight integrates: the KCU lay 9.7 cm from the tightly converged flight after 10 s at 5 ms, 15 cm at
    # 2.5 ms. "sections": the residual's resultant force and moments on each chordwise section, spread over its
    # nodes like a rigid section's inertial load (1.4 cm, and Newton 1.59 instead of 1.68 iterations per step);
    # "full": all of it (0.1 cm; 1.78 iterations: the part within a section is what a kept factorisation contracts
    # worst) (docs/performance.md, "The carried residual")
    carry_residual: str = "sections"
    # the added mass's force: "normal_velocity_rate" (default) = Theodorsen's non-circulatory load
    # (NACA Report 496): the mass blocks M_a a plus -m_a (n' . v_rel) n at the 3/4-chord point, so that a steady turn
    # leaves only the pitch-damping couple; "nodal_acceleration" = M_a a alone, which in
    # a steady turn pulls each section with its added mass times the turn's centripetal acceleration, as if the air
    # turned with the wing. The normal-rate part feeds the wing's 3.9 Hz yaw/twist mode at a lower structural
    # damping (docs/steering.md, "The yaw rig"; docs/model.md, "Structural damping"); with the damping at the wing's
    # lowest mode, the hem's frame-free rods and the force's Newton tangent (docs/model.md, "Theodorsen's force") it
    # flies every flight M_a a flies
    added_mass_force: str = "normal_velocity_rate"


@dataclass(frozen=True)
class AeroConfig:
    rho_kg_m3: float = 1.225  # air density, sea level, 15 deg C (ISA) [kg/m^3]
    # Eq. (9) M = 1/2 rho CM c^p w V^2: p = 2 dimensionally consistent (default); 1 = as printed in the paper
    moment_chord_power: float = 2.0  # [-]
    # luffing canopy: a membrane cannot carry a reversed pressure, so as a section's CL falls to 0 its load moves from
    # the canopy nodes to the LE (tube) and TE (wire) nodes (aero.loads.LUFFING_BAND_CL); false = the paper
    canopy_luffing: bool = True
    # point / chord (from the airfoil nose) that Breukels' regression CM is taken about: 0 = the nose (gives the paper's
    # 7.5 deg mid-wing alpha, docs/model.md, "Trim: the point Breukels' C_M is taken about"); 0.25 = the quarter chord,
    # the open VSM codes' assumption
    cm_regression_ref_over_c: float = 0.0  # [-]
    # damping of the wing's deformation velocity: "consistent" = each section's quasi-steady force response to its
    # own translation velocity, spread over its nodes (symmetric part positive semi-definite; fsi.SectionDamping);
    # "eq3" = Eq. (3) as printed (mean LE/TE finite-difference velocity in the inflow): indefinite, unstable
    damping: str = "consistent"
    # point of each section where the frame's rotation omega x r enters the inflow (Eq. 2): "le_node" = the paper's
    # LE node; "three_quarter_chord" = the 3/4-chord point (Pistolesi's rotation-rate collocation point)
    rotation_point: str = "three_quarter_chord"
    # 3-D induced drag, C_D += C_L^2 / (pi e AR) per section (aero.loads.section_loads; e from Raymer's estimate at the
    # wing's projected aspect ratio); false = the paper's 2-D sections, which it names as why its L/D exceeds ~6
    induced_drag: bool = False
    # section coefficients below zero lift: "bounded" by V3 2-D CFD data (aero/breukels.py), or "breukels" (the
    # regression as is, 4-5 times the measured negative lift)
    negative_alpha: str = "bounded"


@dataclass(frozen=True)
class FsiConfig:
    tol_disp_m: float = 1.0e-4  # coupling: max nodal position change between coupling iterations [m]
    tol_force_rel: float = 1.0e-3  # coupling: change of aero load vector relative to its norm [-]
    # a monolithic Newton solve that stalls (chattering between taut and slack canopy states) is accepted at its best
    # iterate when the force residual is below this fraction of the load, and flagged (WingSolution.accepted)
    accept_force_rel: float = 1.0e-2  # [-]
    max_coupling_iter: int = 200  # [-]
    newton_per_coupling: int = 4  # Newton iterations between two aero load updates [-]
    max_bridle_step_m: float = 0.02  # larger bridle-point moves are applied in converged sub-steps [m]
    cold_load_steps: int = 6  # dynamic-pressure ramp for a cold start from the unloaded wing [-]
    relax_initial: float = 0.3  # first under-relaxation factor of the aero loads (Aitken thereafter) [-]
    relax_min: float = 0.02  # lower bound of the Aitken relaxation factor [-]
    max_newton_iter: int = 30  # monolithic Newton iterations per solve [-]
    max_retries: int = 3  # retries of a failed solve: fresh start, damped Newton, then finer bridle sub-steps [-]
    extrapolate: bool = True  # warm time steps start from the linear extrapolation of the last two steps


@dataclass(frozen=True)
class DynamicsConfig:
    # particle-system model of wing masses, bridle, KCU and tether (paper Sect. II.C, Fig. 5, Table 1)
    mass_le_kg: float = 3.5  # m_A = m_C, 70 % of the wing mass at the leading edge (Table 1) [kg]
    mass_te_kg: float = 1.5  # m_B = m_D (Table 1) [kg]
    mass_kcu_kg: float = 3.0  # m_KCU (Table 1) [kg]
    beta_ac: float = 0.02  # relative damping A-C (Table 1), fraction of critical [-]
    beta_bd: float = 0.002  # relative damping B-D (Table 1) [-]
    beta_diag: float = 0.015  # relative damping A-D and B-C (Table 1) [-]
    line_diameter_m: float = 0.0012  # bridle-line diameter d_c (Table 1) [m]
    # cylinder drag coefficient of a line in cross flow (awegroup/ASKITE, kitesim's bridle-line drag) [-]
    line_cd: float = 1.1
    line_stiffness_N_per_m: float = 4.52e3  # k_c (Table 1) [N/m]
    line_damping_Ns_per_m: float = 251.7  # c_c (Table 1) [N s/m]
    power_line_length_m: float = 25.0  # rest lengths L_A = L_C (Table 1) [m]
    tether_length_m: float = 80.0  # l_t = |r_KCU| (Table 1) [m]
    tether_diameter_m: float = 0.0  # tether drag (not in the paper's model: 0 = off) [m]
    gravity_mps2: float = 9.81  # [m/s^2]
    dt_s: float = 0.005  # fixed RK4 time step (the paper's adaptive RK45 averaged 5.3 ms) [s]
    baumgarte_1_per_s: float = 20.0  # constraint stabilisation rate of the tether and tip constraints [1/s]
    # ground station (FlightSimulator, docs/model.md, "The ground station"): "fixed" = the paper's constant tether
    # length (Table 1); "force" = a winch with an upper force limit: it holds the tether at its length while the
    # tether force stays below winch_force_N and reels out above it (traction phase; no reel-in), the reel-out speed
    # following (F_t - winch_force_N) / winch_damping_Ns_per_m within [0, winch_speed_max_mps] with the time constant
    # winch_time_constant_s (after the winch models of Fechner et al. 2015, Renewable Energy 83, 705, and the
    # force-limited reel-out of van der Vlugt et al. 2019, Renewable Energy 131, 83). The default: the
    # paper's force controller (Eq. 18-19), meant "to keep the tension in the tether between a minimum and maximum
    # value" (Sect. II.D), cannot depower this four-point wing, and the paper names the real system's force control
    # as the ground station's (Sect. III); below the set force the flight is the paper's constant tether.
    winch: str = "force"
    winch_force_N: float = 15000.0  # upper tether force limit of the ground station [N] (a set point)
    winch_damping_Ns_per_m: float = 1000.0  # tether force rise per m/s of reel-out speed [N s/m]
    winch_speed_max_mps: float = 10.0  # [m/s]
    winch_time_constant_s: float = 0.5  # lag of the reel-out speed behind its set value [s]
    # a step whose wing solve fails is split in halves, down to dt / 2**max_substep_halvings (FlightSimulator.step)
    max_substep_halvings: int = 4  # [-]
    # tether between ground station and KCU: "rod" = the paper's bilateral constraint |r_KCU| = l_t (Eq. 12-13; a
    # tether that would have to push ends the flight as "slack tether"); "rope" = a unilateral constraint that only
    # pulls: the KCU flies free inside the sphere when the tether would go slack, and its outward radial velocity
    # is removed (an inelastic jerk) when it reaches the sphere again (dynamics/dynamic_simulator.py). The wing with
    # inertia's tether (default: a tether cannot push, and with the rod random steering ended every
    # episode within 0.4 s, docs/environment.md, "Random steering"); the quasi-static wing (structure.dynamic = false)
    # always flies the paper's rod: a slack tether unloads the bridle, which that wing cannot follow
    tether: str = "rope"
    coupling: str = "explicit"  # wing force over a step: explicit (held + condensed stiffness) | predictor_corrector
    # share of Table 1's wing mass kept as the paper's four point masses at A-D; the rest is spread over the FE nodes
    # (70 % on the LE tube) and condensed onto A-D with the wing's static modes (dynamics/wing_mass.py). 1 = the
    # paper. 0.6 is the smallest share for which the explicit RK4 step with the bridle-line dampers is stable up to
    # dt = 10 ms (end masses m_B = m_D >= c_c dt / 2.78 = 0.9 kg; the condensed modes alone put 0.04 kg there)
    wing_point_mass_share: float = 0.6  # [-]


@dataclass(frozen=True)
class ControlConfig:
    # the paper's steering (Eq. 14-17) and force (Eq. 18-19) controllers; gains not given in the paper
    # gains chosen for this model's steering authority (docs/model.md, "Controller gains and the force loop"): the
    # paper gives none
    k1_m_per_rad: float = 1.0  # heading error -> desired steering-line difference, Eq. (15) [m/rad]
    k2: float = 3.0  # steering-line length loops, Eq. (16-17) [-]
    k3_m: float = 0.5  # force-ratio loop, Eq. (19) [m]
    k3i_per_s: float = 2.0  # integral gain of the force-ratio loop (kite_env.control; 0 = the paper's Eq. 19) [m/s]
    force_integral_max_m: float = 1.0  # anti-windup: |K3i I| at most this [m]
    mu_target: float = 0.3  # desired force ratio mu* (Sect. III.B) [-]
    delta_l_max_m: float = 1.5  # limit of the desired steering-line difference |dl*| [m]
    beta_distance_deg: float = 4.0  # blending: beta = 1/2 at this distance to the path (on the unit sphere) [deg]
    beta_min: float = 0.2  # blending: smallest weight of the path tangent [-]
    control_dt_s: float = 0.02  # controller update period [s]
    # speed limit of the KCU's steering-line actuator, per controller period at most this times control_dt_s on
    # each axis of actuator_axes (kite_env.control.actuate); 0 = none, the paper's Eq. 16-17. 2 m/s (the default
    # with the wing with inertia: a held full input otherwise moves the lines by metres in one
    # controller period) is above all the baseline asks after its first 0.1 s (1.45 m/s); a real KCU is slower
    # (docs/model.md, "Large steering inputs") [m/s]
    line_speed_max_mps: float = 2.0
    # how that limit acts: "steer_depower" = as the KCU's two motors, a steering motor for the difference and a
    # depower motor for the common change of both lines (van der Vlugt et al., "Design and experimental
    # characterization of a pumping kite power system", in Airborne Wind Energy, Springer 2013, ch. 23; Fechner et
    # al., Renewable Energy 83, 705, 2015): half the difference (L_B - L_D)/2 and the mean (L_B + L_D)/2 each move
    # at most line_speed_max_mps; "per_line" = each rest length on its own (a saturated steering
    # command then leaves the force loop no speed at all, docs/environment.md, "The KCU's two motors")
    actuator_axes: str = "steer_depower"


@dataclass(frozen=True)
class SimConfig:
    duration_s: float = 60.0  # simulated time [s]
    warmup_s: float = 3.0  # initial transient excluded from the metrics [s]
    # initial flight speed along the path: > 0 this speed [m/s]; 0 = initial_speed_per_wind times wind.speed_mps
    initial_speed_mps: float = 0.0
    # the initial speed as a multiple of wind.speed_mps where initial_speed_mps is 0: a kite's crosswind speed grows
    # in proportion to the wind (Loyd 1980, J. Energy 4(3), 106); 4.4 gives the paper's 22 m/s at its 5 m/s. From
    # 22 m/s at 10 m/s the wing starts at half its flight speed and folds in the acceleration
    # (docs/environment.md, "Starts") [-]
    initial_speed_per_wind: float = 4.4
    # wing model: fe (the aeroelastic FE wing) | surrogate (the reduced-order wing, kite_env.surrogate)
    fidelity: str = "fe"
    surrogate_path: str = ""  # surrogate weights (.npz); empty: the model shipped for kite.name
    surrogate_start: str = "table"  # surrogate: the start from the start table (fitted to FE starts), else solved |
    #   fe (solved) | table_only (a start the table lacks fails, so that the env redraws it: training)
    # surrogate: the RK4 step of the reduced-order wing's particle system [s]; a whole number of them makes one control
    # period. 10 ms flies the agreement flights within 0.1 % of the 5 ms step's traction at 5-10 m/s (1.6 % at 4 m/s)
    # at half the cost; 20 ms leaves the fitted envelope within 10 s (docs/fast_fidelity.md, "Time step")
    surrogate_dt_s: float = 0.01


#: wing models of the flight simulation (sim.fidelity)
FIDELITIES = ("fe", "surrogate")
#: aero.damping choices (fsi.SectionDamping; "eq3" is the paper's Eq. 3 as printed)
AERO_DAMPING = ("consistent", "eq3")
#: aero.rotation_point choices (aero.sections.apparent_wind): the paper's LE node, or the 3/4-chord point
ROTATION_POINTS = ("le_node", "three_quarter_chord")

#: observation terms of the Gymnasium environment (kite_env.envs), in the order they are stacked
OBSERVATION_TERMS = ("position", "heading", "line_forces", "path", "rates", "actuator")


@dataclass(frozen=True)
class EnvConfig:
    # Gymnasium environment (kite_env.envs): episode, observation, reward and randomisation of the start
    max_episode_s: float = 60.0  # simulated time limit of an episode (truncation) [s]
    force_controller: bool = True  # the paper's force controller (Eq. 18-19) runs inside the env
    observation: str = "position,heading,line_forces,path,rates,actuator"  # terms, comma-separated (OBSERVATION_TERMS)
    force_scale_N: float = 5000.0  # line and tether forces are observed divided by this [N]
    w_tracking: float = 1.0  # weight of the tracking reward exp(-(delta / tracking_scale)^2) per step [-]
    tracking_scale_deg: float = 5.0  # distance to the figure-eight at which the tracking reward is 1/e [deg]
    w_traction: float = 0.5  # weight of the traction reward F_tether / traction_ref per step [-]
    traction_ref_N: float = 5000.0  # [N]
    w_action_rate: float = 0.1  # weight of the penalty (a_k - a_k-1)^2 per step [-]
    crash_penalty: float = 50.0  # reward -crash_penalty on a physical failure (terminated) [-]
    slack_tether_N: float = 50.0  # a tether force below this ends the episode (slack tether) [N]
    wind_speed_min_mps: float = 5.0  # wind speed drawn uniformly per episode from [min, max] [m/s]
    wind_speed_max_mps: float = 5.0  # [m/s]
    turbulence_intensity_min: float = 0.0  # turbulence intensity drawn uniformly from [min, max] per episode [-]
    turbulence_intensity_max: float = 0.0  # [-]
    random_start: bool = False  # start at a random point of the figure-eight (else at the crossing, like kite-eval)
    # random starts only where the path's geodesic curvature |kappa_g| [1/rad] is at most this (the straight
    # segments through the crossing): the start has neutral steering and no turn rate, and from there a start in a
    # turn fails in the full model within ~0.2 s (the controller's steering step on the untwisted wing)
    start_curvature_max: float = float("inf")
    initial_speed_min_mps: float = 22.0  # initial speed along the path drawn from [min, max] [m/s]
    initial_speed_max_mps: float = 22.0  # [m/s]
    # > 0 (both): the initial speed is drawn from [min, max] times the drawn wind speed instead [-] (the crosswind
    # speed of a kite grows with the wind, ~ L/D times it: 4.4 gives the 22 m/s at 5 m/s of the fixed start and
    # keeps a start at 10 m/s from beginning at half its flight speed, a wing that does not converge at the start)
    initial_speed_per_wind_min: float = 0.0
    initial_speed_per_wind_max: float = 0.0
    reset_attempts: int = 5  # draws of the start before reset() gives up (the wing must converge at the start) [-]
    # false: no draws at all, the wind section as configured (turbulence realisation wind.seed unless reset() gets
    # options={"wind_seed": n}) and the start at the crossing at sim.initial_speed_mps (kite-eval's conditions)
    randomize: bool = True


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


# values that must be strictly positive (everything else numeric must be finite)
_POSITIVE = {
    "kite.n_sections", "kite.n_chord", "structure.canopy_E_Pa", "structure.canopy_thickness_m",
    "structure.tube_pressure_Pa", "structure.tube_wall_Et_N_per_m", "structure.tip_rod_E_Pa", "structure.te_wire_E_Pa",
    "structure.te_hem_EI_Nm2",
    "aero.rho_kg_m3", "fsi.tol_disp_m", "fsi.tol_force_rel", "fsi.max_coupling_iter", "fsi.cold_load_steps",
    "fsi.relax_initial", "fsi.relax_min", "fsi.newton_per_coupling", "fsi.max_bridle_step_m", "fsi.max_newton_iter",
    "fsi.accept_force_rel",
    "dynamics.mass_le_kg", "dynamics.mass_te_kg", "dynamics.mass_kcu_kg", "dynamics.line_diameter_m",
    "dynamics.line_stiffness_N_per_m", "dynamics.power_line_length_m", "dynamics.tether_length_m", "dynamics.dt_s",
    "dynamics.baumgarte_1_per_s", "dynamics.winch_force_N", "dynamics.winch_damping_Ns_per_m",
    "dynamics.winch_speed_max_mps", "dynamics.winch_time_constant_s", "control.k2", "control.delta_l_max_m",
    "control.beta_distance_deg",
    "control.control_dt_s", "sim.surrogate_dt_s", "sim.duration_s", "env.max_episode_s", "env.force_scale_N",
    "env.tracking_scale_deg", "env.traction_ref_N", "env.initial_speed_min_mps", "env.initial_speed_max_mps",
    "env.reset_attempts", "env.start_curvature_max",
}
# bounds that may be .inf (no bound)
_UNBOUNDED_OK = {"env.start_curvature_max"}
# values that must be >= 0
_NON_NEGATIVE = {
    "structure.added_mass_factor", "structure.rayleigh_beta_s", "structure.rayleigh_tangent_period_s",
    "sim.initial_speed_per_wind", "sim.initial_speed_mps",
    "structure.rotary_inertia_factor",
    "env.initial_speed_per_wind_min", "env.initial_speed_per_wind_max",
    "fsi.max_retries", "dynamics.max_substep_halvings", "dynamics.beta_ac", "dynamics.beta_bd", "dynamics.beta_diag",
    "dynamics.line_cd",
    "dynamics.line_damping_Ns_per_m", "dynamics.tether_diameter_m", "dynamics.gravity_mps2", "control.k1_m_per_rad",
    "control.k3_m", "control.k3i_per_s", "control.force_integral_max_m", "control.line_speed_max_mps",
    "control.mu_target", "control.beta_min", "sim.warmup_s", "env.w_tracking",
    "env.w_traction", "env.w_action_rate", "env.crash_penalty", "env.slack_tether_N", "env.wind_speed_min_mps",
    "env.wind_speed_max_mps", "env.turbulence_intensity_min", "env.turbulence_intensity_max",
}


# keys that name one of a few models or modes, with their allowed values
_CHOICES = {
    "aero.damping": tuple(AERO_DAMPING),
    "control.actuator_axes": ("steer_depower", "per_line"),
    "structure.membrane_forces": ("energy_consistent", "averaged"),
    "structure.carry_residual": ("sections", "full", "none"),
    "structure.added_mass_force": ("nodal_acceleration", "normal_velocity_rate"),
    "structure.te_hem_element": ("beam", "rod"),
    "structure.membrane_kinematics": ("green_lagrange", "von_karman"),
    "structure.tube_curvature": ("element_energy", "max_end"),
    "aero.negative_alpha": ("bounded", "breukels"),
    "aero.rotation_point": tuple(ROTATION_POINTS),
    "sim.fidelity": tuple(FIDELITIES),
    "sim.surrogate_start": ("table", "fe", "table_only"),
    "dynamics.winch": ("fixed", "force"),
    "dynamics.tether": ("rod", "rope"),
}

def _coerce(key: str, value: Any, default: Any) -> Any:
    """Convert ``value`` to the type of ``default`` or raise a ConfigError naming ``key``."""
    typ = type(default)
    if typ is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "yes", "no"):
            return value.lower() in ("true", "1", "yes")
        raise ConfigError(f"config key '{key}' expects true/false, got {value!r}")
    if typ is int:
        if isinstance(value, bool):
            raise ConfigError(f"config key '{key}' expects an integer, got {value!r}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"config key '{key}' expects an integer, got {value!r}") from None
        if not f.is_integer():
            raise ConfigError(f"config key '{key}' expects an integer, got {value!r}")
        return int(f)
    if typ is float:
        if isinstance(value, bool):
            raise ConfigError(f"config key '{key}' expects a number, got {value!r}")
        try:
            f = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"config key '{key}' expects a number, got {value!r}") from None
        if not math.isfinite(f) and not (key in _UNBOUNDED_OK and f == math.inf):
            raise ConfigError(f"config key '{key}' must be finite, got {value!r}")
        return f
    if typ is str:
        if not isinstance(value, str):
            raise ConfigError(f"config key '{key}' expects a string, got {value!r}")
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
            if key not in valid:
                raise ConfigError(f"unknown config key '{sec_name}.{key}' (valid: {', '.join(valid)})")
            updates[key] = _coerce(f"{sec_name}.{key}", value, getattr(sec, key))
        try:
            sections[sec_name] = dataclasses.replace(sec, **updates)
        except ValueError as exc:  # sections that validate themselves (wind, trajectory)
            raise ConfigError(str(exc)) from None
    cfg = Config(**sections)
    _validate(cfg)
    return cfg


def _validate(cfg: Config) -> None:
    for sec_f in fields(cfg):
        sec = getattr(cfg, sec_f.name)
        for f in fields(sec):
            key = f"{sec_f.name}.{f.name}"
            v = getattr(sec, f.name)
            if key in _POSITIVE and not v > 0:
                raise ConfigError(f"config key '{key}' must be positive, got {v!r}")
            if key in _NON_NEGATIVE and not v >= 0:
                raise ConfigError(f"config key '{key}' must be >= 0, got {v!r}")
    if cfg.aero.moment_chord_power not in (1.0, 2.0):
        raise ConfigError(f"config key 'aero.moment_chord_power' must be 1 or 2, got {cfg.aero.moment_chord_power}")
    if not 0.0 <= cfg.aero.cm_regression_ref_over_c <= 1.0:
        raise ConfigError("config key 'aero.cm_regression_ref_over_c' must lie in [0, 1], "
                          f"got {cfg.aero.cm_regression_ref_over_c}")
    for key, choices in _CHOICES.items():
        section, name = key.split(".")
        v = getattr(getattr(cfg, section), name)
        if v not in choices:
            names = [repr(c) for c in choices]
            allowed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"
            raise ConfigError(f"config key '{key}' must be {allowed}, got {v!r}")
    if cfg.dynamics.coupling not in ("explicit", "predictor_corrector"):
        raise ConfigError("config key 'dynamics.coupling' must be 'explicit' or 'predictor_corrector', "
                          f"got {cfg.dynamics.coupling!r}")
    if not 0.0 <= cfg.dynamics.wing_point_mass_share <= 1.0:
        raise ConfigError("config key 'dynamics.wing_point_mass_share' must lie in [0, 1], "
                          f"got {cfg.dynamics.wing_point_mass_share}")
    if cfg.control.beta_min > 1.0:
        raise ConfigError(f"config key 'control.beta_min' must lie in [0, 1], got {cfg.control.beta_min}")
    if not 0.0 <= cfg.structure.tube_fold_onset_deg < 180.0:
        raise ConfigError("config key 'structure.tube_fold_onset_deg' must lie in [0, 180) (0: no fold contact), "
                          f"got {cfg.structure.tube_fold_onset_deg}")
    if cfg.structure.dynamic and cfg.dynamics.wing_point_mass_share >= 1.0:
        raise ConfigError("structure.dynamic=true spreads 1 - dynamics.wing_point_mass_share of the wing mass over "
                          "its nodes: a share of 1 leaves the canopy's nodes massless (use < 1, or "
                          "structure.dynamic=false for the paper's point masses alone)")
    if not 0.0 <= cfg.structure.rho_inf <= 1.0:
        raise ConfigError(f"config key 'structure.rho_inf' must lie in [0, 1], got {cfg.structure.rho_inf}")
    if not 0.0 < cfg.structure.canopy_shear_ratio <= 1.0:
        raise ConfigError("config key 'structure.canopy_shear_ratio' must lie in (0, 1] (1: the isotropic canopy), "
                          f"got {cfg.structure.canopy_shear_ratio}")
    if cfg.structure.membrane_kinematics == "von_karman" and cfg.structure.membrane_forces == "energy_consistent":
        raise ConfigError("structure.membrane_forces=energy_consistent takes the Green-Lagrange membrane only "
                          "(structure.membrane_kinematics=green_lagrange)")
    if not -1.0 < cfg.structure.canopy_nu < 0.5:
        raise ConfigError(f"config key 'structure.canopy_nu' must lie in (-1, 0.5), got {cfg.structure.canopy_nu}")
    if cfg.kite.n_sections % 2 == 0 or cfg.kite.n_sections < 7:
        raise ConfigError(f"config key 'kite.n_sections' must be odd and >= 7, got {cfg.kite.n_sections}")
    if cfg.kite.n_chord < 3:
        raise ConfigError(f"config key 'kite.n_chord' must be >= 3, got {cfg.kite.n_chord}")
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
    terms = [t.strip() for t in env.observation.split(",") if t.strip()]
    bad = [t for t in terms if t not in OBSERVATION_TERMS]
    if bad or not terms or len(set(terms)) != len(terms):
        raise ConfigError(f"config key 'env.observation' must list distinct terms of {', '.join(OBSERVATION_TERMS)} "
                          f"separated by commas, got {env.observation!r}")
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
    SHA-256 of the model keys (:func:`model_keys`) as sorted JSON. Stored with every artefact made from a model."""
    import hashlib
    import json

    keys = model_keys(cfg)
    digest = hashlib.sha256(json.dumps(keys, sort_keys=True, default=repr).encode()).hexdigest()[:16]
    return {"preset": preset_name(cfg), "fingerprint": digest, "keys": keys}


def check_model(record: dict | None, cfg: Config, what: str) -> None:
    """Raise :class:`ModelMismatch` naming the keys that differ when ``record`` (a :func:`fingerprint` stored with
    ``what``) is not the model of ``cfg``; a record without one is refused too (made before models were recorded)."""
    if not record or "keys" not in record:
        raise ModelMismatch(f"{what} records no model (made before models were recorded); make it again for this "
                            f"model")
    now = model_keys(cfg)
    old = record["keys"]
    diff = sorted(k for k in set(now) | set(old) if now.get(k, "<absent>") != old.get(k, "<absent>"))
    if diff:
        shown = ", ".join(f"{k} ({old.get(k, '<absent>')!r} there, {now.get(k, '<absent>')!r} here)"
                          for k in diff[:8])
        more = f" and {len(diff) - 8} more" if len(diff) > 8 else ""
        raise ModelMismatch(f"{what} was made with model '{record.get('preset', '?')}' ({record.get('fingerprint')}), "
                            f"not this one '{preset_name(cfg)}': {len(diff)} key(s) differ: {shown}{more}")
