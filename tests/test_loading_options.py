"""The loading options every command that reads a recording takes: --rate and --time-column (files without a
usable time column), --header-rows (RepoIMU's names-then-units header, or a profile key), --with/--with-offset
(sensors on different clocks merged onto the input's times, stated in the metadata)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import formats
from formats.csv import iter_csv
from formats.errors import ImutoolError
from imutool.cli import main
from imutool.loading import load_recording

NO_CLOCK = "gx (deg/s),gy (deg/s),gz (deg/s)\n" + "".join(f"{0.1 * i:g},0.2,0.3\n" for i in range(10))
# RepoIMU (TStick/Vicon) layout: ';'-separated, a row of names then a row of units ('a.U.' = arbitrary units)
REPOIMU = (
    "Time;Orientation w;Orientation x;Orientation y;Orientation z;Acceleration x;Acceleration y;Acceleration z;"
    "Gyroscope x;Gyroscope y;Gyroscope z;Magnetometer x;Magnetometer y;Magnetometer z\n"
    "s;;;;;m/s^2;m/s^2;m/s^2;deg/s;deg/s;deg/s;a.U.;a.U.;a.U.\n"
    "0.00;1;0;0;0;0.1;0.2;9.8;10;0;0;0.3;0.1;-0.5\n"
    "0.01;1;0;0;0;0.1;0.2;9.8;10;0;0;0.3;0.1;-0.5\n"
    "0.02;1;0;0;0;0.1;0.2;9.8;10;0;0;0.3;0.1;-0.5\n"
)


@pytest.fixture
def run(capsys):
    """``imutool ARGS`` in-process → (exit status, stdout; or on an error its one error line)."""

    def _run(*args: str) -> tuple[int, str]:
        code = 0
        try:
            main(list(args))
        except SystemExit as e:
            code = int(e.code or 0)
        out, err = capsys.readouterr()
        if code:
            errors = [ln for ln in err.splitlines() if ": error: " in ln]
            assert len(errors) == 1 and "Traceback" not in err, err
            return code, errors[0]
        return code, out

    return _run


def test_rate_gives_a_file_without_time_column_its_times(tmp_path, run):
    p = tmp_path / "xio.csv"
    p.write_text(NO_CLOCK)
    code, out = run("info", str(p))  # without --rate: one line saying to use it
    assert code == 2 and "give the sample rate with --rate HZ" in out
    rec, _ = load_recording(p, input_rate_hz=256.0)
    np.testing.assert_array_equal(rec.time, np.arange(10) / 256.0)
    assert rec.meta["time_source"].startswith("time from --rate 256 Hz") and rec.meta["rate_hz"] == 256.0
    # streamed in chunks the row count carries on: the same times
    t = np.concatenate([c.time for c in iter_csv(str(p), chunk_rows=3, rate_hz=256.0)])
    np.testing.assert_array_equal(t, rec.time)
    code, out = run("info", str(p), "--rate", "256", "--json")
    assert code == 0 and json.loads(out)["rate_hz"] == pytest.approx(256.0)
    # a file with a time column: --rate is refused, not silently preferred
    q = tmp_path / "timed.csv"
    q.write_text("time,gx\n0,1\n1,2\n")
    with pytest.raises(ImutoolError, match="--rate is for a file without a time column"):
        load_recording(q, input_rate_hz=10.0)
    # a CSV-only option on another format: refused in one line
    n = tmp_path / "x.nmea"
    n.write_text("$HEHDT,10.0,T*1C\r\n")
    with pytest.raises(ImutoolError, match="only for a CSV"):
        load_recording(n, input_rate_hz=10.0)


def test_time_column_with_its_unit(tmp_path, run):
    p = tmp_path / "clock.csv"
    p.write_text("Clock,gx,gy,gz\n0,1,2,3\n5,1,2,3\n10,1,2,3\n")
    with pytest.raises(ImutoolError, match="--time-column"):
        load_recording(p)
    rec, _ = load_recording(p, time_column="Clock:ms")
    np.testing.assert_allclose(rec.time, [0.0, 0.005, 0.01])
    code, out = run("info", str(p), "--time-column", "Clock:ns", "--json")
    assert code == 0 and json.loads(out)["end_s"] == pytest.approx(1e-8)
    code, out = run("info", str(p), "--time-column", "Clock:h")
    assert code == 2 and "s, ms, us or ns" in out


def test_header_rows_reads_repoimu_units(tmp_path, run):
    p = tmp_path / "repoimu.csv"
    p.write_text(REPOIMU)
    one, _ = load_recording(p, validate=False)  # one header row: the units row is a bad data row, units guessed
    assert one.meta["skipped_rows"] == 1 and "gyro" in one.meta["units_assumed"]
    rec, _ = load_recording(p, header_rows=2)
    assert len(rec) == 3 and "skipped_rows" not in rec.meta and rec.meta["source_header_rows"] == 2
    np.testing.assert_allclose(rec["gyro"][0], [np.radians(10.0), 0, 0])  # deg/s from the units row
    assert rec.meta["units_assumed"] == "mag"  # 'a.U.' is not a unit: the magnetometer's stays assumed
    prof = tmp_path / "repoimu.toml"
    prof.write_text('name = "RepoIMU"\nheader_rows = 2\n')
    by_profile, _ = load_recording(p, profile=str(prof))
    np.testing.assert_array_equal(by_profile["gyro"], rec["gyro"])
    code, out = run("info", str(p), "--header-rows", "2", "--json")
    assert code == 0 and json.loads(out)["rows"] == 3
    code, out = run("info", str(p), "--header-rows", "4")
    assert code == 2 and "header" in out


def _two_clocks(tmp_path):
    g = tmp_path / "gyro.csv"
    g.write_text("time,gyro_x,gyro_y,gyro_z\n" + "".join(f"{0.1 * i:.1f},0,0,{0.01 * i:g}\n" for i in range(21)))
    m = tmp_path / "mag.csv"  # another logger: its clock 100 s ahead
    m.write_text("time,mag_x,mag_y,mag_z\n" + "".join(f"{100.05 + 0.25 * i:.2f},20,{i},40\n" for i in range(9)))
    return g, m


def test_with_merges_sensors_on_other_clocks(tmp_path, run):
    g, m = _two_clocks(tmp_path)
    code, out = run("info", str(g), "--with", str(m))
    assert code == 2 and "do not overlap" in out and "--with-offset" in out
    rec, report = load_recording(g, with_files=[str(m)], with_offsets=[-100.0])
    assert set(rec.channels) == {"gyro", "mag"}
    assert rec.time[0] >= 0.05 and rec.time[-1] <= 2.0  # only the span both cover
    np.testing.assert_allclose(rec["mag"][:, 1], (rec.time - 0.05) / 0.25, atol=1e-9)  # interpolated onto gyro
    merged = rec.meta["merged"]
    assert merged["files"][0] == {"input": str(g), "channels": ["gyro"], "offset_s": 0.0, "rows": 21}
    assert merged["files"][1]["channels"] == ["mag"] and merged["files"][1]["offset_s"] == -100.0
    assert str(g) in merged["time_base"] and report["with"][0]["input"] == str(m)
    out_csv = tmp_path / "merged.csv"
    code, _ = run("convert", str(g), str(out_csv), "--with", str(m), "--with-offset", "-100")
    back = formats.read(out_csv)
    assert code == 0 and set(back.channels) == {"gyro", "mag"} and back.meta["merged"]["files"][1]["offset_s"] == -100
    # the same channel in two files: which one is meant is not clear, refused
    code, out = run("info", str(g), "--with", str(g))
    assert code == 2 and "channel(s) gyro also in" in out
    code, out = run("info", str(g), "--with", str(m), "--with-offset", "1", "--with-offset", "2")
    assert code == 2 and "one per file" in out
    code, out = run("info", str(g), "--with-offset", "1")
    assert code == 2 and "give the file too" in out
    code, out = run("convert", str(g), str(tmp_path / "m2.csv"), "--with", str(m), "--with-offset", "-100")
    assert code == 0 and f"merged onto its times: {m} (mag)" in out


def test_every_command_with_a_reference_file_takes_the_reference_loading_options():
    """evaluate, report inclinometer|heading and calibrate deviation: one set of --ref-* options (defined once), whose
    parameters are the keys the routes take (imutool.loading.REF_LOAD_OPTIONS)."""
    from imutool.cli.batch import _resolve
    from imutool.loading import REF_LOAD_OPTIONS, reference_text

    flags = {flag for _, flag in REF_LOAD_OPTIONS.values()}
    assert flags == {
        "--ref-columns",
        "--ref-profile",
        "--ref-rate",
        "--ref-time-column",
        "--ref-header-rows",
        "--ref-with",
        "--ref-with-offset",
        "--ref-with-prefix",
        "--ref-start",
    }
    for words in (["evaluate"], ["report", "inclinometer"], ["report", "heading"], ["calibrate", "deviation"]):
        params = {o: p.name for p in _resolve(words).params for o in getattr(p, "opts", [])}
        assert {o: params.get(o) for o in flags} == {flag: k for k, (_, flag) in REF_LOAD_OPTIONS.items()}, words
    assert reference_text("give --rate HZ or --time-column; --with-offset per --with; --ref-rate") == (
        "give --ref-rate HZ or --ref-time-column; --ref-with-offset per --ref-with; --ref-rate"
    )
    assert reference_text("--columns: no column 'X'; --profile P") == "--ref-columns: no column 'X'; --ref-profile P"
    # where the reference took the input's mapping (a report without --ref-columns), the input's flag is kept
    assert reference_text("--columns: no column 'X'", inherited=("columns",)) == "--columns: no column 'X'"


def test_the_reference_mapping_replaces_the_inputs_or_is_inherited(monkeypatch):
    """--ref-columns/--ref-profile are the reference's column mapping in place of the input's --columns/--profile
    (either replaces both); a report's reference without them takes the input's, as before (its errors then name
    the input's flags: ``inherited``)."""
    from formats import Recording
    from imutool.loading import split_reference_options
    from imutool.report import route

    rest, ref = split_reference_options({"columns": "A=roll:deg", "ref_columns": "B=roll:deg", "ref_profile": None})
    assert rest == {"columns": "A=roll:deg"} and ref == {"columns": "B=roll:deg"}
    seen: list[tuple] = []

    def load(name, inputs, *, strict, on_input, inherited=(), **opts):
        seen.append((name, opts.get("columns"), opts.get("profile"), inherited))
        return Recording(np.arange(20.0), {"roll": np.zeros(20)}), {}

    monkeypatch.setattr(route, "load_input", lambda *a, **k: load(*a, **k))
    monkeypatch.setattr(route, "load_reference", load)
    dut = {"columns": None, "profile": "dut.toml"}
    for ref_given, expect in (
        ({}, ("r.csv", None, "dut.toml", ("profile",))),
        ({"ref_columns": "B=roll:deg"}, ("r.csv", "B=roll:deg", None, ())),
        ({"ref_profile": "ref.toml"}, ("r.csv", None, "ref.toml", ())),
    ):
        seen.clear()
        route._load_pair("d.csv", "r.csv", None, None, [], False, None, dut | ref_given)
        assert seen == [("d.csv", None, "dut.toml", ()), expect], ref_given


def test_one_definition_of_the_loading_options():
    """LOAD_OPTIONS is how a file is read (a reference too) plus the input's own; every reference option stands in
    for one of the input's own, for the column mapping (MAPPING) or is --ref-start."""
    import inspect

    from imutool.loading import INPUT_ONLY_OPTIONS, LOAD_OPTIONS, MAPPING, READ_OPTIONS, REF_LOAD_OPTIONS

    assert LOAD_OPTIONS == READ_OPTIONS + INPUT_ONLY_OPTIONS
    assert set(LOAD_OPTIONS) <= set(inspect.signature(load_recording).parameters)
    assert {k for k, _ in REF_LOAD_OPTIONS.values()} - {"start", *MAPPING} <= set(INPUT_ONLY_OPTIONS)
    assert set(MAPPING) <= set(READ_OPTIONS)
