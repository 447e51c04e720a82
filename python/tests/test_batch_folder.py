"""tools/batch_folder.py: a folder of recordings -> one CSV row each and one HTML report."""
import csv
import os
import shutil
import subprocess
import sys

import bouncecal
from conftest import BINARY, RECORDING, SCENE, SOURCE_DIR


def test_batch_folder_writes_one_row_per_recording_and_the_report(tmp_path):
    folder = tmp_path / "drops"
    folder.mkdir()
    shutil.copy(RECORDING, folder / "a_steel.flac")
    (folder / "b_broken.wav").write_text("not audio\n")
    out, report = tmp_path / "results.csv", tmp_path / "report.html"
    package_dir = os.path.dirname(os.path.dirname(os.path.abspath(bouncecal.__file__)))
    env = dict(os.environ, BOUNCECAL_BINARY=str(BINARY), PYTHONPATH=package_dir)
    p = subprocess.run([sys.executable, str(SOURCE_DIR / "tools" / "batch_folder.py"),
                        str(folder), "--scene", str(SCENE), "-o", str(out), "--report",
                        str(report)], capture_output=True, text=True, env=env)
    assert p.returncode == 12, p.stderr  # one recording failed: calibrate --batch's code
    rows = list(csv.DictReader(out.open()))
    assert [r["file"] for r in rows] == [str(folder / "a_steel.flac"), str(folder / "b_broken.wav")]
    ok, broken = rows
    assert (ok["status"], ok["outcome"], ok["law"]) == ("ok", "converged", "hertz-viscoelastic")
    # The recording was simulated with A = 5.16e-7 s (data/default_steel_copper.toml).
    assert abs(float(ok["A"]) - 5.16e-7) < 5 * float(ok["A_sigma"]) + 0.05 * 5.16e-7
    assert ok["A_unit"] == "s" and ok["scatter_e"] != ""
    assert (broken["status"], broken["outcome"]) == ("error", "not_audio")
    assert "b_broken.wav" in broken["reason"]
    html = report.read_text()
    assert "a_steel.flac" in html and "b_broken.wav" not in html
