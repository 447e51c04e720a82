#!/usr/bin/env python3
"""bench_dem — the DEM simulators as the anchor of the simulator's speed: the same single-ball
drop, the same Hertz law, in bouncecal and in LAMMPS, LIGGGHTS and Yade (whichever are on PATH),
as whole processes, with each one's error in e against the exact answer.

    python3 tools/bench_dem.py                          # 30 impacts, every simulator on PATH
    python3 tools/bench_dem.py --impacts 10 --simulators lammps --dt-e-errors 5e-4 5e-5 5e-6

The drop: a 1 cm steel ball (the seed paper's, 0.2 m) under Hertz-Tsuji with e = 0.9. Its
parameter file comes the way a user gets one: `bouncecal synth` renders the drop and `bouncecal
calibrate --law hertz-tsuji` fits it. The exact answer is `bouncecal simulate --params P --rtol
1e-12` (every contact located, errors ~1e-12). Each DEM run is the deck `bouncecal export P --to
SIM --impacts N --dt-e-error X` writes, run by its own `run.sh` (the simulator, then impacts.csv
from its trace); its e per bounce is v_out / v_in there. The DEM simulators step with a fixed
time step, which the export sets from X: the largest e error the step may cost on one contact.
bouncecal runs `simulate --params P --max-impacts N` at rtol 1e-6 and the default 1e-9.

Times are whole processes (wall and the child's user + system CPU from wait4): the median of
--repeat runs for bouncecal (a few ms each), one run for each DEM deck (seconds each). The last
column is the DEM's CPU time over bouncecal's at the default rtol. Prints one Markdown table.
"""
import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

SIMULATORS = {"lammps": "lmp", "liggghts": "liggghts", "yade": "yade"}


def run(cmd, cwd=None):
    """Runs cmd; returns (wall_s, cpu_s, stdout). Exits naming the command when it fails."""
    start = time.monotonic()
    p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = p.communicate()
    wall = time.monotonic() - start
    if p.returncode != 0:
        sys.exit("bench_dem: %s failed (exit %d): %s" %
                 (" ".join(cmd), p.returncode, err.decode(errors="replace").strip()[-400:]))
    return wall, out.decode()


def timed(cmd, cwd=None):
    """Wall and CPU (user + system of the child and its children) of one run, and its stdout."""
    def children_cpu():
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    before = children_cpu()
    wall, out = run(cmd, cwd)
    return wall, children_cpu() - before, out


def fit_params(bouncecal, work):
    """The parameter file of the drop: rendered with Hertz-Tsuji e = 0.9 and fitted back."""
    wav = os.path.join(work, "drop.wav")
    params = os.path.join(work, "params.json")
    run([bouncecal, "synth", "--law", "hertz-tsuji", "--set", "e=0.9", "--height", "0.2",
         "--seed", "7", "-o", wav])
    run([bouncecal, "calibrate", wav, "--law", "hertz-tsuji", "--diameter", "0.01", "--material",
         "steel", "--height", "0.2", "--contact-duration", "--quiet", "-o", params])
    return params


def simulated_e(bouncecal, params, impacts, rtol):
    _, out = run([bouncecal, "simulate", "--params", params, "--max-impacts", str(impacts),
                  "--rtol", repr(rtol), "--json"])
    return [imp["e"] for imp in json.loads(out)["impacts"]]


def csv_e(path):
    with open(path) as f:
        rows = [line.strip().split(",") for line in f.readlines()[1:] if line.strip()]
    return [float(r[3]) / float(r[2]) for r in rows]


def max_error(e, exact):
    n = min(len(e), len(exact))
    return max(abs(a - b) for a, b in zip(e[:n], exact[:n])), n


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bouncecal", default="build/bouncecal")
    ap.add_argument("--impacts", type=int, default=30)
    ap.add_argument("--simulators", nargs="+", default=list(SIMULATORS),
                    choices=list(SIMULATORS))
    ap.add_argument("--dt-e-errors", nargs="+", type=float, default=[5e-4, 5e-5],
                    help="the export's --dt-e-error values to run (LAMMPS and LIGGGHTS)")
    ap.add_argument("--yade-dt-e-errors", nargs="+", type=float, default=[5e-4],
                    help="Yade's, fewer: it takes ~8 us per step")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    bouncecal = os.path.abspath(args.bouncecal)
    if not os.access(bouncecal, os.X_OK):
        sys.exit("bench_dem: %s: not an executable (build the project first)" % bouncecal)

    work = tempfile.mkdtemp(prefix="bench_dem_")
    try:
        params = fit_params(bouncecal, work)
        exact = simulated_e(bouncecal, params, args.impacts, 1e-12)
        rows = []
        base_cpu = None
        for rtol in (1e-6, 1e-9):
            cmd = [bouncecal, "simulate", "--params", params, "--max-impacts", str(args.impacts),
                   "--rtol", repr(rtol), "--json"]
            runs = [timed(cmd) for _ in range(args.repeat)]
            wall = statistics.median(r[0] for r in runs)
            cpu = statistics.median(r[1] for r in runs)
            e = [imp["e"] for imp in json.loads(runs[0][2])["impacts"]]
            steps = sum(imp["steps"] for imp in json.loads(runs[0][2])["impacts"])
            err, n = max_error(e, exact)
            if rtol == 1e-9:
                base_cpu = cpu
            rows.append(["bouncecal", "rtol %g%s" % (rtol, " (default)" if rtol == 1e-9 else ""),
                         "located", "%d" % steps, wall, cpu, n, err])
        for sim in args.simulators:
            if shutil.which(SIMULATORS[sim]) is None:
                rows.append([sim, "not on PATH", "", "", None, None, 0, None])
                continue
            errors = args.yade_dt_e_errors if sim == "yade" else args.dt_e_errors
            for x in errors:
                deck = os.path.join(work, "%s_%g" % (sim, x))
                _, out = run([bouncecal, "export", params, "--to", sim, "-o", deck, "--impacts",
                              str(args.impacts), "--dt-e-error", repr(x), "--json"])
                mapping = json.loads(out)
                wall, cpu, _ = timed([os.path.join(deck, "run.sh")])
                err, n = max_error(csv_e(os.path.join(deck, "impacts.csv")), exact)
                rows.append([sim, "dt-e-error %g (%s)" % (x, mapping["mapping"]),
                             "%.3g s" % mapping["time_step_s"], "%d" % mapping["steps"], wall,
                             cpu, n, err])
        print("| program | setting | time step | steps | wall (s) | CPU (s) | impacts | "
              "max abs error in e | CPU / bouncecal |")
        print("|---|---|---|---|---|---|---|---|---|")
        for name, setting, step, steps, wall, cpu, n, err in rows:
            if wall is None:
                print("| %s | %s | | | | | | | |" % (name, setting))
                continue
            print("| %s | %s | %s | %s | %.3f | %.3f | %d | %.2e | %.0f |" %
                  (name, setting, step, steps, wall, cpu, n, err, cpu / base_cpu))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
