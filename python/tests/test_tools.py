"""laws, simulate, export, read_audio, columns and the error translation."""
import json
import math

import numpy as np
import pytest

import bouncecal
from conftest import RECORDING, SCENE, SOURCE_DIR, run_cli


def test_laws_equals_cli_json():
    assert bouncecal.laws() == run_cli("laws", "--json")


def test_laws_one_law_with_scene_equals_cli_json():
    scene = SOURCE_DIR / "data" / "scenes" / "pingpong-wood.toml"
    got = bouncecal.laws("hertz-viscoelastic", scene=scene)
    assert got == run_cli("laws", "hertz-viscoelastic", "--scene", scene, "--json")
    assert [law["name"] for law in got["laws"]] == ["hertz-viscoelastic"]


def test_laws_unknown_law_raises_bad_parameter():
    with pytest.raises(bouncecal.BadParameterError) as info:
        bouncecal.laws("no-such-law")
    e = info.value
    assert (e.code, e.exit_code) == ("bad_parameter", 9)
    assert "no-such-law" in e.message
    assert isinstance(e, bouncecal.Error)


def test_simulate_equals_cli_json():
    got = bouncecal.simulate(law="walton-braun", set={"gamma": 0.5}, height=0.2, max_impacts=5)
    want = run_cli("simulate", "--law", "walton-braun", "--set", "gamma=0.5", "--height", "0.2",
                   "--max-impacts", "5", "--json")
    assert got == want
    assert len(got["impacts"]) == 5


def test_simulate_scene_file_and_scene_dict_agree():
    from_file = bouncecal.simulate(scene=SCENE, max_impacts=4)
    as_dict = {
        "ball.diameter_m": 0.01, "ball.density_kg_m3": 7800.0, "ball.material": "steel",
        "surface": {"material": "copper"}, "drop.height_m": 0.2, "effects.drag": "none",
        "effects.contact_duration": True, "law.name": "hertz-viscoelastic",
        "law.parameters.A": 5.16e-7,
    }
    got = bouncecal.simulate(scene=as_dict, max_impacts=4)
    assert got["scene"]["source"] == "scene dict"
    assert dict(got, scene=dict(got["scene"], source=from_file["scene"]["source"])) == from_file
    assert from_file == run_cli("simulate", "--scene", SCENE, "--max-impacts", "4", "--json")


def test_simulate_first_impact_speed_is_free_fall():
    # v = sqrt(2 g h) with g = 9.8 (the scene default), h = 0.2 m, no drag: 1.979899 m/s.
    s = bouncecal.simulate(scene={"drop.height_m": 0.2, "effects.drag": "none"}, max_impacts=1)
    assert s["impacts"][0]["v_in_m_s"] == pytest.approx(math.sqrt(2 * 9.8 * 0.2), rel=1e-6)


def test_simulate_bad_scene_dict_raises_bad_scene_with_the_key():
    with pytest.raises(bouncecal.BadSceneError) as info:
        bouncecal.simulate(scene={"ball.no_such_key": 1.0})
    assert info.value.exit_code == 8
    assert "no_such_key" in info.value.message


def test_simulate_missing_scene_file_raises_input_missing():
    with pytest.raises(bouncecal.InputMissingError) as info:
        bouncecal.simulate(scene="/nonexistent/scene.toml")
    assert (info.value.code, info.value.exit_code) == ("input_missing", 3)
    assert "/nonexistent/scene.toml" in info.value.message


def test_simulate_negative_height_message_is_the_clis_with_the_keyword():
    # One check in the library (SceneOverrides::height_m); each front end names its own input:
    # the keyword here, the flag on the command line.
    with pytest.raises(bouncecal.BadParameterError) as info:
        bouncecal.simulate(height=-1.0)
    p = __import__("subprocess").run([str(__import__("conftest").BINARY), "simulate", "--height",
                                      "-1"], capture_output=True, text=True)
    assert p.returncode == info.value.exit_code == 9
    assert info.value.message == "height: must be finite and > 0 (got -1)"
    assert p.stderr.strip() == "bouncecal: --height: must be finite and > 0 (got -1)"


def test_export_writes_the_deck_and_returns_the_mapping(params_file, tmp_path):
    out = tmp_path / "deck"
    got = bouncecal.export(params_file, out, to="lammps")
    assert (out / "run.sh").is_file()
    assert got == json.loads((out / "mapping.json").read_text())
    assert got["target"] == "lammps"
    cli_out = tmp_path / "deck_cli"
    assert run_cli("export", params_file, "--to", "lammps", "-o", cli_out, "--json") == got


def test_export_existing_directory_raises_output(params_file, tmp_path):
    out = tmp_path / "deck"
    bouncecal.export(params_file, out, to="lammps")
    with pytest.raises(bouncecal.OutputError) as info:
        bouncecal.export(params_file, out, to="lammps")
    assert info.value.exit_code == 11
    assert "force" in info.value.message


def test_export_inexact_mapping_raises_bad_parameter_naming_the_option(params_file, tmp_path):
    # Yade's Mindlin betan misses this fit's e(v) by 0.018 > 0.01: refused unless accepted.
    with pytest.raises(bouncecal.BadParameterError) as info:
        bouncecal.export(params_file, tmp_path / "y", to="yade")
    assert info.value.exit_code == 9
    assert "allow_approximation" in info.value.message
    got = bouncecal.export(params_file, tmp_path / "y", to="yade", allow_approximation=True)
    assert got["max_e_error"] > 0.01


def test_export_unknown_target_raises_usage(params_file, tmp_path):
    with pytest.raises(bouncecal.UsageError) as info:
        bouncecal.export(params_file, tmp_path / "x", to="gromacs")
    assert info.value.exit_code == 2
    assert "gromacs" in info.value.message


def test_read_audio_gives_the_waveform_as_numpy():
    a = bouncecal.read_audio(RECORDING)
    assert a["samples"].dtype == np.float32
    assert a["samples"].shape == (a["channels"], a["frames"])
    assert a["duration_s"] == pytest.approx(a["frames"] / a["sample_rate_hz"])
    assert 0.0 < float(np.max(np.abs(a["samples"]))) <= 1.0


def test_read_audio_not_audio_raises_not_audio(tmp_path):
    bad = tmp_path / "notes.wav"
    bad.write_text("this is not audio\n")
    with pytest.raises(bouncecal.NotAudioError) as info:
        bouncecal.read_audio(bad)
    assert info.value.exit_code == 4
    assert str(bad) in info.value.message


def test_columns_turns_records_into_arrays_with_nan_for_null():
    cols = bouncecal.columns([{"e": 0.9, "k": 1, "ok": True}, {"e": None, "k": 2, "ok": False}])
    assert np.isnan(cols["e"][1]) and cols["e"][0] == 0.9
    assert cols["k"].dtype == np.int64 and list(cols["k"]) == [1, 2]
    assert cols["ok"].dtype == bool


def test_misspelled_option_is_a_type_error():
    with pytest.raises(TypeError):
        bouncecal.simulate(hieght=0.2)


def test_simulate_replays_a_parameter_file_as_the_cli(params_file):
    got = bouncecal.simulate(params=params_file, max_impacts=3)
    assert got == run_cli("simulate", "--params", params_file, "--max-impacts", "3", "--json")


def test_simulate_params_with_a_scene_option_raises_usage(params_file):
    with pytest.raises(bouncecal.UsageError) as info:
        bouncecal.simulate(params=params_file, height=0.3)
    assert info.value.exit_code == 2
    assert "cannot be combined" in info.value.message
