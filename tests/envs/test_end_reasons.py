"""scripts/end_reasons.py (its count of why episodes end), with a stand-in ``kite-eval``.

The script runs one ``kite-eval`` per episode (the executable next to ``sys.executable``). A stand-in written here
answers each seed as the real one would: an episode's ``episodes.csv`` and exit 0, or, for a numerical failure of
the wing with inertia, kite-eval's error line and exit 3 (``NumericalFailure``; tests/test_eval_cli.py checks that
line against the real kite-eval). What is checked is the script's own logic: the count, the kind, the time and wind
of a failure read from the error line, its kept log, and the exit status.
"""

from __future__ import annotations

import csv
import os
import stat
import sys
from pathlib import Path

import pytest

STAND_IN = """#!{python}
import sys
from pathlib import Path
args = sys.argv[1:]
seed = int(args[args.index("--seed") + 1])
out = Path(args[args.index("--out") + 1])
if seed == {failing}:
    sys.stderr.write("kite-eval: error: numerical failure at t = 7.2500 s (wind 8.123 m/s, turbulence 0.1000, wind "
                     "seed 5, start s 0.1000, start speed 33.000 m/s): wing did not converge: forced; "
                     "nothing written\\n"
                     "this is a bug of the simulator, not an end of the flight\\nresidual history (last 1): test\\n")
    sys.exit(3)
if seed == {broken}:
    sys.stderr.write("kite-eval: error: something else\\n")
    sys.exit(1)
out.mkdir(parents=True)
reason = "ground" if seed % 2 else ""
(out / "episodes.csv").write_text(
    "episode,seed,wind_speed_mps,termination_reason,sim_time_s,failed_starts\\n"
    f"0,{{seed}},{{4 + seed % 7}},{{reason}},{{3.5 if reason else 30.0}},0\\n")
"""


@pytest.fixture()
def stand_in(tmp_path, monkeypatch):
    """A folder with a ``python`` (this interpreter) and a stand-in ``kite-eval``, made ``sys.executable``'s folder."""

    def make(failing: int = -1, broken: int = -1) -> None:
        bin_dir = tmp_path / "bin"
        bin_dir.mkdir(exist_ok=True)
        exe = bin_dir / "kite-eval"
        exe.write_text(STAND_IN.format(python=sys.executable, failing=failing, broken=broken))
        exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
        python = bin_dir / "python"
        if not python.exists():
            os.symlink(sys.executable, python)
        monkeypatch.setattr(sys, "executable", str(python))

    return make


def _rows(out: Path) -> list[dict]:
    with open(out / "episodes.csv") as fh:
        return list(csv.DictReader(fh))


def test_a_numerical_failure_is_counted_with_its_time_and_wind_and_the_script_exits_3(load_script, stand_in,
                                                                                      tmp_path, capsys):
    stand_in(failing=301)
    out = tmp_path / "er"
    rc = load_script("end_reasons").main(["--episodes", "4", "--duration", "30", "--jobs", "2", "--seed", "300",
                                          "--out", str(out)])
    assert rc == 3
    rows = _rows(out)
    assert [int(r["seed"]) for r in rows] == [300, 301, 302, 303]
    failed = rows[1]
    assert failed["termination_reason"] == "numerical failure"
    assert (float(failed["sim_time_s"]), float(failed["wind_speed_mps"])) == (7.25, 8.123)
    assert "residual history (last 1): test" in (out / "failures" / "seed_301.log").read_text()
    table = (out / "end_reasons.md").read_text()
    assert "| numerical failure | 1 | numerical (a bug) | 7.25 | 7.25 |" in table
    assert "| ground | 1 | physical | 3.50 | 3.50 |" in table  # seed 303 (301 failed)
    assert "| time limit | 2 | none | 30.00 | 30.00 |" in table
    assert table in capsys.readouterr().out + "\n"


def test_without_a_failure_the_script_exits_0_and_another_kite_eval_error_stops_it(load_script, stand_in, tmp_path,
                                                                                   capsys):
    stand_in()
    out = tmp_path / "ok"
    assert load_script("end_reasons").main(["--episodes", "3", "--jobs", "1", "--seed", "10", "--out", str(out)]) == 0
    assert not (out / "failures").exists() and len(_rows(out)) == 3
    stand_in(broken=11)
    assert load_script("end_reasons").main(["--episodes", "3", "--jobs", "1", "--seed", "10", "--out",
                                            str(tmp_path / "broken")]) == 1
    assert "kite-eval failed for seed 11 (exit 1" in capsys.readouterr().err
