"""``kite-polar``: aeroelastic polar of a kite (angle-of-attack sweep at fixed airspeed).

Example::

    kite-polar --kite rhino16 --airspeed 25 --alpha-deg -5:20:1 --out runs/polar_rhino16

writes ``polar.csv`` (columns in :data:`kite_env.polar.POLAR_COLUMNS`), ``polar.png`` (CL, CD, L/D, CM against the
kite angle of attack) and ``wing.png`` (deformed against unloaded wing at the angle of best L/D), plus
``polar.json`` with the settings. Files are written to temporary names and renamed only when the sweep is done, so
an interrupted or failed run leaves nothing half-written. Bad input exits with status 2 and one message.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="kite-polar", description=__doc__.split("\n\n")[0])
    p.add_argument("--kite", default="rhino16", help="kite geometry: rhino16 (default) or v3")
    p.add_argument("--airspeed", type=float, default=25.0, help="apparent wind speed [m/s] (default 25)")
    p.add_argument("--alpha-deg", default="-5:20:1", help="kite angles of attack START:STOP:STEP [deg]")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    p.add_argument("--config", default=None, help="YAML config file (default: built-in defaults)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a config value (repeatable)")
    p.add_argument("--support", choices=("lines", "prescribed"), default="lines",
                   help="bridle support: 'lines' (tips free to move in y_k, default) or 'prescribed'")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    return p


def _fail(msg: str) -> int:
    print(f"kite-polar: error: {msg}", file=sys.stderr)
    return 2


def _write_all(out: Path, writers: dict) -> None:
    """Write every file to a temporary name first, rename them only when all succeeded."""
    tmps = {}
    try:
        for name, writer in writers.items():
            fd, tmp = tempfile.mkstemp(dir=out, prefix=f".{name}.", suffix=".tmp")
            os.close(fd)
            tmps[name] = tmp
            writer(tmp)
        for name, tmp in tmps.items():
            os.replace(tmp, out / name)
    finally:
        for tmp in tmps.values():
            if os.path.exists(tmp):
                os.remove(tmp)


def _plots(points, wing, out: Path, title: str) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = np.array([p.alpha_deg for p in points])
    ok = np.array([p.converged for p in points])
    fig, ax = plt.subplots(2, 2, figsize=(10, 7), constrained_layout=True)
    for axi, key, lab in ((ax[0, 0], "CL", "$C_L$"), (ax[0, 1], "CD", "$C_D$"),
                          (ax[1, 0], "L_over_D", "L/D"), (ax[1, 1], "CM", "$C_M$ (about $r_k$)")):
        axi.plot(a[ok], [getattr(p, key) for p in np.array(points)[ok]], "o-", ms=3)
        axi.set_xlabel(r"kite angle of attack $\alpha_k$ [deg]")
        axi.set_ylabel(lab)
        axi.grid(alpha=0.3)
    fig.suptitle(title)
    figs = {}

    def save_polar(tmp):
        fig.savefig(tmp, format="png", dpi=110)

    figs["polar.png"] = save_polar
    conv = [p for p in points if p.converged]
    best = max(conv, key=lambda p: p.L_over_D) if conv else None
    fig2 = None
    if best is not None:
        fig2 = plt.figure(figsize=(10, 5), constrained_layout=True)
        mesh = wing.mesh
        for k, (el, az) in enumerate(((20, -60), (0, -90))):
            ax3 = fig2.add_subplot(1, 2, k + 1, projection="3d")
            for X, style, lab in ((mesh.nodes, dict(color="0.6", lw=0.6), "unloaded"),
                                  (best.nodes, dict(color="C0", lw=0.8), f"loaded, alpha_k = {best.alpha_deg:g} deg")):
                tri = mesh.shells
                ax3.plot_trisurf(X[:, 0], X[:, 1], X[:, 2], triangles=tri, alpha=0.25 if lab == "unloaded" else 0.5,
                                 color=style["color"])
                for b in mesh.beams:
                    ax3.plot(*X[b].T, color=style["color"], lw=style["lw"])
            ax3.set_xlabel("$x_k$ [m]")
            ax3.set_ylabel("$y_k$ [m]")
            ax3.set_zlabel("$z_k$ [m]")
            ax3.view_init(elev=el, azim=az)
            ax3.set_box_aspect(np.ptp(mesh.nodes, axis=0) + 1e-3)
        fig2.suptitle(f"deformed (blue) and unloaded (grey) wing at best L/D, alpha_k = {best.alpha_deg:g} deg")

        def save_wing(tmp):
            fig2.savefig(tmp, format="png", dpi=110)

        figs["wing.png"] = save_wing
    return figs


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from kite_env.config import ConfigError, load_config
    from kite_env.fsi import nominal_wing
    from kite_env.polar import POLAR_COLUMNS, parse_alpha_range, sweep

    try:
        alphas = parse_alpha_range(args.alpha_deg)
    except ValueError as exc:
        return _fail(str(exc))
    if not (np.isfinite(args.airspeed) and args.airspeed > 0):
        return _fail(f"--airspeed must be a positive number [m/s], got {args.airspeed}")
    if args.airspeed > 80:
        return _fail(f"--airspeed {args.airspeed} m/s is outside the model's range (at most 80 m/s)")
    if args.config is not None and not Path(args.config).is_file():
        return _fail(f"--config file {args.config!r} does not exist")
    try:
        cfg = load_config(args.config, args.overrides)
    except ConfigError as exc:
        return _fail(str(exc))
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        return _fail(f"--out {str(out)!r} exists and is not a folder")
    try:
        wing = nominal_wing(args.kite, cfg)
    except ValueError as exc:  # unknown kite name or invalid geometry parameters
        return _fail(str(exc))

    def progress(p):
        if not args.quiet:
            status = (f"CL={p.CL:6.3f} CD={p.CD:6.3f} L/D={p.L_over_D:5.2f} tip={p.tip_distance_m:5.3f} m "
                      f"iters={p.coupling_iterations}" if p.converged else f"FAILED: {p.message}")
            print(f"  alpha_k = {p.alpha_deg:6.2f} deg  {status}", flush=True)

    if not args.quiet:
        print(f"kite-polar: {args.kite}, {wing.mesh.n_nodes} nodes, V = {args.airspeed:g} m/s, "
              f"{len(alphas)} angles", flush=True)
    points = sweep(wing, args.airspeed, alphas, support=args.support, progress=progress)
    out.mkdir(parents=True, exist_ok=True)

    def write_csv(tmp):
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(POLAR_COLUMNS)
            for p in points:
                w.writerow([f"{v:.6g}" if isinstance(v, float) else int(v) if isinstance(v, (bool, np.bool_))
                            else v for v in p.row()])

    def write_json(tmp):
        from kite_env.polar import reference_values

        area, c_ref = reference_values(wing)
        with open(tmp, "w") as fh:
            json.dump({"kite": args.kite, "airspeed_mps": args.airspeed, "support": args.support,
                       "reference_area_m2": area, "reference_chord_m": c_ref,
                       "n_converged": int(sum(p.converged for p in points)), "n_points": len(points),
                       "failures": {f"{p.alpha_deg:g}": p.message for p in points if not p.converged}},
                      fh, indent=2)

    figs = _plots(points, wing, out, f"{args.kite} aeroelastic polar, V = {args.airspeed:g} m/s")
    writers = {"polar.csv": write_csv, "polar.json": write_json, **figs}
    _write_all(out, writers)
    if not args.quiet:
        print(f"kite-polar: wrote {', '.join(writers)} to {out}")
    return 0 if any(p.converged for p in points) else 1


if __name__ == "__main__":
    sys.exit(main())
