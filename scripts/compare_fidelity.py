"""Fly the baseline figure-eight with the full model (``fe``) and the reduced-order wing (``surrogate``) from the same
start and compare them (issue 5, flight agreement).

    python scripts/compare_fidelity.py --out runs/fidelity [--duration 60] [--start fe|table] [--set k=v ...]

Both flights are ``kite-eval``'s (the environment in evaluation conditions, the paper's controller). Writes
``fidelity.md`` / ``fidelity.json`` (metrics of both over the time both flew, and of each whole flight) and
``fidelity.png`` (path on the sphere and tether force of both, overlaid).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _window_metrics(log, t_end: float, warmup: float) -> dict:
    t = np.asarray(log.series["t"])
    sel = (t >= warmup) & (t <= t_end)
    F = np.asarray(log.series["tether_force"])[sel]
    d = np.asarray(log.series["path_distance"])[sel]
    return {"window_s": [warmup, t_end], "tether_force_mean_N": float(np.nanmean(F)),
            "tracking_error_rms_deg": float(np.degrees(np.sqrt(np.mean(d**2))))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--start", choices=("fe", "table"), default="fe", help="start of the surrogate flight")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.baseline import BaselineAgent
    from kite_env.config import ConfigError, load_config
    from kite_env.envs.figure_eight import KiteFigureEightEnv
    from kite_env.flight import evaluation_config, run_episode
    from kite_env.metrics import compute_metrics

    try:
        cfg = load_config(None, [*args.set, f"sim.duration_s={args.duration!r}",
                                 f"sim.surrogate_start={args.start}"])
    except ConfigError as exc:
        print(f"compare_fidelity: error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logs, whole = {}, {}
    for fid in ("fe", "surrogate"):
        env = KiteFigureEightEnv(config=evaluation_config(cfg), fidelity=fid)
        log, info = run_episode(env, BaselineAgent(env.cfg), seed=cfg.wind.seed,
                                options={"wind_seed": cfg.wind.seed})
        logs[fid] = log
        m = compute_metrics(log, env.cfg)
        whole[fid] = {k: m[k] for k in ("sim_time_s", "termination_reason", "figure_eights_completed",
                                        "tether_force_mean_N", "tracking_error_rms_deg", "wall_time_s")}
        env.close()
    t_end = min(whole[f]["sim_time_s"] for f in logs)
    warmup = min(cfg.sim.warmup_s, 0.5 * t_end)
    common = {f: _window_metrics(logs[f], t_end, warmup) for f in logs}
    rel = common["surrogate"]["tether_force_mean_N"] / common["fe"]["tether_force_mean_N"] - 1.0
    dtrack = common["surrogate"]["tracking_error_rms_deg"] - common["fe"]["tracking_error_rms_deg"]
    result = {"whole_flight": whole, "common_window": common, "traction_rel_diff": rel,
              "tracking_error_diff_deg": dtrack, "start": args.start}
    (out / "fidelity.json").write_text(json.dumps(result, indent=2))
    lines = ["| quantity | fe | surrogate |", "|---|---|---|"]
    for k in ("sim_time_s", "termination_reason", "figure_eights_completed", "wall_time_s"):
        lines.append(f"| {k} | {whole['fe'][k]} | {whole['surrogate'][k]} |")
    for k in ("tether_force_mean_N", "tracking_error_rms_deg"):
        lines.append(f"| {k}, t = {warmup:.1f}-{t_end:.2f} s | {common['fe'][k]:.4g} | {common['surrogate'][k]:.4g} |")
    lines.append(f"\nmean traction difference {100 * rel:+.2f} %, tracking error difference {dtrack:+.3f} deg")
    (out / "fidelity.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for fid, style in (("fe", "C0-"), ("surrogate", "C3--")):
        s = logs[fid].series
        r = np.asarray(s["r"])[:, 4]
        az, el = np.degrees(np.arctan2(r[:, 1], r[:, 0])), np.degrees(np.arcsin(r[:, 2] / np.linalg.norm(r, axis=1)))
        a1.plot(az, el, style, lw=1.2, label=fid)
        a2.plot(s["t"], np.asarray(s["tether_force"]) * 1e-3, style, lw=1.0, label=fid)
    from kite_env.trajectory import Lemniscate

    P = Lemniscate(cfg.trajectory).point(np.linspace(0, 2 * np.pi, 400))
    a1.plot(np.degrees(np.arctan2(P[:, 1], P[:, 0])), np.degrees(np.arcsin(P[:, 2])), "k:", lw=0.8, label="path")
    a1.invert_xaxis()
    a1.set_xlabel("azimuth [deg]")
    a1.set_ylabel("elevation [deg]")
    a1.legend(fontsize=8)
    a2.set_xlabel("t [s]")
    a2.set_ylabel("tether force [kN]")
    a2.legend(fontsize=8)
    fig.suptitle("Baseline flight: full aeroelastic model (fe) and reduced-order wing (surrogate), same start")
    fig.tight_layout()
    fig.savefig(out / "fidelity.png", dpi=110)
    print(f"compare_fidelity: wrote {out}/fidelity.md, fidelity.json, fidelity.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
