"""Why episodes end: run ``kite-eval`` over many randomized episodes and count the end reasons.

    python scripts/end_reasons.py --episodes 50 --duration 30 --jobs 2 --out runs/end_reasons [--policy random]
        [--set section.key=value ...]

The episodes are those of ``kite-eval --randomize`` (wind, turbulence and start drawn per episode from the env
section's ranges; by default winds 4-10 m/s, turbulence up to 0.15 and starts anywhere on the figure-eight, set
below, each overridable with ``--set``), one ``kite-eval`` process per episode, ``--jobs`` at a time (episode ``i``
has seed ``seed + i``). Writes ``episodes.csv`` (all episodes), ``end_reasons.md`` (the table) and, for an episode
that failed numerically, ``failures/seed_N.log`` (kite-eval's message with the wing solver's residual history) under
``--out`` and prints the table. With the wing with inertia (the default) a numerical failure is not an end of the
episode but an error of the simulator (``NumericalFailure``, kite-eval's exit status 3): it is counted here as
"numerical failure" at the time it happened, and the script exits with status 3. With the paper's quasi-static wing
(``--set structure.dynamic=false``) the episode ends instead ("wing did not converge", "non-finite ..."): numerical
too. Ground contact and (on the paper's rod tether) a slack tether are physical ends. A drawn start whose wing does
not converge is drawn again by the env; the table's last line counts those failed starts.
"""

from __future__ import annotations

import argparse
import csv
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

NUMERICAL = ("numerical failure", "wing did not converge", "non-finite particle state", "non-finite state")
FAILURE = re.compile(r"numerical failure at t = ([-+0-9.eE]+) s \(wind ([-+0-9.eE]+) m/s")
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
    seeds = list(range(args.seed, args.seed + args.episodes))
    running: list[tuple[int, Path, subprocess.Popen]] = []
    rows: list[dict] = []
    failures = 0

    def finish(seed: int, d: Path, proc: subprocess.Popen) -> bool:
        nonlocal failures
        err = (d.parent / f"{d.name}.log").read_text()
        if proc.returncode == 0:
            with open(d / "episodes.csv") as fh:
                rows.extend(csv.DictReader(fh))
            return True
        m = FAILURE.search(err)
        if proc.returncode == 3 and m:  # NumericalFailure: a bug of the simulator, counted and kept
            failures += 1
            (out / "failures").mkdir(exist_ok=True)
            (out / "failures" / f"seed_{seed}.log").write_text(err)
            rows.append({"episode": 0, "seed": seed, "termination_reason": "numerical failure",
                         "sim_time_s": m.group(1), "wind_speed_mps": m.group(2)})
            return True
        print(f"end_reasons: kite-eval failed for seed {seed} (exit {proc.returncode}, see {d}.log)", file=sys.stderr)
        return False

    while seeds or running:
        while seeds and len(running) < args.jobs:
            seed = seeds.pop(0)
            d = out / "episodes" / f"seed_{seed}"
            d.parent.mkdir(parents=True, exist_ok=True)
            cmd = [exe, "--policy", args.policy, "--episodes", "1", "--duration", str(args.duration), "--randomize",
                   "--seed", str(seed), "--out", str(d), "--force", "--quiet", *sets]
            with open(d.parent / f"{d.name}.log", "w") as log:
                running.append((seed, d, subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log)))
        seed, d, proc = running.pop(0)
        proc.wait()
        if not finish(seed, d, proc):
            for _, _, other in running:
                other.kill()
            return 1
    rows.sort(key=lambda r: int(r["seed"]))
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(out / "episodes.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys, restval="")
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
    return 3 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
