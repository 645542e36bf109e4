"""Figures of a flight like the paper's Sect. IV (Bosch et al., Fig. 9, 11-18), drawn with matplotlib (Agg).

:func:`make_plots` writes one PNG per figure into a folder:

=====================  ======  =========================================================================
file                   paper   content
=====================  ======  =========================================================================
path.png               Fig. 9  KCU flight path (azimuth, elevation) against the figure-eight, start marked
wing_turn.png          Fig. 11 deformed wing in frame K at the largest steering input vs the design shape
alpha.png              Fig. 12 angle of attack of the left tip, right tip and mid section
tip_forces.png         Fig. 13 lift and drag of the two tip sections
forces.png             Fig. 14 bridle-line tensions A-D and tether force
steering.png           Fig. 15 steering-line lengths l_B, l_D, their difference, Delta L and dl*
yaw_vs_steering.png    Fig. 16 yaw rate vs steering input, upper half of the figure and its fitted line
lift_to_drag.png       Fig. 17 lift-to-drag ratio and force ratio mu
tip_displacement.png   Fig. 18 transverse (y_k) displacements of the bridle points A-D and tip distance
=====================  ======  =========================================================================

The warm-up period (excluded from the metrics) is shaded in the time plots. Long logs are subsampled for drawing
(at most :data:`MAX_POINTS` points per curve); the statistics in :mod:`kite_env.metrics` use every sample.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from kite_env.config import Config
from kite_env.flight import FlightLog
from kite_env.metrics import yaw_steering_fit

#: most points drawn per curve
MAX_POINTS = 6000
DPI = 100


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _stride(n: int) -> int:
    return max(1, int(math.ceil(n / MAX_POINTS)))


def _time_axes(plt, n_rows: int, title: str, warmup_s: float, t_end: float):
    fig, axes = plt.subplots(n_rows, 1, figsize=(9, 2.6 * n_rows + 0.6), sharex=True, constrained_layout=True,
                             squeeze=False)
    axes = axes[:, 0]
    for ax in axes:
        if warmup_s > 0:
            ax.axvspan(0.0, min(warmup_s, t_end), color="0.85", lw=0, label="warm-up")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time t [s]")
    axes[-1].set_xlim(0.0, max(t_end, 1e-9))
    fig.suptitle(title)
    return fig, axes


def _save(plt, fig, path: Path, written: list[Path]) -> None:
    fig.savefig(path, format="png", dpi=DPI)
    plt.close(fig)
    written.append(path)


def make_plots(log: FlightLog, cfg: Config, out_dir: str | Path) -> list[Path]:
    """Draw the Sect. IV figures of ``log`` into ``out_dir`` (module docstring); returns the PNG paths written.

    Parameters
    ----------
    log : FlightLog from :func:`kite_env.flight.fly`
    cfg : Config of the flight (trajectory, kite mesh, warm-up)
    out_dir : existing folder
    """
    plt = _plt()
    out = Path(out_dir)
    se = log.series
    t = np.asarray(se["t"], dtype=float)
    k = slice(None, None, _stride(t.size))
    ts = t[k]
    t_end = float(t[-1]) if t.size else 0.0
    warmup = float(log.meta.get("warmup_s", cfg.sim.warmup_s))
    written: list[Path] = []
    deg = np.degrees

    _plot_path(plt, log, cfg, out, written)
    _plot_wing(plt, log, cfg, out, written)

    # Fig. 12: angles of attack
    alpha = np.asarray(se["alpha"])
    fig, (ax,) = _time_axes(plt, 1, "Angle of attack of three wing sections (cf. paper Fig. 12)", warmup, t_end)
    ax.plot(ts, deg(alpha[k, -1]), lw=0.9, label=r"left tip $\alpha_l$")
    ax.plot(ts, deg(alpha[k, 0]), lw=0.9, label=r"right tip $\alpha_r$")
    ax.plot(ts, deg(alpha[k, alpha.shape[1] // 2]), lw=1.2, color="k", label=r"mid section $\alpha_m$")
    ax.set_ylabel(r"$\alpha$ [deg]")
    ax.legend(loc="upper right", fontsize=8, ncol=4)
    _save(plt, fig, out / "alpha.png", written)

    # Fig. 13: tip lift and drag
    # (the reduced-order wing of the surrogate fidelity returns no section forces: no plot)
    lift, drag = np.asarray(se["section_lift"]), np.asarray(se["section_drag"])
    if lift.ndim == 2:
        fig, axes = _time_axes(plt, 2, "Aerodynamic forces on the wing tip sections (cf. paper Fig. 13)", warmup,
                               t_end)
        for ax, arr, name in ((axes[0], lift, "lift"), (axes[1], drag, "drag")):
            ax.plot(ts, arr[k, -1], lw=0.9, label=f"left tip {name}")
            ax.plot(ts, arr[k, 0], lw=0.9, label=f"right tip {name}")
            ax.set_ylabel(f"section {name} [N]")
            ax.legend(loc="upper right", fontsize=8, ncol=3)
        _save(plt, fig, out / "tip_forces.png", written)

    # Fig. 14: line tensions and tether force
    lt = np.asarray(se["line_tension"])
    fig, axes = _time_axes(plt, 2, "Bridle-line tensions and tether force (cf. paper Fig. 14)", warmup, t_end)
    for i, name in enumerate("ABCD"):
        axes[0].plot(ts, lt[k, i], lw=0.9, label=f"line {name}")
    axes[0].set_ylabel("line tension [N]")
    axes[0].legend(loc="upper right", fontsize=8, ncol=5)
    axes[1].plot(ts, np.asarray(se["tether_force"])[k] * 1e-3, lw=1.0, color="k", label="tether force")
    axes[1].set_ylabel("tether force [kN]")
    axes[1].legend(loc="upper right", fontsize=8, ncol=2)
    _save(plt, fig, out / "forces.png", written)

    # Fig. 15: steering lines
    ll = np.asarray(se["line_length"])
    fig, axes = _time_axes(plt, 2, "Steering-line lengths and steering input (cf. paper Fig. 15)", warmup, t_end)
    axes[0].plot(ts, ll[k, 1], lw=0.9, label=r"$l_B$")
    axes[0].plot(ts, ll[k, 3], lw=0.9, label=r"$l_D$")
    axes[0].set_ylabel("line length [m]")
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    axes[1].plot(ts, np.asarray(se["delta_l"])[k], lw=0.9, label=r"$\Delta l = l_B - l_D$")
    axes[1].plot(ts, np.asarray(se["steering_input"])[k], lw=0.9, label=r"$\Delta L = L_B - L_D$")
    axes[1].plot(ts, np.asarray(se["delta_l_star"])[k], lw=0.8, ls="--", label=r"policy $\Delta l^*$")
    axes[1].set_ylabel("length difference [m]")
    axes[1].legend(loc="upper right", fontsize=8, ncol=4)
    _save(plt, fig, out / "steering.png", written)

    _plot_yaw(plt, log, cfg, out, written, warmup)

    # Fig. 17: L/D and mu
    fig, axes = _time_axes(plt, 2, "Lift-to-drag ratio and force ratio (cf. paper Fig. 17)", warmup, t_end)
    axes[0].plot(ts, np.asarray(se["lift_to_drag"])[k], lw=0.9, color="k", label="L/D")
    axes[0].set_ylabel("L/D [-]")
    axes[1].plot(ts, np.asarray(se["mu"])[k], lw=0.9, label=r"$\mu$")
    axes[1].axhline(cfg.control.mu_target, color="C3", ls="--", lw=0.8, label=r"target $\mu^*$")
    axes[1].set_ylabel(r"force ratio $\mu$ [-]")
    for ax in axes:
        ax.legend(loc="upper right", fontsize=8, ncol=3)
    _save(plt, fig, out / "lift_to_drag.png", written)

    # Fig. 18: the y_k displacements of the bridle points A-D from the design
    fig, axes = _time_axes(plt, 2, "Transverse displacement of the bridle points and tip distance (cf. paper Fig. 18)",
                           warmup, t_end)
    by = np.asarray(se["bridle_y"])[k] - np.asarray(log.meta["design_bridle_y_m"], dtype=float)
    for j, name in enumerate("ABCD"):
        axes[0].plot(ts, by[:, j], lw=0.9, label=name)
    axes[0].set_ylabel(r"$y_k$ displacement [m]")
    axes[1].plot(ts, np.asarray(se["tip_distance"])[k], lw=0.9, color="k", label="tip distance |A - C|")
    design = log.meta.get("design_tip_distance_m")
    if design is not None:
        axes[1].axhline(design, color="0.4", ls="--", lw=0.8, label="design (unloaded)")
    axes[1].set_ylabel("tip distance [m]")
    for ax in axes:
        ax.legend(loc="upper right", fontsize=8, ncol=3)
    _save(plt, fig, out / "tip_displacement.png", written)
    return written


def _plot_path(plt, log: FlightLog, cfg: Config, out: Path, written: list[Path]) -> None:
    """Fig. 9: the KCU path on the unit sphere (azimuth, elevation) against the prescribed figure-eight."""
    from kite_env.trajectory import Lemniscate, azimuth, elevation

    se = log.series
    path = Lemniscate(cfg.trajectory)
    p = path.point(np.linspace(0.0, 2.0 * np.pi, 721))
    az, el = np.degrees(azimuth(p)), np.degrees(elevation(p))
    t = np.asarray(se["t"])
    k = _stride(t.size)
    a_k, e_k = np.degrees(np.asarray(se["azimuth"])), np.degrees(np.asarray(se["elevation"]))
    warm = t <= float(log.meta.get("warmup_s", cfg.sim.warmup_s))
    fig, ax = plt.subplots(figsize=(9, 4.8), constrained_layout=True)
    ax.plot(az, el, "k--", lw=1.0, label="prescribed figure-eight")
    ax.plot(a_k[warm][::k], e_k[warm][::k], color="C1", lw=1.0, alpha=0.6, label="flight path (warm-up)")
    ax.plot(a_k[~warm][::k], e_k[~warm][::k], color="C0", lw=1.2, label="flight path (KCU)")
    if t.size:
        ax.plot(a_k[0], e_k[0], "o", color="C2", ms=7, label="start")
        ax.plot(a_k[-1], e_k[-1], "s", color="C3", ms=6, label="end")
    ax.invert_xaxis()  # as seen from the ground station looking downwind: +y_w (positive azimuth) on the left
    ax.set_xlabel(r"azimuth $\phi$ [deg] (view from the ground station)")
    ax.set_ylabel(r"elevation $\beta$ [deg]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"Flight path (cf. paper Fig. 9): wind {cfg.wind.speed_mps:g} m/s, {t[-1] if t.size else 0:.1f} s")
    _save(plt, fig, out / "path.png", written)


def _plot_yaw(plt, log: FlightLog, cfg: Config, out: Path, written: list[Path], warmup: float) -> None:
    """Fig. 16: yaw rate against steering input; the upper half of the figure (after the warm-up) is fitted."""
    se = log.series
    t = np.asarray(se["t"])
    x = np.asarray(se["steering_input"], dtype=float)
    y = np.asarray(se["omega_k"], dtype=float)[:, 2]
    after = t >= warmup if (t.size and t[-1] >= warmup) else np.ones(t.shape, dtype=bool)
    upper = np.asarray(se["elevation"]) > math.radians(cfg.trajectory.elevation_deg)
    corr, slope, icpt, n = yaw_steering_fit(x[after], y[after], upper[after])
    k = _stride(t.size)
    lo = after & ~upper
    hi = after & upper
    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    ax.scatter(x[lo][::k], np.degrees(y[lo][::k]), s=4, color="0.6", label="lower half of the figure")
    ax.scatter(x[hi][::k], np.degrees(y[hi][::k]), s=5, color="C0", label=f"upper half of the figure ({n} samples)")
    if slope is not None:
        xs = np.array([np.nanmin(x[hi]), np.nanmax(x[hi])])
        ax.plot(xs, slope * xs + icpt, color="C3", lw=1.5,
                label=f"fit (upper half): {slope:.1f} deg/s per m, r = {corr if corr is None else round(corr, 3)}")
    ax.set_xlabel(r"steering input $\Delta L$ [m]")
    ax.set_ylabel(r"yaw rate $\omega_{z,k}$ [deg/s]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("Yaw rate vs steering input after the warm-up (cf. paper Fig. 16)")
    _save(plt, fig, out / "yaw_vs_steering.png", written)


def _plot_wing(plt, log: FlightLog, cfg: Config, out: Path, written: list[Path], exaggeration: float = 1.0) -> None:
    """Fig. 11: deformed wing (frame K) at the turn snapshot (or the initial one) against the design shape.

    Each section is drawn as a chordwise line, plus the leading and trailing edges. Displacements from the design
    shape are multiplied by ``exaggeration`` (noted in the title when it is not 1).
    """
    from matplotlib.ticker import MaxNLocator

    snaps = log.snapshots
    design = snaps.get("design")
    key = "turn" if "turn" in snaps else "initial"
    shape = snaps.get(key)
    fig = plt.figure(figsize=(11, 5), constrained_layout=True)
    if design is None or shape is None:
        ax = fig.add_subplot(1, 1, 1)
        ax.text(0.5, 0.5, "no wing snapshots in the flight log", ha="center", va="center")
        ax.set_axis_off()
        _save(plt, fig, out / "wing_turn.png", written)
        return
    design = np.asarray(design, dtype=float)
    shape = design + exaggeration * (np.asarray(shape, dtype=float) - design)
    sections = None
    try:
        from kite_env.geometry import build_kite

        mesh = build_kite(cfg.kite.name, cfg.kite.n_sections, cfg.kite.n_chord)
        if mesh.nodes.shape == design.shape:
            sections = mesh.sections
    except ValueError:
        pass
    when = ""
    if key == "turn" and "turn_t" in snaps:
        when = f" at t = {float(snaps['turn_t']):.2f} s (largest steering input, upper half)"
    elif key == "initial":
        when = " at the start (no turn snapshot)"
    for i, (el, az, name) in enumerate(((25, -60, "perspective"), (0, 180, "front view (along +x_k)"))):
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        for X, color, lw, lab in ((design, "0.6", 0.7, "design (unloaded)"), (shape, "C0", 1.0, "deformed")):
            if sections is None:
                ax.scatter(X[:, 0], X[:, 1], X[:, 2], s=3, color=color, label=lab)
                continue
            for j, sec in enumerate(sections):
                ax.plot(*X[sec].T, color=color, lw=lw, label=lab if j == 0 else None)
            ax.plot(*X[sections[:, 0]].T, color=color, lw=1.6 * lw)  # leading edge
            ax.plot(*X[sections[:, -1]].T, color=color, lw=lw)  # trailing edge
        ax.set_xlabel("$x_k$ [m]")
        ax.set_ylabel("$y_k$ [m]")
        ax.set_zlabel("$z_k$ [m]")
        ax.view_init(elev=el, azim=az)
        ax.xaxis.set_major_locator(MaxNLocator(3))
        if i == 1:  # the x_k axis points at the viewer
            ax.set_xticks([])
            ax.set_xlabel("")
        span = np.ptp(np.vstack([design, shape]), axis=0)
        ax.set_box_aspect(span + 1e-3)
        ax.set_title(name, fontsize=9)
        if i == 0:
            ax.legend(loc="upper left", fontsize=8)
    scale = "true scale" if exaggeration == 1.0 else f"displacements x {exaggeration:g}"
    fig.suptitle(f"Deformed wing in frame K{when} (cf. paper Fig. 11), {scale}")
    _save(plt, fig, out / "wing_turn.png", written)
