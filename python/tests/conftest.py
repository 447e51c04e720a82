"""Shared fixtures of the binding tests: where the sources, the data and the CLI are.

ctest (python_test) sets PYTHONPATH=build/python, BOUNCECAL_SOURCE_DIR and BOUNCECAL_BINARY;
run by hand: PYTHONPATH=build/python python3 -m pytest python/tests -q
"""
import json
import os
import pathlib
import subprocess

import pytest

SOURCE_DIR = pathlib.Path(os.environ.get("BOUNCECAL_SOURCE_DIR",
                                         pathlib.Path(__file__).resolve().parents[2])).resolve()
BINARY = pathlib.Path(os.environ.get("BOUNCECAL_BINARY",
                                     SOURCE_DIR / "build" / "bouncecal")).resolve()
RECORDING = SOURCE_DIR / "data" / "default_steel_copper.flac"
SCENE = SOURCE_DIR / "data" / "default_steel_copper.toml"


@pytest.fixture(autouse=True)
def scratch_cwd(tmp_path, monkeypatch):
    """Every test runs in its own scratch directory: nothing lands in the source tree (the
    exporter asks the simulators for their version, and LIGGGHTS writes log.liggghts)."""
    monkeypatch.chdir(tmp_path)


def run_cli(*args, expect=0):
    """The CLI's JSON output (the oracle the bindings' dicts are compared with)."""
    p = subprocess.run([str(BINARY), *map(str, args)], capture_output=True, text=True)
    assert p.returncode == expect, p.stderr
    return json.loads(p.stdout) if p.stdout.strip() else None


@pytest.fixture(scope="session")
def params_file(tmp_path_factory):
    """A parameter file of the bundled recording's calibration (the CLI writes it)."""
    path = tmp_path_factory.mktemp("params") / "params.json"
    run_cli("calibrate", RECORDING, "--scene", SCENE, "-o", path, "--json")
    return path
