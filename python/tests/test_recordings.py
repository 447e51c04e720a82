"""detect, analyze, calibrate: the dicts equal the CLI's --json output; one error path each."""
import json

import numpy as np
import pytest

import bouncecal
from conftest import BINARY, RECORDING, SCENE, run_cli


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    out = tmp_path_factory.mktemp("cal") / "params.json"
    return bouncecal.calibrate(RECORDING, scene=SCENE, output=out), out


def without_provenance(doc):
    # Provenance records when the fit ran (date_utc): the one value that differs between runs.
    if isinstance(doc, dict):
        return {k: without_provenance(v) for k, v in doc.items() if k != "date_utc"}
    if isinstance(doc, list):
        return [without_provenance(v) for v in doc]
    return doc


def test_detect_equals_cli_json():
    got = bouncecal.detect(RECORDING)
    assert got == run_cli("detect", RECORDING, "--json")
    assert got["schema"] == "bouncecal.detect/2"
    assert "impacts" not in got  # each impact once, in its sequence
    times = bouncecal.columns(got["sequences"][got["chosen_sequences"][0]]["impacts"])["time_s"]
    assert times.dtype == float and np.all(np.diff(times) > 0)


def test_detect_options_are_the_flags():
    got = bouncecal.detect(RECORDING, channel=0, start=0.1, min_snr_db=12, sequence="all")
    assert got == run_cli("detect", RECORDING, "--channel", "0", "--start", "0.1",
                          "--min-snr-db", "12", "--sequence", "all", "--json")
    assert got["channel"] == 0
    assert all(i["time_s"] >= 0.1 for q in got["sequences"] for i in q["impacts"])


def test_detect_missing_file_raises_input_missing():
    with pytest.raises(bouncecal.InputMissingError) as info:
        bouncecal.detect("/nonexistent/drop.wav")
    assert (info.value.code, info.value.exit_code) == ("input_missing", 3)
    assert "/nonexistent/drop.wav" in info.value.message


def test_detect_several_files_one_missing_raises_some_failed_with_every_entry():
    with pytest.raises(bouncecal.SomeFailedError) as info:
        bouncecal.detect([RECORDING, "/nonexistent/drop.wav"])
    e = info.value
    assert e.exit_code == 12
    ok, failed = e.result
    assert ok == bouncecal.detect(RECORDING)
    assert failed["file"] == "/nonexistent/drop.wav"
    assert failed["error"]["exit_code"] == 3
    p = __import__("subprocess").run([str(BINARY), "detect", str(RECORDING),
                                      "/nonexistent/drop.wav", "--json"],
                                     capture_output=True, text=True)
    assert p.returncode == 12 and json.loads(p.stdout) == e.result


def test_detect_list_of_one_gives_a_list():
    assert bouncecal.detect([RECORDING]) == [bouncecal.detect(RECORDING)]


def test_analyze_equals_cli_json():
    got = bouncecal.analyze(RECORDING, scene=SCENE)
    assert got == run_cli("analyze", RECORDING, "--scene", SCENE, "--json")
    assert got["schema"] == "bouncecal.analysis/1"
    e = bouncecal.columns(got["bounces"])["e"]
    # The bundled recording was simulated with e = 0.920 at the first impact (data/README.md).
    assert e[np.isfinite(e)][0] == pytest.approx(0.92, abs=0.01)


def test_analyze_scene_dict_and_flags_equal_the_cli(tmp_path):
    got = bouncecal.analyze(RECORDING, scene={"ball": {"diameter_m": 0.01, "material": "steel"}},
                            height=0.2, drag="none")
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(bouncecal.scene_toml({"ball": {"diameter_m": 0.01,
                                                         "material": "steel"}}))
    want = run_cli("analyze", RECORDING, "--scene", scene_file, "--height", "0.2", "--drag",
                   "none", "--json")
    want["scene"]["source"] = got["scene"]["source"]  # the dict is named "scene dict"
    assert got == want


def test_analyze_not_audio_raises_not_audio(tmp_path):
    bad = tmp_path / "drop.wav"
    bad.write_bytes(b"RIFF\x00\x00")
    with pytest.raises(bouncecal.NotAudioError) as info:
        bouncecal.analyze(bad, height=0.2)
    assert info.value.exit_code == 4
    assert str(bad) in info.value.message


def test_calibrate_equals_cli_json_and_writes_the_parameter_file(calibration, tmp_path):
    got, path = calibration
    want = run_cli("calibrate", RECORDING, "--scene", SCENE, "--json")
    assert without_provenance(got) == without_provenance(want)
    written = json.loads(path.read_text())
    assert without_provenance(written) == without_provenance(got)
    assert got["fit"]["outcome"] == "converged"
    assert got["provenance"]["inputs"][0]["file"] == str(RECORDING)


def test_calibrate_parameter_file_exports(calibration, tmp_path):
    _, path = calibration
    mapping = bouncecal.export(path, tmp_path / "deck", to="liggghts")
    assert mapping["target"] == "liggghts"


def test_calibrate_without_a_ball_raises_bad_scene():
    with pytest.raises(bouncecal.BadSceneError) as info:
        bouncecal.calibrate(RECORDING, height=0.2)
    assert info.value.exit_code == 8
    assert "ball" in info.value.message


def test_calibrate_unknown_law_raises_bad_parameter():
    with pytest.raises(bouncecal.BadParameterError) as info:
        bouncecal.calibrate(RECORDING, scene=SCENE, law="no-such-law")
    assert info.value.exit_code == 9
    assert "no-such-law" in info.value.message


def test_calibrate_existing_output_raises_output_before_fitting(calibration):
    _, path = calibration
    with pytest.raises(bouncecal.OutputError) as info:
        bouncecal.calibrate(RECORDING, scene=SCENE, output=path)
    assert info.value.exit_code == 11


def test_calibrate_batch_rows_equal_cli_json_lines():
    rows = bouncecal.calibrate([RECORDING], scene=SCENE, batch=True)
    p = __import__("subprocess").run([str(BINARY), "calibrate", str(RECORDING), "--scene",
                                      str(SCENE), "--batch", "--json"],
                                     capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    want = [json.loads(line) for line in p.stdout.splitlines()]
    assert rows == want


def test_calibrate_outcome_other_than_converged_raises_with_the_result(tmp_path):
    out = tmp_path / "params.json"
    with pytest.raises(bouncecal.FitOutcomeError) as info:
        bouncecal.calibrate(RECORDING, scene=SCENE, max_iterations=1, starts=1, output=out)
    e = info.value
    assert (e.code, e.exit_code) == ("iteration_limit", 13)
    assert e.result["fit"]["outcome"] == "iteration_limit"
    # The parameter file is still written and records the outcome, as the CLI does.
    assert json.loads(out.read_text())["fit"]["outcome"] == "iteration_limit"
    p = __import__("subprocess").run([str(BINARY), "calibrate", str(RECORDING), "--scene",
                                      str(SCENE), "--max-iterations", "1", "--starts", "1"],
                                     capture_output=True, text=True)
    assert p.returncode == 13
    assert "bouncecal: " + e.message in p.stderr


def test_calibrate_wrong_law_is_a_poor_fit():
    # The recording was simulated with the viscoelastic Hertz law; Walton-Braun's constant e
    # cannot follow its e(v) trend (the CLI exits 14).
    with pytest.raises(bouncecal.FitOutcomeError) as info:
        bouncecal.calibrate(RECORDING, scene=SCENE, law="walton-braun")
    assert (info.value.code, info.value.exit_code) == ("poor_fit", 14)
    assert info.value.result["law"]["name"] == "walton-braun"


def test_calibrate_law_all_equals_cli_json():
    got = bouncecal.calibrate(RECORDING, scene=SCENE, law="all")
    want = run_cli("calibrate", RECORDING, "--scene", SCENE, "--law", "all", "--json")
    assert without_provenance(got) == without_provenance(want)
    assert got["schema"] == "bouncecal.law_comparison/2"
    # The recording was simulated with the viscoelastic Hertz law: it ranks first.
    assert got["laws"][0]["law"]["name"] == "hertz-viscoelastic" and got["laws"][0]["rank"] == 1
