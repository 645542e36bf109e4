"""Why episodes end: run ``kite-eval`` over many randomized episodes and count the end reasons (issue 20's check).

    python scripts/end_reasons.py --episodes 50 --duration 30 --jobs 2 --out runs/end_reasons [--policy random]
        [--set section.key=value ...]

The episodes are those of ``kite-eval --randomize`` (wind, turbulence and start drawn per episode from the env
section's ranges; by default winds 4-10 m/s, turbulence up to 0.15 and starts anywhere on the figure-eight, set
below, each overridable with ``--set``), split over ``--jobs`` processes by their seeds (episode ``i`` has seed
``seed + i`` whichever process flies it). Writes ``episodes.csv`` (all episodes) and ``end_reasons.md`` (the table)
under ``--out`` and prints the table. A numerical end ("wing did not converge", "non-finite ...") is a bug of the
simulator; ground contact and (on the paper's rod tether) a slack tether are physical ends. A drawn start whose wing
does not converge is drawn again by the env; the table's last line counts those failed starts.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
from collections import Counter
from pathlib import Path

NUMERICAL = ("wing did not converge", "non-finite particle state", "non-finite state")
RANGES = ["env.wind_speed_min_mps=4", "env.wind_speed_max_mps=10", "env.turbulence_intensity_max=0.15",
          "env.random_start=true"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--policy", default="random")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = p.parse_args(argv)
    if args.episodes < 1 or args.jobs < 1 or args.duration <= 0:
        p.error("--episodes and --jobs must be >= 1 and --duration > 0")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    exe = str(Path(sys.executable).with_name("kite-eval"))
    sets = [a for s in RANGES + args.set for a in ("--set", s)]
    jobs = min(args.jobs, args.episodes)
    bounds = [args.episodes * j // jobs for j in range(jobs + 1)]  # contiguous seeds per process
    procs = []
    for j in range(jobs):
        d = out / f"shard{j}"
        cmd = [exe, "--policy", args.policy, "--episodes", str(bounds[j + 1] - bounds[j]), "--duration",
               str(args.duration), "--randomize", "--seed", str(args.seed + bounds[j]), "--out", str(d), "--force",
               "--quiet", *sets]
        procs.append((d, subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=open(out / f"shard{j}.log", "w"))))
    rows = []
    for d, proc in procs:
        if proc.wait() != 0:
            print(f"end_reasons: kite-eval failed in {d} (see {d}.log)", file=sys.stderr)
            return 1
        with open(d / "episodes.csv") as fh:
            rows += list(csv.DictReader(fh))
    rows.sort(key=lambda r: int(r["seed"]))
    with open(out / "episodes.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    reasons = Counter(r["termination_reason"] or "time limit" for r in rows)
    lines = [f"{len(rows)} episodes of {args.duration:g} s, policy {args.policy}, "
             f"`{' '.join(RANGES + args.set)}`", "",
             "| end | episodes | kind | median end [s] | shortest [s] |", "|---|---:|---|---:|---:|"]
    for reason, n in reasons.most_common():
        t = sorted(float(r["sim_time_s"]) for r in rows if (r["termination_reason"] or "time limit") == reason)
        kind = "numerical (a bug)" if reason in NUMERICAL else ("none" if reason in ("time limit", "completed")
                                                                  else "physical")
        lines.append(f"| {reason} | {n} | {kind} | {t[len(t) // 2]:.2f} | {t[0]:.2f} |")
    winds = sorted(float(r["wind_speed_mps"]) for r in rows)
    # a start that does not converge is drawn again by the env (env.reset_attempts): numerical too, counted here
    failed = sum(int(r.get("failed_starts") or 0) for r in rows)
    lines += ["", f"wind {winds[0]:.1f}-{winds[-1]:.1f} m/s; starts that did not converge (drawn again): {failed}"]
    text = "\n".join(lines)
    (out / "end_reasons.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
