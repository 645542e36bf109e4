"""Open-loop steering authority of the full model: yaw rate per steering input at a few wind speeds.

    python analyses/turn_rate.py [--dl=-0.2,0.1,0.2,0.3] [--wind 5,7] [--no-force-loop] [--set section.key=value ...]

Measures the neutral-subtracted yaw rate ``omega_k . z_k`` per held steering-line difference dL = L_B - L_D, flown
open loop from the figure's crossing (:func:`kite_env.analysis.turn_rate.turn_rate_table`), with the paper's force
controller on the common rest length (``--no-force-loop``: both held): about 5 rad/s per m in the paper's Fig. 16,
2.5-5 in V3 flight data. (The rate of the heading on the tangent plane is not a measure here: the neutral flight
climbs towards the zenith, where the heading's reference turns fast.) Prints one row per wind speed and input: the
yaw rate, its rate per metre, the airspeed, the smaller steering-line tension and how the flight ended.

Reported in docs/steering.md, "Summary" and "The open-loop turn rate" (also "Where a steering input goes", "The von
Karman membrane") and docs/model.md, "Theodorsen's force" and "The ground station". Not run in CI;
tests/dynamics/test_flight_model.py flies the same table.
"""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    from kite_env.analysis.turn_rate import turn_rate_table
    from kite_env.config import ConfigError, load_config

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dl", default="-0.2,0.1,0.2,0.3",
                   help="held inputs L_B - L_D [m], comma separated (write --dl=-0.2,0.1 when the first is negative)")
    p.add_argument("--wind", default="5", help="wind speeds [m/s], comma separated")
    p.add_argument("--no-force-loop", action="store_true",
                   help="hold both rest lengths (no force controller; a steering line can go slack in the window)")
    p.add_argument("--set", action="append", default=[], help="config override section.key=value (repeatable)")
    args = p.parse_args(argv)
    try:
        cfg = load_config(None, args.set)
        dls = [float(x) for x in args.dl.split(",")]
        winds = [float(x) for x in args.wind.split(",")]
    except (ConfigError, ValueError) as exc:
        print(f"turn_rate: {exc}", file=sys.stderr)
        return 2
    if any(d == 0.0 for d in dls):
        print("turn_rate: --dl must not contain 0 (the neutral flight is subtracted)", file=sys.stderr)
        return 2
    rows = turn_rate_table(cfg, dls, winds, force_loop=not args.no_force_loop)
    print(f"{'wind [m/s]':>10} {'dL [m]':>7} {'yaw rate [rad/s]':>17} {'per dL [rad/s/m]':>17} {'airspeed [m/s]':>15} "
          f"{'line min [N]':>13}  end")
    for r in rows:
        print(f"{r['wind_mps']:10.1f} {r['dl_m']:7.2f} {r['yaw_rate_rad_s']:17.3f} {r['per_m']:17.2f} "
              f"{r['airspeed_mps']:15.1f} {r['steering_line_min_N']:13.0f}  {r['end']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
