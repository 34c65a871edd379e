"""imutool.calibrate: the calibration runs behind `imutool calibrate ...`, called from Python, give what the CLI
gives (same sections in the calibration file, same summary), and take a Recording as well as a path."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_main

import formats
from calibration import load_calibration
from formats.errors import ImutoolError
from imutool import calibrate as lib
from imutool.sim import simulate


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("calib")
    formats.write(simulate("mag-sphere", duration=60, seed=7), d / "sphere.csv")
    formats.write(simulate("compass-swing", duration=200, rate_hz=5, seed=9), d / "swing.csv")
    formats.write(simulate("six-position", seed=3), d / "sixpos.csv")
    return d


def _sections(path):
    """Sections of a calibration file (JSON text) without the run-specific provenance (time stamp)."""
    out = {}
    for name, sec in load_calibration(path).sections.items():
        out[name] = {k: v for k, v in sec.items() if k != "provenance"}
        prov = dict(sec.get("provenance", {}))
        prov.pop("date_utc", None)
        out[name]["provenance"] = prov
    return json.dumps(out, sort_keys=True, default=str)  # as text: NaN (unobservable) compares equal


CASES = {
    "mag-sphere": (["calibrate", "mag", "sphere.csv"], lambda f, o: lib.calibrate_mag(f / "sphere.csv", o)),
    "mag-swing": (
        ["calibrate", "mag", "swing.csv", "--method", "swing"],
        lambda f, o: lib.calibrate_mag(f / "swing.csv", o, method="swing"),
    ),
    "gyro": (
        ["calibrate", "gyro", "sixpos.csv", "--min-rest", "1.5"],
        lambda f, o: lib.calibrate_gyro(f / "sixpos.csv", o, rest=lib.rest_options(min_rest_s=1.5)),
    ),
    "accel": (
        ["calibrate", "accel", "sixpos.csv", "--latitude", "59.4"],
        lambda f, o: lib.calibrate_accel(f / "sixpos.csv", o, latitude=59.4),
    ),
    "deviation": (
        ["calibrate", "deviation", "swing.csv", "--vessel", "MV Test", "--new"],
        lambda f, o: lib.deviation_card(f / "swing.csv", [o], vessel="MV Test", append=False),
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_python_call_equals_cli(files, tmp_path, capsys, case):
    argv, call = CASES[case]
    cli_out, lib_out = tmp_path / "cli.toml", tmp_path / "lib.toml"
    code, out, err = run_main([*argv[:2], files / argv[2], "-o", cli_out, "--json", *argv[3:]], capsys)
    assert code == 0, err
    cli_summary = json.loads(out)
    run = call(files, lib_out)
    assert _sections(cli_out) == _sections(lib_out)
    lib_summary = json.loads(json.dumps(run.summary, default=str))
    for k in ("output", "outputs"):
        if k in lib_summary:
            assert lib_summary.pop(k) in (str(lib_out), [str(lib_out)])
    assert lib_summary == {k: cli_summary[k] for k in lib_summary}
    assert len(run.recording) > 100


def test_recording_source_and_accuracy(files, tmp_path):
    """A Recording in memory takes the same route as its path; the fit recovers the simulated hard iron."""
    rec = formats.read(files / "sphere.csv")
    a = lib.calibrate_mag(files / "sphere.csv", tmp_path / "a.toml")
    b = lib.calibrate_mag(rec, tmp_path / "b.toml")
    assert np.array_equal(a.fit.b, b.fit.b) and np.array_equal(a.fit.A, b.fit.A)
    assert np.allclose(a.fit.b, [12, -25, 8], atol=0.5)  # the scenario's default hard iron, µT
    card = lib.deviation_card(
        formats.read(files / "swing.csv"), [tmp_path / "card.txt"], heading_column="ref_compass_heading", variation=0.0
    )  # simulated variation: 0
    truth = formats.read(files / "swing.csv").meta["deviation_deg"]
    assert np.allclose([card.summary["coefficients_deg"][n] for n in "ABCDE"], truth, atol=0.05)
    assert (tmp_path / "card.txt").read_text().strip()


def test_refusals(files, tmp_path):
    stages: list[str] = []
    with pytest.raises(ImutoolError, match=".toml"):
        lib.calibrate_gyro(files / "sixpos.csv", tmp_path / "x.json")
    with pytest.raises(ImutoolError, match="sensor axes"):
        lib.calibrate_mag(files / "sphere.csv", tmp_path / "m.toml", mounting="x,-y,-z", stage=stages.append)
    assert stages == ["reading"] and not (tmp_path / "m.toml").exists()
    with pytest.raises(TypeError, match="colums"):
        lib.calibrate_mag(files / "sphere.csv", tmp_path / "m.toml", colums="x")
    with pytest.raises(ImutoolError, match="card plot"):
        lib.deviation_card(files / "swing.csv", [tmp_path / "card.docx"])
