"""Open-loop steering authority: the yaw rate a held steering input gives, in the full flight model.

The paper (Sect. IV, Fig. 16) calls the steering input and the yaw rate "linearly correlated" in the upper half of
the figure-eight. Here the relation is measured without the steering controller: the kite (the configured wing)
starts at the figure's crossing point flying along the path, the steering-line rest lengths are set to ``L_B = L_0 +
dL / 2 + L3``, ``L_D = L_0 - dL / 2 + L3`` from ``t_hold``, with ``dL`` held and ``L3`` the paper's force loop
(Eq. 18-19) keeping both lines loaded; the yaw rate ``omega_k . z_k`` is averaged over a window after the transient,
and the same flight with ``dL = 0`` is subtracted (gravity and the start turn the kite a little by themselves).

``psi_dot / dL`` [rad/s per m] at a few speeds is the number the model's steering is judged by: about 5 in the
paper's Fig. 16 (its two axis scales, +-0.3 m against +-1.5 rad/s), about 2.5-5 in TU Delft V3 flight data
(README, "Steering authority").

Why it is what it is, on the static wing: :func:`steering_point_stiffness` (how much of a steering input moves the
wing, and what holds the steering points) and :func:`lateral_balance` (the steady turn in which the steered wing's
side force and yaw moment vanish); docs/steering.md, "Where a steering input goes". The wing's yaw/twist mode on its
lines:
:func:`tethered_wing_yaw_response` and its linearisation :func:`tethered_wing_modes` (docs/steering.md, "The open-loop
turn rate", "The yaw rig").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from kite_env.config import Config
from kite_env.control import LineActuator, actuate
from kite_env.dynamics.factory import make_simulator
from kite_env.dynamics.simulator import SimulationError
from kite_env.trajectory import Lemniscate
from kite_env.wind import WindField


@dataclass(frozen=True)
class TurnRate:
    """One open-loop flight: held input ``dl_m`` [m], mean yaw rate [rad/s] in the window (raw, not
    neutral-subtracted), mean airspeed [m/s], how the flight ended (``"ok"`` or the failure reason) and when [s],
    and the least tension of the two steering lines in the window [N] (near 0: a line was slack)."""

    dl_m: float
    yaw_rate_rad_s: float
    airspeed_mps: float
    end: str
    t_end_s: float
    steering_line_min_N: float = float("nan")


def open_loop_flight(cfg: Config, dl_m: float, t_hold_s: float = 0.5, window_s: tuple[float, float] = (1.0, 2.5),
                     speed_mps: float | None = None, force_loop: bool = True) -> TurnRate:
    """Fly the kite open loop with ``L_B - L_D = dl_m`` held from ``t_hold_s`` and average the yaw rate over
    ``t_hold_s + window_s``.

    Parameters
    ----------
    cfg : Config
        The model (wind from ``cfg.wind``, start at the crossing of ``cfg.trajectory``).
    dl_m : float [m]
        Held steering-line rest-length difference (positive: the right line B longer).
    t_hold_s : float [s]
    window_s : (2,) float [s]
        Averaging window after ``t_hold_s``.
    speed_mps : float, optional [m/s]
        Start speed (default ``cfg.start_speed_mps``).
    force_loop : bool
        Run the paper's force controller (Eq. 18-19 with ``control.k3i_per_s``) on the common rest length of both
        steering lines, as in the paper's flight of Fig. 16, and move the rest lengths through the KCU's motors
        (:func:`kite_env.control.actuate`). ``False``: both rest lengths held: the kite climbs,
        mu drifts and a steering line goes slack within the window (at 10 m/s both), so the yaw rate then measures
        a wing hanging on its power lines (docs/steering.md, "The open-loop turn rate").
    """
    path = Lemniscate(cfg.trajectory)
    sim = make_simulator(cfg, WindField(cfg.wind))
    rec = sim.reset(path.point(0.0), path.tangent(0.0), speed_mps)
    act = LineActuator(cfg.control, sim.L_B0, sim.L_D0) if force_loop else None
    n_control = max(1, int(round(cfg.control.control_dt_s / cfg.dynamics.dt_s)))
    t0, t1 = t_hold_s + window_s[0], t_hold_s + window_s[1]
    yaw, speed = [], []
    line_min = float("inf")
    end = "ok"
    L_B, L_D = sim.L_B0, sim.L_D0
    k = 0
    try:
        while rec.t < t1 - 1e-9:
            d = dl_m if rec.t >= t_hold_s - 1e-9 else 0.0
            if act is None:
                L_B, L_D = sim.L_B0 + 0.5 * d, sim.L_D0 - 0.5 * d
            elif k % n_control == 0:
                L3, _ = act.force_increment(rec.line_tension)
                L_B, L_D = actuate(sim.L_B0 + 0.5 * d + L3, sim.L_D0 - 0.5 * d + L3, L_B, L_D, cfg.control)
            rec = sim.step(L_B, L_D)
            k += 1
            if rec.t >= t0 - 1e-9:
                yaw.append(float(rec.omega @ rec.R_wk[:, 2]))
                speed.append(float(np.linalg.norm(rec.v_kite - rec.v_wind)))
                line_min = min(line_min, float(rec.line_tension[1]), float(rec.line_tension[3]))
    except SimulationError as exc:
        end = exc.reason
    return TurnRate(dl_m=float(dl_m), yaw_rate_rad_s=float(np.mean(yaw)) if yaw else float("nan"),
                    airspeed_mps=float(np.mean(speed)) if speed else float("nan"), end=end, t_end_s=float(sim.t),
                    steering_line_min_N=line_min if speed else float("nan"))


def turn_rate_table(cfg: Config, dls_m=(-0.2, 0.1, 0.2, 0.3), wind_speeds_mps=(5.0,), **kwargs) -> list[dict]:
    """Neutral-subtracted yaw rate per input for each wind speed: rows with ``wind_mps``, ``dl_m``,
    ``yaw_rate_rad_s`` (minus the ``dL = 0`` flight), ``per_m`` [rad/s per m], ``airspeed_mps`` and ``end``."""
    rows = []
    for w in wind_speeds_mps:
        c = dataclasses.replace(cfg, wind=dataclasses.replace(cfg.wind, speed_mps=float(w)))
        neutral = open_loop_flight(c, 0.0, **kwargs)
        for dl in dls_m:
            r = open_loop_flight(c, dl, **kwargs)
            d = r.yaw_rate_rad_s - neutral.yaw_rate_rad_s
            rows.append({"wind_mps": float(w), "dl_m": float(dl), "yaw_rate_rad_s": d, "per_m": d / dl,
                         "airspeed_mps": r.airspeed_mps,
                         "steering_line_min_N": r.steering_line_min_N,
                         "end": r.end if r.end == "ok" else f"{r.end} at {r.t_end_s:.2f} s"})
    return rows


# ------------------------------------------------------------------ where a steering input goes
#: element groups of :func:`steering_point_stiffness`, in its ``parts`` order
STIFFNESS_PARTS = ("LE tube", "struts", "TE", "tip rods", "canopy", "aero")


@dataclass(frozen=True)
class SteeringStiffness:
    """Stiffness of the wing at a steering-line point along its line (A, C and the other steering point held).

    ``coupled_N_per_m``: with the aerodynamic loads following the shape (the monolithic tangent);
    ``frozen_N_per_m``: with the loads held; ``parts_N_per_m``: ``u^T K_g u`` of each group ``g`` of
    :data:`STIFFNESS_PARTS` along the coupled deformation ``u`` (they sum to ``coupled_N_per_m``; the aerodynamic part
    is minus the work the loads do along ``u``); ``share``: the part of a change of the line's rest length that
    becomes motion of the point, ``k_line / (k_line + coupled)``; ``pitch_per_m``: the sections' pitch change per
    metre of the point's motion [rad/m] along the span (positive: the trailing edge moves towards ``-z_k``, the
    section's angle of attack grows).
    """

    point: str
    coupled_N_per_m: float
    frozen_N_per_m: float
    parts_N_per_m: dict
    share: float
    pitch_per_m: np.ndarray


def steering_point_stiffness(wing, flight, kcu_K: np.ndarray, k_line_N_per_m: float) -> list[SteeringStiffness]:
    """Linearised stiffness of ``wing`` (an :class:`~kite_env.fsi.AeroelasticWing` at its last solved state) at B and
    D along their steering lines towards the KCU at ``kcu_K`` (frame K), with A-D's translations held except the
    point moved (the static condensation of the tangent ``K_T - dF_a/dx`` onto that point's line direction).

    This says where a steering input goes: a change ``dL`` of a line's rest length moves its wing point by
    ``share dL`` and stretches the line by the rest (docs/steering.md, "Where a steering input goes").
    """
    from kite_env.fsi import load_jacobian
    from kite_env.geometry.mesh import BEAM_LE, BEAM_STRUT, BEAM_TE, BEAM_TIP
    from kite_env.structure.assembly import element_dofs

    st, m = wing.state, wing.mesh
    wing.update_tube_stiffness(st, material_tangent=True)
    n_dof = 6 * m.n_nodes
    groups = {g: np.zeros((n_dof, n_dof)) for g in STIFFNESS_PARTS}
    _, Kb = wing.beams.internal(st.x[m.beams], st.Rn[m.beams])
    dof_b = element_dofs(m.beams)
    for g, code in zip(STIFFNESS_PARTS[:4], (BEAM_LE, BEAM_STRUT, BEAM_TE, BEAM_TIP)):
        sel = m.beam_kind == code
        np.add.at(groups[g], (dof_b[sel][:, :, None], dof_b[sel][:, None, :]), Kb[sel])
    if wing.hem is not None:  # (the hem as frame-free rods)
        _, Kh = wing.hem.internal(st.x[wing.hem.conn], st.Rn[wing.hem.conn])
        dof_h = element_dofs(wing.hem.conn)
        np.add.at(groups[STIFFNESS_PARTS[2]], (dof_h[:, :, None], dof_h[:, None, :]), Kh)
    _, Ks = wing.shells.internal(st.x[m.shells], st.Rn[m.shells])
    dof_s = element_dofs(m.shells)
    np.add.at(groups["canopy"], (dof_s[:, :, None], dof_s[:, None, :]), Ks)
    fl = wing.downwashed(flight)
    _, J = load_jacobian(st.x[m.sections], m.section_tube_d, m.section_width, fl.v_kite, fl.omega, fl.v_wind,
                         wing.cfg.aero.rho_kg_m3, **wing.aero_options())
    for i, sec in enumerate(m.sections):
        d = (6 * sec[:, None] + np.arange(3)[None, :]).ravel()
        groups["aero"][np.ix_(d, d)] -= J[i]
    K_struct = sum(groups[g] for g in STIFFNESS_PARTS[:5])
    K = K_struct + groups["aero"]
    held = (6 * wing.bridle[:, None] + np.arange(3)[None, :]).ravel()
    free = np.setdiff1d(np.flatnonzero(np.any(K != 0.0, axis=1)), held)
    le, te = m.sections[:, 0], m.sections[:, -1]
    out = []
    for name, node in (("B", wing.bridle[1]), ("D", wing.bridle[3])):
        e = kcu_K - st.x[node]
        e /= np.linalg.norm(e)
        dp = 6 * node + np.arange(3)

        def mode(KK, dp=dp, e=e):
            u = np.zeros(n_dof)
            u[dp] = e
            u[free] = -np.linalg.solve(KK[np.ix_(free, free)], KK[np.ix_(free, dp)] @ e)
            return u

        u = mode(K)
        uf = mode(K_struct)
        k = float(u @ K @ u)
        # pitch of each section's LE-TE chord about y_k, linearised: d(atan2(-c_z, c_x))
        c = st.x[te] - st.x[le]
        dc = (u.reshape(-1, 6)[te, :3] - u.reshape(-1, 6)[le, :3])
        pitch = (-dc[:, 2] * c[:, 0] + c[:, 2] * dc[:, 0]) / (c[:, 0] ** 2 + c[:, 2] ** 2)
        out.append(SteeringStiffness(point=name, coupled_N_per_m=k, frozen_N_per_m=float(uf @ K_struct @ uf),
                                     parts_N_per_m={g: float(u @ groups[g] @ u) for g in STIFFNESS_PARTS},
                                     share=k_line_N_per_m / (k_line_N_per_m + k), pitch_per_m=pitch))
    return out


@dataclass(frozen=True)
class LateralBalance:
    """The quasi-steady lateral balance of :func:`lateral_balance`.

    ``derivatives``: the static wing's yaw moment ``N`` about ``z_k`` (through the origin of K) and side force ``Y``
    along ``y_k`` per metre of the steering points' antisymmetric motion (``N_delta`` [N m/m], ``Y_delta`` [N/m]: B
    towards the KCU, D away), per radian of sideslip (``N_beta`` [N m], ``Y_beta`` [N]) and per yaw rate about ``z_k``
    (``N_r`` [N m s], ``Y_r`` [N s]); ``share`` as :class:`SteeringStiffness`; ``beta_per_m`` [rad/m] and
    ``rate_per_point_m`` [rad/s per m] the steady sideslip and yaw rate per metre of that motion;
    ``rate_per_input_m`` [rad/s per m] the yaw rate per metre of steering input ``L_B - L_D``;
    ``damping_only_per_input_m`` the same from the yaw moment against ``N_r`` alone (no sideslip; at the flight states
    measured about five times larger and of the other sign: the kite turns towards its side force).
    """

    derivatives: dict
    share: float
    beta_per_m: float
    rate_per_point_m: float
    rate_per_input_m: float
    damping_only_per_input_m: float


def lateral_balance(cfg: Config, airspeed_mps: float, alpha_rad: float, delta_m: float = 0.01,
                    beta_rad: float = np.deg2rad(1.0), rate_rad_s: float = 0.2) -> LateralBalance:
    """Why the kite turns as fast as it does: the steady turn of a wing whose side force and yaw moment both vanish.

    The static wing (A-D prescribed) in a uniform flow of ``airspeed_mps`` at kite angle ``alpha_rad`` gives, by
    one-sided differences (steps ``delta_m``, ``beta_rad``, ``rate_rad_s``), the derivatives of its yaw moment and side
    force with respect to the steering points' antisymmetric motion ``delta``, the sideslip ``beta`` and the yaw rate
    ``r``. Setting ``Y_delta delta + Y_beta beta + Y_r r = 0`` and ``N_delta delta + N_beta beta + N_r r = 0`` (the
    wing's mass, gravity and the tether neglected) gives ``r / delta = (Y_beta N_delta - N_beta Y_delta) / (N_beta Y_r
    - Y_beta N_r)``; a change ``dL`` of ``L_B - L_D`` moves each point by ``share dL / 2``
    (:func:`steering_point_stiffness`), towards the KCU at B for ``dL < 0``. docs/steering.md, "Where a steering input
    goes".
    """
    from kite_env.fsi import FlightState, nominal_wing

    wing = nominal_wing(cfg.kite.name, cfg)
    flight = FlightState.wind_tunnel(airspeed_mps, alpha_rad)
    sol0 = wing.solve(None, flight, warm=False)

    def moment_and_side_force(sol):
        return np.array([sol.aero_moment[2], sol.aero_force[1]])

    base = moment_and_side_force(sol0)
    kcu = wing.kcu_position()
    q = wing.design_bridle.copy()
    for j, sign in ((1, 1.0), (3, -1.0)):
        e = kcu - sol0.nodes[wing.bridle[j]]
        q[j] += sign * delta_m * e / np.linalg.norm(e)
    d_delta = (moment_and_side_force(wing.solve(q, flight, commit=False)) - base) / delta_m
    slipped = FlightState.wind_tunnel(airspeed_mps, alpha_rad, beta_rad)
    d_beta = (moment_and_side_force(wing.solve(None, slipped, commit=False)) - base) / beta_rad
    yawing = FlightState(v_kite=np.zeros(3), omega=np.array([0.0, 0.0, rate_rad_s]), v_wind=flight.v_wind)
    d_r = (moment_and_side_force(wing.solve(None, yawing, commit=False)) - base) / rate_rad_s
    (N_d, Y_d), (N_b, Y_b), (N_r, Y_r) = d_delta, d_beta, d_r
    wing.solve(None, flight, commit=True)  # the base state for the stiffness
    share = steering_point_stiffness(wing, flight, kcu, cfg.dynamics.line_stiffness_N_per_m)[0].share
    beta, rate = np.linalg.solve(np.array([[Y_b, Y_r], [N_b, N_r]]), -np.array([Y_d, N_d]))
    per_input = -0.5 * share  # points' motion per metre of L_B - L_D
    return LateralBalance(
        derivatives={"N_delta": float(N_d), "Y_delta": float(Y_d), "N_beta": float(N_b), "Y_beta": float(Y_b),
                     "N_r": float(N_r), "Y_r": float(Y_r)},
        share=float(share), beta_per_m=float(beta), rate_per_point_m=float(rate),
        rate_per_input_m=float(rate * per_input), damping_only_per_input_m=float(-N_d / N_r * per_input))


# ------------------------------------------------------------------ the wing's yaw mode on its bridle
@dataclass(frozen=True)
class YawResponse:
    """The free yaw response of :func:`tethered_wing_yaw_response`: times ``t`` [s], the yaw angle ``yaw`` [rad] of
    the line through the LE tips A and C in the ``x_k``-``y_k`` plane, and the Newton iterations of each step."""

    t: np.ndarray
    yaw: np.ndarray
    newton: np.ndarray

    def amplitude(self, t0: float, t1: float) -> float:
        """Largest deviation of the yaw from its mean over the last third [rad] within ``t0 <= t < t1``."""
        y = self.yaw - self.yaw[-len(self.yaw) // 3:].mean()
        m = (self.t >= t0) & (self.t < t1)
        return float(np.abs(y[m]).max())

    def growth_rate_per_s(self, t0: float = 0.5, t1: float = 3.0, window_s: float = 0.5) -> float:
        """Exponential growth rate [1/s] of the yaw's oscillation (negative where it decays): the slope of the log
        of :meth:`amplitude` over successive windows of ``window_s`` from ``t0`` to ``t1``."""
        starts = np.arange(t0, t1 - 1e-9, window_s)
        amp = np.array([self.amplitude(a, a + window_s) for a in starts])
        return float(np.polyfit(starts + 0.5 * window_s, np.log(amp), 1)[0])

    def frequency_hz(self, f_min: float = 1.0) -> float:
        """The yaw's dominant frequency above ``f_min`` [Hz] (Hann-windowed spectrum)."""
        y = self.yaw - self.yaw.mean()
        f = np.fft.rfftfreq(len(y), self.t[1] - self.t[0])
        P = np.abs(np.fft.rfft(y * np.hanning(len(y))))
        P[f < f_min] = 0.0
        return float(f[np.argmax(P)])


def _tethered_wing_rig(cfg: Config, airspeed_mps: float, alpha_rad: float, settle_s: float):
    """The rig of :func:`tethered_wing_yaw_response` at rest on its lines: ``(dyn, kcu, rest, flight)``.

    The static solve on lines (``support="lines"``) holds the ``x_k`` and ``z_k`` of A-D and frees only their
    ``y_k``; its reactions are not along the lines. With rest lengths ``l - |F_b| / k_c`` the free wing is therefore
    not in equilibrium there: it surges 0.96 m forward (a 0.6 Hz swing on its lines, up to 2.8 m/s) and settles
    within about 10 s. The wing is released from the static shape at rest and stepped for ``settle_s``, which leaves
    it moving at about 1e-4 m/s (docs/steering.md, "The yaw rig")."""
    from kite_env.dynamics.wing_dynamics import WingDynamics
    from kite_env.fsi import FlightState, nominal_wing

    cfg = dataclasses.replace(cfg, structure=dataclasses.replace(cfg.structure, dynamic=True),
                              dynamics=dataclasses.replace(cfg.dynamics, gravity_mps2=0.0, line_cd=0.0))
    wing = nominal_wing(cfg.kite.name, cfg)
    flight = FlightState.wind_tunnel(airspeed_mps, alpha_rad)
    sol = wing.solve(None, flight, support="lines", warm=False)
    kcu = wing.kcu_position()
    x0 = wing.state.x
    rest = (np.linalg.norm(x0[wing.bridle] - kcu, axis=1)
            - np.linalg.norm(sol.F_b, axis=1) / cfg.dynamics.line_stiffness_N_per_m)
    dyn = WingDynamics(wing)
    dyn.start(wing.state.copy(), np.zeros_like(x0), kcu, np.zeros(3), rest, np.zeros(3), flight.v_wind)
    for _ in range(int(round(settle_s / cfg.dynamics.dt_s))):
        dyn.step(cfg.dynamics.dt_s, kcu, np.zeros(3), rest, np.zeros(3), flight.v_wind, flight)
    return dyn, kcu, rest, flight


def tethered_wing_yaw_response(cfg: Config, airspeed_mps: float = 30.0, alpha_rad: float = np.deg2rad(8.0),
                               yaw_rate_rad_s: float = 0.5, duration_s: float = 3.0,
                               settle_s: float = 12.0) -> YawResponse:
    """The wing with inertia on its four bridle lines from a fixed KCU in a wind tunnel (no gravity, no line drag),
    at rest on them (:func:`_tethered_wing_rig`, after ``settle_s``), kicked with a rigid yaw rate about ``z_k``
    through its centre, then free for ``duration_s``.

    The rig isolates the yaw/twist oscillation of the flying wing (3.9 Hz in the baseline flight), a mode of the
    wing on its lines (the wing held at A-D shows none); :func:`tethered_wing_modes` linearises it
    (docs/steering.md, "The open-loop turn rate", "The yaw rig")."""
    dyn, kcu, rest, flight = _tethered_wing_rig(cfg, airspeed_mps, alpha_rad, settle_s)
    dt = dyn.wing.cfg.dynamics.dt_s
    x0 = dyn.state.x
    v0 = dyn.v + np.cross(np.array([0.0, 0.0, yaw_rate_rad_s])[None, :], x0 - x0.mean(axis=0))
    dyn.start(dyn.state.copy(), v0, kcu, np.zeros(3), rest, np.zeros(3), flight.v_wind)
    A, C = dyn.bridle[0], dyn.bridle[2]
    t, yaw, newton = [], [], []
    for k in range(int(round(duration_s / dt))):
        s = dyn.step(dt, kcu, np.zeros(3), rest, np.zeros(3), flight.v_wind, flight)
        e = dyn.state.x[A] - dyn.state.x[C]
        t.append((k + 1) * dt)
        yaw.append(float(np.arctan2(e[0], e[1])))
        newton.append(s.newton_iters)
    return YawResponse(np.array(t), np.array(yaw), np.array(newton))


@dataclass(frozen=True)
class WingModes:
    """The linearised rig's modes (:func:`tethered_wing_modes`), sorted by frequency: eigenvalues ``lam`` [1/s]
    (those with a positive imaginary part, and the real ones), ``frequency_hz``, ``damping_ratio`` (``-Re / |lam|``,
    negative where the mode grows), and each mode's rigid-body content: ``rigid`` (the share of its mass-weighted
    translations that a rigid motion of the wing fits) and ``yaw`` (the fitted rotation about ``z_k`` over the
    largest nodal translation, 1/m)."""

    lam: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    rigid: np.ndarray
    yaw: np.ndarray

    def yaw_mode(self, f_min: float = 2.5, f_max: float = 4.5, rigid_min: float = 0.6) -> int:
        """Index of the least damped mode in ``f_min``-``f_max`` Hz that turns the wing rigidly about ``z_k``
        (``rigid`` above ``rigid_min`` and ``|yaw|`` above a third of the largest such)."""
        m = (self.frequency_hz > f_min) & (self.frequency_hz < f_max) & (self.rigid > rigid_min)
        m &= np.abs(self.yaw) > np.abs(self.yaw[m]).max() / 3.0
        idx = np.flatnonzero(m)
        return int(idx[np.argmin(self.damping_ratio[idx])])


def tethered_wing_modes(cfg: Config, airspeed_mps: float = 30.0, alpha_rad: float = np.deg2rad(8.0),
                        settle_s: float = 12.0, h_mps: float = 1e-4, rigid_inflow: bool = True) -> WingModes:
    """The rig of :func:`tethered_wing_yaw_response` linearised at rest on its lines: ``M q'' + D q' + K q = 0`` on
    the nodes' translations, the rotations condensed statically (the nodes' rotary inertia does not change the
    rig's response, docs/steering.md, "The open-loop turn rate").

    ``K``: the structure's tangent and the step's external stiffness (:meth:`StepLoad.operators`: the section loads
    at the held inflow, the bridle lines). ``M``: the nodal mass blocks with the added mass. ``D = -df/dv`` by
    central differences (``h_mps``) of the step's own force law (:class:`StepLoad`, built at each velocity state):
    the section loads see the wing's rigid translation through the inflow (``u_ref``, their force and moment alike),
    the deviation from it through the section damping, plus the bridle lines' and the structural damping and
    Theodorsen's normal-rate force with ``n' = (dn/dx) v``.
    ``rigid_inflow=False`` gives the operators' damping ``C`` instead (the Newton tangent's, which applies the
    section damping to all of the velocity: the rigid translation's response is then the sections' forces at their
    3/4-chord points, symmetric part projected onto the positive semi-definite cone, without the moment of Eq. 9)."""
    from kite_env.dynamics.wing_dynamics import StepLoad

    dyn, kcu, rest, flight = _tethered_wing_rig(cfg, airspeed_mps, alpha_rad, settle_s)
    wing = dyn.wing
    n = len(dyn.state.x)
    st = dyn.state
    dt = wing.cfg.dynamics.dt_s
    asm = wing.prescribed_assembly
    zero3 = np.zeros(3)
    dyn.v = np.zeros((n, 3))
    dyn.a = np.zeros((n, 3))
    dyn.w = np.zeros((n, 3))
    dyn.aw = np.zeros((n, 3))
    dyn.carry = None
    dyn.update_mass(st.x)

    def load_at(v):
        dyn.v = v
        ld = StepLoad(dyn, dt, kcu, zero3, rest, zero3, flight.v_wind)
        ld.x_pred, ld.v_pred = st.x, v  # a = 0 at the iterate st, v the velocities
        return ld

    ld0 = load_at(np.zeros((n, 3)))
    ld0.force(st)
    dyn.rayleigh_held = (ld0.K0, ld0.Kb_at, 0.0, np.eye(3))  # the structure's tangent at rest, for every state below
    K, C, M = ld0.operators(st)
    wing.update_tube_stiffness(st)
    _, kd = asm.assemble_data(st.x, st.Rn, tangent=True)
    Kfull = asm.matrix(kd + K).toarray()
    Mfull = asm.matrix(M).toarray()
    free = np.setdiff1d(np.arange(6 * n), dyn.solver.auto_fixed)
    is_t = np.zeros(6 * n, bool)
    is_t[(6 * np.arange(n)[:, None] + np.arange(3)).ravel()] = True
    t = free[is_t[free]]
    r = free[~is_t[free]]
    Kc = Kfull[np.ix_(t, t)] - Kfull[np.ix_(t, r)] @ np.linalg.solve(Kfull[np.ix_(r, r)], Kfull[np.ix_(r, t)])
    Mt = Mfull[np.ix_(t, t)]
    nodes, comp = t // 6, t % 6
    if rigid_inflow:
        D = np.zeros((t.size, t.size))
        normal_rate = dyn.section_added_mass is not None
        n0 = dyn.section_frames(st.x).e_z if normal_rate else None
        eps = 1e-6  # [s] the normal's rate (dn/dx) v by a forward difference of the shape

        def f(v):
            ld = load_at(v)
            out = ld.force(st).reshape(-1, 6)[:, :3].copy()
            if normal_rate:
                out += dyn.normal_rate_force((n0, dyn.section_added_mass, eps), st.x + eps * v, v, flight.v_wind)
            return out

        for j, (i, c) in enumerate(zip(nodes, comp)):
            dv = np.zeros((n, 3))
            dv[i, c] = h_mps
            D[:, j] = -((f(dv) - f(-dv)) / (2.0 * h_mps))[nodes, comp]
    else:
        D = asm.matrix(C).toarray()[np.ix_(t, t)]
    Mi = np.linalg.inv(Mt)
    N = t.size
    A = np.block([[np.zeros((N, N)), np.eye(N)], [-Mi @ Kc, -Mi @ D]])
    lam, V = np.linalg.eig(A)
    keep = lam.imag >= 0.0
    lam, V = lam[keep], V[:N, keep]
    # rigid-body content of each mode's translations: WingDynamics.rigid_velocity's mass-weighted fit (dyn.state is st)
    m, x = dyn.m_node, st.x
    rigid, yaw = np.zeros(lam.size), np.zeros(lam.size)
    for k in range(lam.size):
        q = np.zeros((n, 3), complex)
        q[nodes, comp] = V[:, k]
        u = np.real(q * np.exp(-0.5j * np.angle(np.sum(q * q))))  # the phase of largest real part
        Vr, w = dyn.rigid_velocity(u)
        ur = Vr[None, :] + np.cross(w[None, :], x)
        rigid[k] = np.sum(m[:, None] * ur ** 2) / np.sum(m[:, None] * u ** 2)
        yaw[k] = w[2] / np.abs(u).max()
    order = np.argsort(np.abs(lam.imag))
    lam, rigid, yaw = lam[order], rigid[order], yaw[order]
    return WingModes(lam, lam.imag / (2.0 * np.pi), -lam.real / np.abs(lam), rigid, yaw)
