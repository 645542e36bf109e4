"""Flight metrics and time-series export for ``kite-eval`` (Bosch et al., Sect. IV, Fig. 9-18).

:func:`compute_metrics` reduces a :class:`kite_env.flight.FlightLog` to a flat, JSON-serialisable dict. Every
statistic is taken over the *metrics window*: the samples with ``t >= sim.warmup_s`` (the initial transient is
excluded). If the flight ended before the warm-up was over, the whole flight is used and ``metrics_window`` says
so. Only ``sim_time_s``, ``wall_time_s``, ``real_time_factor``, ``crashed`` and ``termination_reason`` describe the
whole flight. Non-finite samples are ignored by the statistics; a statistic without any finite sample, and any
non-finite result, is ``None`` (JSON ``null``).

Conventions (those of the flight log): angles in the log are in rad and converted here to outputs named ``*_deg``;
section index 0 is the right tip, ``n_sec - 1`` the left tip, ``n_sec // 2`` the mid section; the yaw rate is
``omega_k[:, 2]`` (rotation rate about ``z_k``); the *upper half* of the figure-eight is where the KCU elevation
exceeds ``trajectory.elevation_deg`` (the crossing point's elevation), the part of the figure where the paper finds
yaw rate and steering input linearly related (Sect. IV, Fig. 16).

:func:`write_timeseries` writes ``timeseries.npz`` (all series, snapshots, meta as JSON) and ``timeseries.csv``
(scalar series plus a few flattened vector series, SI units, angles in rad, one row per time step);
:func:`read_timeseries` reads the NPZ back into a FlightLog.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from kite_env.config import Config
from kite_env.flight import FlightLog

TWO_PI = 2.0 * math.pi
#: fewest upper-half samples for the yaw-rate / steering-input fit
MIN_FIT_SAMPLES = 10
#: a steering line below this tension counts as slack [N]
SLACK_LINE_N = 50.0

# Paper values (Bosch et al., Sect. IV; figure numbers of the paper): (key, quantity, paper value, unit, source).
# A pair is a range (min, max); a single number an average or typical value.
PAPER_VALUES = (
    ("tether_force", "traction (tether) force range", (3.0, 6.0), "kN", "Sect. IV, Fig. 14"),
    ("lift_to_drag", "lift-to-drag ratio range", (7.5, 9.0), "-", "Sect. IV, Fig. 17"),
    ("alpha_mid", "mid-wing angle of attack (mean)", 7.5, "deg", "Sect. IV, Fig. 12"),
    ("speed", "flight speed range", (18.0, 28.0), "m/s", "Sect. IV"),
    ("mu", "force ratio mu range", (0.26, 0.34), "-", "Sect. IV (Eq. 18)"),
    ("tip_reduction", "tip distance reduction (mean)", 1.0, "m", "Sect. IV, Fig. 18"),
    # Fig. 18 plots the y_k displacement of the bridle points; a tip's variation is the larger of its two points'
    ("tip_variation_left", "transverse displacement variation, left tip (C, D)", 0.3, "m", "Sect. IV, Fig. 18-19"),
    ("tip_variation_right", "transverse displacement variation, right tip (A, B)", 0.3, "m", "Sect. IV, Fig. 18-19"),
    # the ratio of Fig. 16's two axes (yaw rate +-1.5 rad/s, steering input +-0.3 m), whose curves the text calls
    # linearly correlated in the upper half; the paper's yaw is its heading on the tangent plane (Sect. III)
    ("heading_rate_slope", "heading rate per steering input, upper half", 5.0, "rad/s/m", "Sect. IV, Fig. 16 axes"),
)


# ------------------------------------------------------------------------------------------------ helpers
def _num(x) -> float | None:
    """A finite float, or None (NaN, inf, None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _finite(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float).ravel()
    return a[np.isfinite(a)]


def _stat(a: np.ndarray, fun) -> float | None:
    """``fun`` over the finite entries of ``a``; None when there are none."""
    f = _finite(a)
    return _num(fun(f)) if f.size else None


def _deg(x: float | None) -> float | None:
    return None if x is None else math.degrees(x)


def _series(log: FlightLog, key: str) -> np.ndarray:
    try:
        return np.asarray(log.series[key], dtype=float)
    except KeyError:
        raise KeyError(f"flight log has no series {key!r} (has: {', '.join(sorted(log.series))})") from None


def metrics_window(log: FlightLog, warmup_s: float) -> tuple[np.ndarray, str]:
    """Boolean mask (n,) of the samples used for the statistics, and its description."""
    t = _series(log, "t")
    if t.size and t[-1] >= warmup_s:
        return t >= warmup_s, f"t >= {warmup_s:g} s (after the warm-up)"
    return np.ones(t.shape, dtype=bool), (f"whole flight: it ended at t = {float(t[-1]) if t.size else 0.0:g} s, "
                                          f"before the warm-up of {warmup_s:g} s was over")


def yaw_steering_fit(steering_m: np.ndarray, yaw_rate_rad_s: np.ndarray,
                     upper: np.ndarray) -> tuple[float | None, float | None, float | None, int]:
    """Least-squares line ``yaw rate = slope * steering + intercept`` over the upper-half samples (Fig. 16).

    Parameters
    ----------
    steering_m : (n,) float [m], steering input Delta L
    yaw_rate_rad_s : (n,) float [rad/s]
    upper : (n,) bool, samples to use

    Returns
    -------
    corr : Pearson correlation [-], None with fewer than MIN_FIT_SAMPLES samples or a zero variance
    slope : [deg/s per m], None with too few samples or no variance of the steering input
    intercept : [deg/s], None like slope
    n : number of finite samples used
    """
    x = np.asarray(steering_m, dtype=float)
    y = np.degrees(np.asarray(yaw_rate_rad_s, dtype=float))
    ok = np.asarray(upper, dtype=bool) & np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    n = int(x.size)
    if n < MIN_FIT_SAMPLES:
        return None, None, None, n
    dx, dy = x - x.mean(), y - y.mean()
    sxx, syy, sxy = float(dx @ dx), float(dy @ dy), float(dx @ dy)
    # relative zero-variance test: a constant series carries only round-off in dx
    tiny_x = sxx <= (1e-12 * max(1.0, float(np.abs(x).max()))) ** 2 * n
    tiny_y = syy <= (1e-12 * max(1.0, float(np.abs(y).max()))) ** 2 * n
    if tiny_x:
        return None, None, None, n
    slope = sxy / sxx
    intercept = float(y.mean() - slope * x.mean())
    corr = None if tiny_y else _num(sxy / math.sqrt(sxx * syy))
    return corr, _num(slope), _num(intercept), n


def heading_rate(t: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """``d psi / dt`` (n,) [rad/s] of the heading ``psi`` (n,) [rad] on the tangent plane (unwrapped; second-order
    central differences, one-sided at the ends; NaN where ``t`` or ``psi`` is not finite or fewer than 2 remain).

    The heading is the paper's yaw angle, the third of its x-y'-z'' Euler angles (Sect. III: "the yaw rotation of the
    kite [...] describes its heading h on the local tangential plane"); its rate differs from the body rate
    ``omega_k . z_k`` by the turn of the tangent plane's axes as the kite crosses the sphere."""
    t, psi = np.asarray(t, dtype=float), np.asarray(psi, dtype=float)
    out = np.full(t.shape, np.nan)
    ok = np.isfinite(t) & np.isfinite(psi)
    if ok.sum() >= 2:
        out[ok] = np.gradient(np.unwrap(psi[ok]), t[ok])
    return out


def heading_rate_mean(t: np.ndarray, psi: np.ndarray) -> float | None:
    """Mean ``|d psi / dt|`` [rad/s] with ``psi`` unwrapped over the finite samples; None with < 2 samples."""
    t, psi = np.asarray(t, dtype=float), np.asarray(psi, dtype=float)
    ok = np.isfinite(t) & np.isfinite(psi)
    t, psi = t[ok], np.unwrap(psi[ok])
    if t.size < 2:
        return None
    dt = np.diff(t)
    good = dt > 0
    if not good.any():
        return None
    return _num(np.mean(np.abs(np.diff(psi)[good] / dt[good])))


# ------------------------------------------------------------------------------------------------ metrics
def compute_metrics(log: FlightLog, cfg: Config) -> dict:
    """Flight metrics (module docstring) as a flat JSON-serialisable dict plus ``paper_comparison``.

    Parameters
    ----------
    log : FlightLog from :func:`kite_env.flight.fly` (series documented there)
    cfg : Config the flight was run with (warm-up, trajectory elevation)

    Returns
    -------
    dict of float | int | bool | str | None, and ``paper_comparison``: list of dicts
    ``{quantity, model, paper, unit, source}`` where ``model``/``paper`` are a number or a ``[min, max]`` pair.
    """
    meta = log.meta
    warmup = float(meta.get("warmup_s", cfg.sim.warmup_s))
    t_all = _series(log, "t")
    win, window_text = metrics_window(log, warmup)

    def s(key: str) -> np.ndarray:
        return _series(log, key)[win]

    t = s("t")
    m: dict = {}
    sim_time = float(meta.get("sim_time_s", t_all[-1] if t_all.size else 0.0))
    wall = _num(meta.get("wall_time_s"))
    m["sim_time_s"] = _num(sim_time)
    m["wall_time_s"] = wall
    m["real_time_factor"] = _num(wall / sim_time) if wall is not None and sim_time > 0 else None
    m["crashed"] = bool(meta.get("crashed", False))
    m["termination_reason"] = str(meta.get("termination_reason", "unknown"))
    m["metrics_window"] = window_text
    m["metrics_window_start_s"] = _num(t[0]) if t.size else None
    m["metrics_window_samples"] = int(t.size)

    # path following: path_s is unwrapped, one figure-eight = 2 pi
    path_s = _finite(s("path_s"))
    n_fig = int(math.floor((path_s[-1] - path_s[0]) / TWO_PI + 1e-9)) if path_s.size >= 2 else 0
    m["figure_eights_completed"] = max(n_fig, 0)
    span_s = float(path_s[-1] - path_s[0]) if path_s.size >= 2 else 0.0
    duration = float(t[-1] - t[0]) if t.size >= 2 else 0.0
    # mean sim time per figure from the mean progress rate along the path in the window
    m["figure_period_s"] = _num(duration * TWO_PI / span_s) if n_fig >= 1 else None
    m["tracking_error_rms_deg"] = _deg(_stat(s("path_distance"), lambda a: np.sqrt(np.mean(a ** 2))))

    # forces and speed (Fig. 14)
    tf = s("tether_force")
    m["tether_force_mean_N"] = _stat(tf, np.mean)
    m["tether_force_min_N"] = _stat(tf, np.min)
    m["tether_force_max_N"] = _stat(tf, np.max)
    sp = s("speed")
    m["kite_speed_min_mps"] = _stat(sp, np.min)
    m["kite_speed_max_mps"] = _stat(sp, np.max)
    m["kite_speed_mean_mps"] = _stat(sp, np.mean)

    # aerodynamics (Fig. 12, 17)
    ld = s("lift_to_drag")
    m["lift_to_drag_min"] = _stat(ld, np.min)
    m["lift_to_drag_max"] = _stat(ld, np.max)
    m["lift_to_drag_mean"] = _stat(ld, np.mean)
    alpha = s("alpha")
    n_sec = alpha.shape[1] if alpha.ndim == 2 else 0
    a_mid = alpha[:, n_sec // 2] if n_sec else np.empty(0)
    a_left = alpha[:, -1] if n_sec else np.empty(0)
    a_right = alpha[:, 0] if n_sec else np.empty(0)
    m["alpha_mid_mean_deg"] = _deg(_stat(a_mid, np.mean))
    m["alpha_mid_min_deg"] = _deg(_stat(a_mid, np.min))
    m["alpha_mid_max_deg"] = _deg(_stat(a_mid, np.max))
    m["alpha_left_min_deg"] = _deg(_stat(a_left, np.min))
    m["alpha_left_max_deg"] = _deg(_stat(a_left, np.max))
    m["alpha_right_min_deg"] = _deg(_stat(a_right, np.min))
    m["alpha_right_max_deg"] = _deg(_stat(a_right, np.max))

    # control (Eq. 18, Fig. 15-16)
    mu = s("mu")
    m["force_ratio_mu_min"] = _stat(mu, np.min)
    m["force_ratio_mu_max"] = _stat(mu, np.max)
    T_lines = s("line_tension")
    m["steering_line_slack_fraction"] = _num(np.mean(np.min(T_lines[:, [1, 3]], axis=1) < SLACK_LINE_N)) \
        if T_lines.ndim == 2 and len(T_lines) else None
    steer = s("steering_input")
    m["steering_input_max_m"] = _stat(steer, lambda a: np.max(np.abs(a)))
    upper = s("elevation") > math.radians(cfg.trajectory.elevation_deg)
    corr, slope, _, n_fit = yaw_steering_fit(steer, s("omega_k")[:, 2], upper)
    m["yaw_rate_steering_corr"] = corr
    m["yaw_rate_steering_slope_deg_s_per_m"] = slope
    m["yaw_rate_steering_samples"] = n_fit
    # the same fit with the rate of the heading, the paper's yaw angle (Sect. III), for Fig. 16
    corr, slope, _, _ = yaw_steering_fit(steer, heading_rate(t, s("psi")), upper)
    m["heading_rate_steering_corr"] = corr
    m["heading_rate_steering_slope_deg_s_per_m"] = slope
    m["heading_rate_mean_deg_s"] = _deg(heading_rate_mean(t, s("psi")))

    # wing deformation (Fig. 18)
    td = s("tip_distance")
    design_td = _num(meta.get("design_tip_distance_m"))
    td_mean = _stat(td, np.mean)
    m["tip_distance_reduction_mean_m"] = (design_td - td_mean) if design_td is not None and td_mean is not None \
        else None
    m["tip_distance_variation_m"] = _stat(td, np.ptp)
    tl, tr = s("tip_disp_left"), s("tip_disp_right")
    m["tip_displacement_left_mean_m"] = _stat(tl, np.mean)
    m["tip_displacement_right_mean_m"] = _stat(tr, np.mean)
    m["tip_displacement_left_variation_m"] = _stat(tl, np.ptp)
    m["tip_displacement_right_variation_m"] = _stat(tr, np.ptp)
    # the paper's Fig. 18: the transverse (y_k) displacement of the bridle points A, B, C, D from the design; a
    # tip's variation (Sect. IV: "varies in total by 0.3 m") is the larger of its two points' (A, B right; C, D left)
    by = s("bridle_y") if "bridle_y" in log.series else np.empty((0, 4))  # (older logs have none)
    var = {name: _stat(by[:, j], np.ptp) for j, name in enumerate("ABCD")}
    for name, v in var.items():
        m[f"bridle_{name}_y_variation_m"] = v
    for side, pts in (("right", "AB"), ("left", "CD")):
        vals = [var[p] for p in pts if var[p] is not None]
        m[f"tip_{side}_bridle_y_variation_m"] = max(vals) if vals else None

    # numerics
    m["newton_iters_mean"] = _stat(s("newton_iters"), np.mean)
    wt = _series(log, "wall_time").copy()
    if wt.size:
        wt[0] = np.nan  # row 0 is the initial state: no step was taken
    m["wall_time_per_step_ms_median"] = _stat(wt[win] * 1e3, np.median)
    m["constraint_drift_max_m"] = _stat(np.abs(s("constraint_drift")), np.max)
    # physics steps made in halves because the wing failed at the full step (FlightSimulator.step), whole flight
    m["substepped_steps"] = int(np.sum(_series(log, "substeps") > 1)) if "substeps" in log.series else None

    # ground station (dynamics.winch): tether length, reel-out speed and the mechanical power F_t v_r at the drum
    if "tether_length" in log.series:
        v_r = s("reel_speed")
        m["tether_length_end_m"] = _num(_series(log, "tether_length")[-1])
        m["reel_out_speed_mean_mps"] = _stat(v_r, np.mean)
        m["reel_out_power_mean_W"] = _stat(tf * v_r, np.mean)

    m["paper_comparison"] = paper_comparison(m)
    return m


def paper_comparison(m: dict) -> list[dict]:
    """Model against the paper's Sect. IV numbers (:data:`PAPER_VALUES`) from a metrics dict."""

    def pair(lo, hi, scale=1.0):
        return [None if lo is None else lo * scale, None if hi is None else hi * scale]

    model = {
        "tether_force": pair(m["tether_force_min_N"], m["tether_force_max_N"], 1e-3),
        "lift_to_drag": pair(m["lift_to_drag_min"], m["lift_to_drag_max"]),
        "alpha_mid": m["alpha_mid_mean_deg"],
        "speed": pair(m["kite_speed_min_mps"], m["kite_speed_max_mps"]),
        "mu": pair(m["force_ratio_mu_min"], m["force_ratio_mu_max"]),
        "tip_reduction": m["tip_distance_reduction_mean_m"],
        "tip_variation_left": m.get("tip_left_bridle_y_variation_m"),
        "tip_variation_right": m.get("tip_right_bridle_y_variation_m"),
        "heading_rate_slope": (None if m.get("heading_rate_steering_slope_deg_s_per_m") is None
                               else math.radians(m["heading_rate_steering_slope_deg_s_per_m"])),
    }
    return [{"quantity": q, "model": model[key], "paper": list(p) if isinstance(p, tuple) else p, "unit": unit,
             "source": src} for key, q, p, unit, src in PAPER_VALUES]


# ------------------------------------------------------------------------------------------------ export
def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


def csv_columns(log: FlightLog) -> dict[str, np.ndarray]:
    """Columns of ``timeseries.csv``: every (n,) series, then alpha mid/left/right, line tensions A-D, KCU x/y/z."""
    cols = {k: np.asarray(v, dtype=float) for k, v in log.series.items() if np.ndim(v) == 1}
    alpha = log.series.get("alpha")
    if alpha is not None and np.ndim(alpha) == 2 and alpha.shape[1]:
        cols["alpha_mid"] = alpha[:, alpha.shape[1] // 2]
        cols["alpha_left"] = alpha[:, -1]
        cols["alpha_right"] = alpha[:, 0]
    lt = log.series.get("line_tension")
    if lt is not None and np.ndim(lt) == 2 and lt.shape[1] == 4:
        for i, name in enumerate("ABCD"):
            cols[f"line_tension_{name}"] = lt[:, i]
    r = log.series.get("r")
    if r is not None and np.ndim(r) == 3 and r.shape[1] >= 5:
        for i, c in enumerate("xyz"):
            cols[f"kcu_{c}"] = r[:, 4, i]
    return cols


def write_timeseries(log: FlightLog, out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``timeseries.npz`` and ``timeseries.csv`` into ``out_dir``; returns their paths.

    NPZ: every series under its own name, snapshots as ``snapshot_<name>``, and ``meta`` as a JSON string.
    CSV: header row of column names (:func:`csv_columns`), values in SI units (angles in rad), ``%.9g``.
    """
    out = Path(out_dir)
    npz = out / "timeseries.npz"
    arrays = {k: np.asarray(v) for k, v in log.series.items()}
    arrays.update({f"snapshot_{k}": np.asarray(v) for k, v in log.snapshots.items()})
    arrays["meta"] = np.array(json.dumps(log.meta, default=_json_default))
    with open(npz, "wb") as fh:  # a file handle keeps numpy from appending '.npz' to the name
        np.savez_compressed(fh, **arrays)
    csv = out / "timeseries.csv"
    cols = csv_columns(log)
    table = np.column_stack(list(cols.values())) if cols else np.empty((0, 0))
    np.savetxt(csv, table, fmt="%.9g", delimiter=",", header=",".join(cols), comments="")
    return npz, csv


def read_timeseries(path: str | Path) -> FlightLog:
    """Read a ``timeseries.npz`` written by :func:`write_timeseries` back into a FlightLog."""
    with np.load(path, allow_pickle=False) as data:
        series, snaps, meta = {}, {}, {}
        for k in data.files:
            if k == "meta":
                meta = json.loads(str(data[k]))
            elif k.startswith("snapshot_"):
                snaps[k[len("snapshot_"):]] = data[k]
            else:
                series[k] = data[k]
    return FlightLog(series=series, meta=meta, snapshots=snaps)
