#!/usr/bin/env python3
"""Calibrate every recording of a folder: one CSV row per recording and one HTML report.

    PYTHONPATH=build/python python3 tools/batch_folder.py RECORDINGS_DIR \\
        --scene data/default_steel_copper.toml -o results.csv --report report.html

Each recording is fitted on its own (bouncecal.calibrate(..., batch=True)). The CSV has one row
per recording: file, status (ok | fit | error), outcome (the fit's, or the error's code name),
law, impacts, each law parameter's value, sigma and unit, scatter_e and its sigma, the reason
(for an outcome other than converged, or the error message) and the warning codes
(";"-separated). The HTML report (`bouncecal report`, the CLI) shows the recordings that could
be read, fitted jointly. Exit status: 0 when every recording converged, 12 otherwise (as
`calibrate --batch`), the library's code when nothing could run.
"""
import argparse
import csv
import os
import pathlib
import subprocess
import sys

import bouncecal

AUDIO_SUFFIXES = {".wav", ".flac", ".ogg", ".oga", ".aiff", ".aif", ".m4a", ".mp3", ".opus",
                  ".aac", ".caf", ".3gp", ".webm"}


def recordings_in(folder):
    return sorted(str(p) for p in pathlib.Path(folder).iterdir()
                  if p.is_file() and p.suffix.lower() in AUDIO_SUFFIXES)


def table(rows):
    """The CSV: fixed columns, then NAME, NAME_sigma, NAME_unit per law parameter (in the
    law's order, the union over the rows), then scatter, reason and warnings."""
    names = []
    for r in rows:
        for name in ((r.get("law") or {}).get("parameters") or {}):
            if name not in names:
                names.append(name)
    header = ["file", "status", "outcome", "law", "impacts"]
    for n in names:
        header += [n, f"{n}_sigma", f"{n}_unit"]
    header += ["scatter_e", "scatter_e_sigma", "reason", "warnings"]
    out = [header]
    for r in rows:
        error = r.get("error")
        law = r.get("law") or {}
        params = law.get("parameters") or {}
        row = [r["file"], r["status"], error["code"] if error else r.get("outcome"),
               law.get("name"), r.get("impacts")]
        for n in names:
            p = params.get(n) or {}
            row += [p.get("value"), p.get("sigma"), p.get("unit")]
        row += [r.get("scatter_e"), r.get("scatter_e_sigma"),
                error["message"] if error else (r.get("reason") or ""),
                ";".join(w["code"] for w in r.get("warnings") or [])]
        out.append(["" if v is None else (repr(v) if isinstance(v, float) else v) for v in row])
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", help="folder of recordings (WAV, FLAC, m4a, ...)")
    ap.add_argument("--scene", required=True, help="scene file (TOML) shared by the recordings")
    ap.add_argument("--law", help="contact law (default: the scene's)")
    ap.add_argument("-o", "--output", required=True, help="CSV file to write")
    ap.add_argument("--report", help="HTML report to write (bouncecal report)")
    ap.add_argument("--bouncecal", default=os.environ.get("BOUNCECAL_BINARY", "build/bouncecal"),
                    help="the CLI, for the report (default build/bouncecal)")
    ap.add_argument("--jobs", type=int, default=1, help="worker threads")
    ap.add_argument("--force", action="store_true", help="replace existing output files")
    a = ap.parse_args()

    for path in [a.output] + ([a.report] if a.report else []):
        if os.path.exists(path) and not a.force:
            print(f"batch_folder: {path}: exists (--force replaces it)", file=sys.stderr)
            return 11
    files = recordings_in(a.folder)
    if not files:
        print(f"batch_folder: {a.folder}: no recordings", file=sys.stderr)
        return 3
    try:
        rows = bouncecal.calibrate(files, scene=a.scene, law=a.law, batch=True, jobs=a.jobs)
        status = 0
    except bouncecal.SomeFailedError as e:
        rows, status = e.result, e.exit_code
    except bouncecal.Error as e:
        print(f"batch_folder: {e.message}", file=sys.stderr)
        return e.exit_code
    with open(a.output, "w", newline="") as f:
        csv.writer(f).writerows(table(rows))
    print(f"wrote {a.output}: {len(rows)} recordings, "
          f"{sum(r['status'] == 'ok' for r in rows)} converged")

    if a.report:
        readable = [r["file"] for r in rows if r["status"] != "error"]
        if readable:
            cmd = [a.bouncecal, "report", *readable, "--scene", a.scene, "-o", a.report,
                   "--quiet"] + (["--law", a.law] if a.law else []) + (["--force"] if a.force else [])
            p = subprocess.run(cmd)
            if p.returncode != 0 and not os.path.exists(a.report):
                return p.returncode
            print(f"wrote {a.report}" + (f" (report exit code {p.returncode})" if p.returncode else ""))
        else:
            print("batch_folder: no readable recording: no report", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
