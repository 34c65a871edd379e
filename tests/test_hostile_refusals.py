"""Hostile cases of issue 39: the last internal errors, and inputs where no answer can be right.

Each case runs ``imutool.cli.main`` in-process through ``test_hostile.check``: no traceback, no internal error,
exit 2 with ONE line on stderr naming the file (or option) at fault, nothing left under the output name, every
input byte-identical afterwards.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from test_hostile import LAYOUT, SENSOR, _csv, _limited, check, leftovers, run, snapshot

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    import formats
    from imutool import sim

    d = tmp_path_factory.mktemp("refusals")
    out: dict[str, Path] = {}
    for name, scenario, kw in (
        ("roll.csv", "ship-roll", {"duration": 30.0, "rate_hz": 50.0}),
        ("static.csv", "static", {"duration": 30.0, "rate_hz": 50.0}),
        ("array.csv", "accel-array", {"duration": 5.0}),
    ):
        formats.write(sim.simulate(scenario, seed=1, **kw), d / name)
        out[name] = d / name
    code, _, err = run(["filter", out["roll.csv"], "-o", d / "est.csv", "-q"])
    assert code == 0, err
    out["est.csv"] = d / "est.csv"
    rng = np.random.default_rng(3)
    # 2 000 rows sharing one time stamp: 1 999 are dropped as duplicates, one row is left
    (d / "one_time.csv").write_bytes(_csv(np.column_stack([np.full(2000, 5.0), rng.normal(size=(2000, 9))])))
    t = np.arange(300) / 50.0
    (d / "all_nan.csv").write_bytes(_csv(np.column_stack([t, np.full((300, 9), np.nan)])))
    (d / "dup_cols.csv").write_bytes(
        _csv(np.column_stack([t, rng.normal(size=(300, 9))]), SENSOR.replace("accel_y", "accel_x"))
    )
    text = out["roll.csv"].read_text().splitlines()
    head = [ln for ln in text if ln.startswith("#")]
    rows = [ln for ln in text if not ln.startswith("#")]
    late = [",".join([repr(float(r.split(",")[0]) + 1000.0), *r.split(",")[1:]]) for r in rows[1:]]
    (d / "late.csv").write_text("\n".join([*head, rows[0], *late]) + "\n")
    (d / "ref_one_row.csv").write_text("\n".join([*head, *rows[:2]]) + "\n")
    for name in ("one_time.csv", "all_nan.csv", "dup_cols.csv", "late.csv", "ref_one_row.csv"):
        out[name] = d / name
    # gyro-free layouts
    lay = LAYOUT.read_text()
    layouts = {
        "layout_1e300.toml": lay.replace("[-0.1, 0.0, 0.0]", "[1e300, 0.0, 0.0]"),  # was: SVD did not converge
        "layout_2km.toml": lay.replace("[-0.1, 0.0, 0.0]", "[-2000.0, 0.0, 0.0]"),
        "layout_pos_text.toml": lay.replace("[-0.1, 0.0, 0.0]", '"abc"'),
        "layout_pos_strings.toml": lay.replace("[-0.1, 0.0, 0.0]", '["1", "2", "3"]'),
        "layout_cols_numbers.toml": lay.replace('["a4_x", "a4_y", "a4_z"]', "[1, 2, 3]"),
        "layout_unit_number.toml": lay.replace('unit = "m/s^2"', "unit = 9.81"),
        "layout_unit_unknown.toml": lay.replace('unit = "m/s^2"', 'unit = "furlongs"'),
        "layout_unit_not_accel.toml": lay.replace('unit = "m/s^2"', 'unit = "deg/s"'),
        "layout_sensor_not_table.toml": 'name = "x"\nsensor = [1, 2, 3]\n',
        "layout_preset_r_text.toml": 'preset = "paper"\nr = "abc"\n',
        "layout_preset_r_huge.toml": 'preset = "paper"\nr = 1e300\n',
        "layout_noise_text.toml": lay.replace("noise_density = 9.8e-4", 'noise_density = "low"'),
    }
    for name, body in layouts.items():
        (d / name).write_text(body)
        out[name] = d / name
    (d / "layout_folder.toml").mkdir()
    out["layout_folder.toml"] = d / "layout_folder.toml"
    (d / "layout_missing_cols.toml").write_text(lay.replace('"a4_x"', '"nope_x"'))
    out["layout_missing_cols.toml"] = d / "layout_missing_cols.toml"
    # column profiles (TOML) with a key of the wrong type
    profiles = {
        "profile_scale_text.toml": '[columns]\n"gyro_x" = { to = "gyro_x", unit = "rad/s", scale = "abc" }\n',
        "profile_scale_zero.toml": '[columns]\n"gyro_x" = { to = "gyro_x", unit = "rad/s", scale = 0 }\n',
        "profile_scale_nan.toml": '[columns]\n"gyro_x" = { to = "gyro_x", unit = "rad/s", scale = nan }\n',
        "profile_scale_bool.toml": '[columns]\n"gyro_x" = { to = "gyro_x", unit = "rad/s", scale = true }\n',
        "profile_to_number.toml": '[columns]\n"gyro_x" = { to = 5 }\n',
        "profile_unit_number.toml": '[columns]\n"gyro_x" = { to = "gyro_x", unit = 3 }\n',
        "profile_unit_unknown.toml": '[columns]\n"gyro_x" = { to = "gyro_x", unit = "furlongs" }\n',
        "profile_unknown_key.toml": '[columns]\n"gyro_x" = { to = "gyro_x", sclae = 2.0 }\n',
        "profile_columns_list.toml": "columns = [1, 2]\n",
    }
    for name, body in profiles.items():
        (d / name).write_text(body)
        out[name] = d / name
    # Modbus register profiles with a key of the wrong type
    reg = '[[register]]\nname = "roll"\naddress = 1\n'
    modbus = {
        "modbus_address_text.toml": '[[register]]\nname = "roll"\naddress = "one"\n',
        "modbus_scale_text.toml": reg + 'scale = "x"\n',
        "modbus_rate_text.toml": '[device]\nrate_hz = "fast"\n' + reg,
        "modbus_rate_zero.toml": "[device]\nrate_hz = 0\n" + reg,
        "modbus_unit_float.toml": "[device]\nunit = 1.5\n" + reg,
        "modbus_register_not_table.toml": "register = [1, 2]\n",
        "modbus_device_not_table.toml": "device = 3\n" + reg,
    }
    for name, body in modbus.items():
        (d / name).write_text(body)
        out[name] = d / name
    (d / "manifest_jobs_numbers.toml").write_text("job = [1, 2]\n")
    (d / "manifest_job_table.toml").write_text(f'[[job]]\ninput = {{ path = "{out["roll.csv"]}" }}\n')
    out["manifest_jobs_numbers.toml"] = d / "manifest_jobs_numbers.toml"
    out["manifest_job_table.toml"] = d / "manifest_job_table.toml"
    return out


def _args(template: list, files: dict[str, Path], tmp_path: Path) -> tuple[list, list, list]:
    """@name → a file of the fixture (an input); OUT.ext → tmp_path/out.ext (an output)."""
    args, inputs, outputs = [], [], []
    for a in template:
        if isinstance(a, str) and a.startswith("@"):
            args.append(files[a[1:]])
            inputs.append(files[a[1:]])
        elif isinstance(a, str) and a.startswith("OUT"):
            outputs.append(tmp_path / ("out" + a[3:]))
            args.append(outputs[-1])
        else:
            args.append(a)
    return args, inputs, outputs


# -- capture serial -----------------------------------------------------------------------------------------------
@pytest.fixture
def pty_port():
    """A real serial-like port (a pseudo-terminal) that opens: the output is what fails."""
    from imutool.capture.serve import open_pty

    master, slave, name = open_pty()
    yield name
    os.close(slave)
    os.close(master)


@pytest.mark.parametrize("target", ["/proc/imutool_test.csv", "/proc/imutool/x.csv", "/proc/self/imutool/x.csv"])
@pytest.mark.parametrize("protocol", ["nmea", "bridge"])
def test_capture_serial_onto_proc_is_one_line(pty_port, target, protocol):
    """Was: internal error FileNotFoundError (the folder under /proc could not be made)."""
    check(
        ["capture", "serial", pty_port, "--protocol", protocol, "-o", target, "--duration", "1", "-q"],
        inputs=[],
        names=[target],
    )


@pytest.mark.parametrize("port", ["/dev/imutool-no-such-port", "/dev/null"])
@pytest.mark.parametrize("protocol", ["nmea", "bridge"])
def test_capture_serial_on_a_bad_port_leaves_no_folder(tmp_path, port, protocol):
    """A missing or non-serial port: one line, and the output folder it would have made is not there."""
    out = tmp_path / "voyage" / "deck"
    check(["capture", "serial", port, "--protocol", protocol, "-o", out, "-q"], inputs=[], outputs=[out], names=[port])
    assert not (tmp_path / "voyage").exists()


# -- gyro-free layouts --------------------------------------------------------------------------------------------
BAD_LAYOUTS = [
    "layout_1e300.toml",
    "layout_2km.toml",
    "layout_pos_text.toml",
    "layout_pos_strings.toml",
    "layout_cols_numbers.toml",
    "layout_unit_number.toml",
    "layout_unit_unknown.toml",
    "layout_unit_not_accel.toml",
    "layout_sensor_not_table.toml",
    "layout_preset_r_text.toml",
    "layout_preset_r_huge.toml",
    "layout_noise_text.toml",
    "layout_folder.toml",
]


@pytest.mark.parametrize("layout", BAD_LAYOUTS)
@pytest.mark.parametrize("mode", ["run", "check", "check-input"])
def test_bad_gyrofree_layout_is_one_line(files, tmp_path, layout, mode):
    """Every layout key of a wrong type, a position of 1e300 m (was: SVD did not converge) and a folder (was:
    IsADirectoryError): refused, one line naming the layout, with and without --check-layout."""
    out = tmp_path / "rates.csv"
    lay = files[layout]
    args = {
        "run": ["gyrofree", files["array.csv"], "--layout", lay, "-o", out, "-q"],
        "check": ["gyrofree", "--layout", lay, "--check-layout", "-q"],
        "check-input": ["gyrofree", files["array.csv"], "--layout", lay, "--check-layout", "-q"],
    }[mode]
    check(args, inputs=[files["array.csv"], lay], outputs=[out], names=[lay])


def test_check_layout_refuses_columns_the_input_lacks(files):
    """--check-layout with INPUT: a column the recording does not have is exit 2 (was: exit 0)."""
    lay = files["layout_missing_cols.toml"]
    _, _, err = check(
        ["gyrofree", files["array.csv"], "--layout", lay, "--check-layout", "-q"],
        inputs=[files["array.csv"], lay],
        names=[lay],
    )
    assert "nope_x" in err
    code, _, err = run(["gyrofree", files["array.csv"], "--layout", LAYOUT, "--check-layout", "-q"])
    assert code == 0, err


# -- ROS2 bags onto a full disk ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) for n in ("full.db3", "fullbag", "full.mcap")] + ["full.bag"]
)
def test_bag_onto_a_full_disk_is_one_line(files, tmp_path, name):
    """Was: internal error 'database or disk is full' (sqlite3) for .db3 and bag folders."""
    run(["convert", files["roll.csv"], tmp_path / "warm.db3", "-q"])  # the bag kernels compiled, outside the limit
    out = tmp_path / name
    before = snapshot([files["roll.csv"]])
    p = _limited(["convert", files["roll.csv"], out, "-q"], tmp_path, 20_000)
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr and "internal error" not in p.stderr
    lines = [ln for ln in p.stderr.strip().splitlines() if not ln.startswith("imutool: compiling")]
    assert len(lines) == 1 and out.name in lines[0], p.stderr
    assert not leftovers(out)
    assert not [q for q in tmp_path.iterdir() if q.name.startswith(".imutool-bag.")]
    assert snapshot([files["roll.csv"]]) == before


# -- TOML files with a key of the wrong type -----------------------------------------------------------------------
@pytest.mark.parametrize(
    "profile",
    [
        "profile_scale_text.toml",  # was: internal error ValueError
        "profile_scale_zero.toml",
        "profile_scale_nan.toml",
        "profile_scale_bool.toml",
        "profile_to_number.toml",
        "profile_unit_number.toml",
        "profile_unit_unknown.toml",
        "profile_unknown_key.toml",
        "profile_columns_list.toml",
    ],
)
@pytest.mark.parametrize("cmd", ["info", "convert"])
def test_column_profile_of_a_wrong_type_is_one_line(files, tmp_path, profile, cmd):
    out = tmp_path / "o.csv"
    args = ["info", files["roll.csv"]] if cmd == "info" else ["convert", files["roll.csv"], out, "-q"]
    check(
        [*args, "--profile", files[profile]],
        inputs=[files["roll.csv"], files[profile]],
        outputs=[out],
        names=[files[profile]],
    )


@pytest.mark.parametrize("spec", ["gyro_x=gyro_x:rad/s*nan", "gyro_x=gyro_x:rad/s*0", "gyro_x=gyro_x:rad/s*inf"])
def test_columns_option_scale_must_be_finite_and_nonzero(files, spec):
    check(["info", files["roll.csv"], "--columns", spec], inputs=[files["roll.csv"]], names=["--columns"])


@pytest.mark.parametrize(
    "profile",
    [
        "modbus_address_text.toml",
        "modbus_scale_text.toml",
        "modbus_rate_text.toml",
        "modbus_rate_zero.toml",
        "modbus_unit_float.toml",
        "modbus_register_not_table.toml",
        "modbus_device_not_table.toml",
    ],
)
def test_modbus_profile_of_a_wrong_type_is_one_line(files, tmp_path, profile):
    out = tmp_path / "incl.csv"
    check(
        ["capture", "modbus", "/dev/imutool-no-such-port", "--profile", files[profile], "-o", out, "-q"],
        inputs=[files[profile]],
        outputs=[out],
        names=[files[profile]],
    )


@pytest.mark.parametrize("manifest", ["manifest_jobs_numbers.toml", "manifest_job_table.toml"])
def test_batch_manifest_of_a_wrong_type_is_one_line(files, manifest):
    check(["batch", "info", "--manifest", files[manifest]], inputs=[files[manifest]], names=[files[manifest]])


# -- options with a huge value ---------------------------------------------------------------------------------------
HUGE_CASES = {
    "evaluate-max-lag-1e9": ["evaluate", "@est.csv", "--reference", "@roll.csv", "--max-lag", "1e9"],  # was: killed
    "evaluate-max-lag-1e300": ["evaluate", "@est.csv", "--reference", "@roll.csv", "--max-lag", "1e300"],
    "report-max-lag-1e9": [
        "report",
        "heading",
        "@est.csv",
        "--reference",
        "@roll.csv",
        "-o",
        "OUT.pdf",
        "--max-lag",
        "1e9",
    ],
    "heave-tilt-gain-1e300": ["heave", "@roll.csv", "-o", "OUT.csv", "--tilt-gain", "1e300"],  # was: OverflowError
    "zvi-window-1e300": ["zvi", "@roll.csv", "-o", "OUT.csv", "--window", "1e300"],
    "zvi-sigma-a-1e300": ["zvi", "@roll.csv", "-o", "OUT.csv", "--sigma-a", "1e300"],
    "zvi-sigma-g-1e300": ["zvi", "@roll.csv", "-o", "OUT.csv", "--sigma-g", "1e300"],
    "gyrofree-noise-1e300": ["gyrofree", "@array.csv", "--layout", "paper", "-o", "OUT.csv", "--noise", "1e300"],
    "gyrofree-rate-rw-1e300": ["gyrofree", "@array.csv", "--layout", "paper", "-o", "OUT.csv", "--rate-rw", "1e300"],
    "convert-chunk-rows-1e30": ["convert", "@roll.csv", "OUT.csv", "--chunk-rows", str(10**30)],
    "plot-max-points-1e30": ["plot", "@roll.csv", "gyro", "-o", "OUT.png", "--max-points", str(10**30)],
    "filter-stream-mb-1e300": ["filter", "@roll.csv", "-o", "OUT.csv", "--stream-mb", "1e300"],
    "events-min-cycles-1e30": ["events", "detect", "@est.csv", "-o", "OUT.json", "--min-cycles", str(10**30)],
}


@pytest.mark.parametrize("case", list(HUGE_CASES))
def test_huge_option_is_refused(files, tmp_path, case):
    args, inputs, outputs = _args(HUGE_CASES[case], files, tmp_path)
    opt = [a for a in HUGE_CASES[case] if a.startswith("--")][-1]
    check([*args, "-q"] if args[0] != "evaluate" else args, inputs=inputs, outputs=outputs, names=[opt])


def test_every_option_bounded_below_is_bounded_above():
    """The kind: no numeric option takes an unbounded value (an array size or a variance from 1e300)."""
    import click

    from imutool.cli import COMMANDS, cli
    from imutool.cli.ranges import is_numeric

    ctx = click.Context(cli)
    open_ended = []

    def walk(cmd, path):
        for p in cmd.params:
            t = p.type
            if is_numeric(p) and getattr(t, "min", None) is not None and t.min >= 0 and t.max is None:
                open_ended.append(f"{path} --{p.name}")
        if isinstance(cmd, click.Group):
            for name, sub in cmd.commands.items():
                walk(sub, f"{path} {name}")

    for name in COMMANDS:
        cmd = cli.get_command(ctx, name)
        if cmd is not None:
            walk(cmd, name)
    assert not open_ended, f"options without an upper bound: {open_ended}"


def test_lag_search_is_bounded_by_the_data():
    """best_lag over ±1 h on 30 s of data: the search stops at the data's span and finds the true lag."""
    from imutool.metrics import best_lag

    t = np.arange(0, 30, 0.02)
    walk = np.cumsum(np.random.default_rng(5).normal(size=len(t)))  # not periodic: one best lag
    ref = walk
    x = np.interp(t - 0.3, t, walk)
    lag, rms = best_lag(t[100:], x[100:], t, ref, 3600.0)
    assert abs(lag - 0.3) < 0.01 and rms < 0.01


# -- fits the data cannot determine -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "case",
    [
        ["calibrate", "accel", "@static.csv", "-o", "OUT.toml", "--min-poses", "1"],  # one pose, 6 parameters
        ["calibrate", "accel", "@static.csv", "-o", "OUT.toml", "--min-poses", "1", "--kind", "offset"],
        ["calibrate", "accel", "@static.csv", "-o", "OUT.toml", "--min-poses", "1", "--kind", "full"],
        ["calibrate", "mag", "@static.csv", "-o", "OUT.toml", "--min-coverage", "0"],  # a point cloud
        ["calibrate", "mag", "@static.csv", "-o", "OUT.toml", "--min-coverage", "0", "--kind", "offset"],
        ["calibrate", "mag", "@static.csv", "-o", "OUT.toml", "--min-coverage", "0", "--kind", "full"],
        ["calibrate", "deviation", "@static.csv", "-o", "OUT.toml", "--min-span", "0.001", "--variation", "0"],
    ],
    ids=["accel-diag", "accel-offset", "accel-full", "mag-auto", "mag-offset", "mag-full", "deviation"],
)
def test_a_floor_option_never_allows_an_undetermined_fit(files, tmp_path, case):
    args, inputs, outputs = _args(case, files, tmp_path)
    _, _, err = check([*args, "-q"], inputs=inputs, outputs=outputs)
    if "mag" in case or "accel" in case:
        assert "rank" in err, err


def test_gyro_temperature_slope_needs_a_temperature_that_varies():
    """--min-temp-range 0 on a constant temperature: no slope (the fit would be singular), the bias stands."""
    from calibration.inertial import calibrate_gyro

    t = np.arange(0, 20, 0.01)
    g = np.random.default_rng(0).normal(0.01, 1e-4, (len(t), 3))
    cal = calibrate_gyro(t, g, None, np.full(len(t), 25.0), min_temp_range=0.0)
    assert cal.temp_slope is None and "constant" in cal.quality["temp_note"]
    np.testing.assert_allclose(cal.bias, 0.01, atol=1e-4)


def test_mag_fit_still_works_on_a_sphere(tmp_path):
    """The rank check does not refuse a real tumble."""
    from calibration.magnetometer import calibrate_sphere
    from imutool import sim

    rec = sim.simulate("mag-sphere", seed=2)
    fit = calibrate_sphere(rec["mag"])
    assert fit.coverage > 0.6


# -- recordings without a duration or without sensor data --------------------------------------------------------
NO_DURATION = {
    "info": ["info", "@one_time.csv"],
    "convert": ["convert", "@one_time.csv", "OUT.csv", "-q"],
    "convert-streamed": ["convert", "@one_time.csv", "OUT.csv", "-q", "--chunk-rows", "100"],
    "convert-bag": ["convert", "@one_time.csv", "OUT.db3", "-q"],
    "filter": ["filter", "@one_time.csv", "-o", "OUT.csv", "-q"],
    "filter-streamed": ["filter", "@one_time.csv", "-o", "OUT.csv", "-q", "--stream-mb", "0", "--chunk-rows", "100"],
    "plot": ["plot", "@one_time.csv", "gyro", "-o", "OUT.png", "-q"],
    "evaluate": ["evaluate", "@one_time.csv", "--reference", "@roll.csv"],
    "evaluate-ref": ["evaluate", "@est.csv", "--reference", "@one_time.csv"],
    "heave": ["heave", "@one_time.csv", "-o", "OUT.csv", "-q"],
}


@pytest.mark.parametrize("case", list(NO_DURATION))
def test_one_time_stamp_is_no_recording(files, tmp_path, case):
    """2 000 rows with one time stamp: 1 999 dropped, and one row is not a recording (was: exit 0 with 1 row)."""
    args, inputs, outputs = _args(NO_DURATION[case], files, tmp_path)
    _, _, err = check(args, inputs=inputs, outputs=outputs, names=[files["one_time.csv"]])
    assert "no duration" in err, err


@pytest.mark.parametrize(
    "case",
    [
        ["convert", "@all_nan.csv", "OUT.csv", "-q"],
        ["convert", "@all_nan.csv", "OUT.csv", "-q", "--chunk-rows", "100"],
        ["convert", "@all_nan.csv", "OUT.bag", "-q"],
        ["info", "@all_nan.csv"],
        ["filter", "@all_nan.csv", "-o", "OUT.csv", "-q"],
    ],
    ids=["convert", "convert-streamed", "convert-bag", "info", "filter"],
)
def test_every_sensor_value_missing_is_refused(files, tmp_path, case):
    """Was: convert exit 0 without a warning. The message names the channels."""
    args, inputs, outputs = _args(case, files, tmp_path)
    _, _, err = check(args, inputs=inputs, outputs=outputs)
    if "--chunk-rows" in case or case[0] in ("convert", "info"):
        assert "gyro, accel, mag" in err, err


@pytest.mark.parametrize("stream", [[], ["--chunk-rows", "100"]])
def test_one_sensor_channel_missing_is_a_warning(files, tmp_path, stream):
    """gyro and accel present, mag empty in every row: written with a warning naming mag; --strict refuses."""
    text = files["roll.csv"].read_text().splitlines()
    header = next(ln for ln in text if not ln.startswith("#")).split(",")
    cols = [j for j, c in enumerate(header) if c.startswith("mag_")]
    rows = []
    for ln in text:
        v = ln.split(",")
        if not ln.startswith("#") and v != header:
            v = ["" if j in cols else x for j, x in enumerate(v)]
        rows.append(",".join(v))
    src = tmp_path / "no_mag.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "o.csv"
    code, _, err = run(["convert", src, out, "-q", *stream])
    assert code == 0 and "every value of mag" in err, err
    out.unlink()
    _, _, err = check(["convert", src, out, "-q", "--strict", *stream], inputs=[src], outputs=[out])
    assert "every value of mag" in err


@pytest.mark.parametrize("cmd", [["info"], ["convert", "OUT.csv", "-q"], ["filter", "-o", "OUT.csv", "-q"]])
def test_duplicate_column_names_are_refused(files, tmp_path, cmd):
    args, inputs, outputs = _args([cmd[0], "@dup_cols.csv", *cmd[1:]], files, tmp_path)
    _, _, err = check(args, inputs=inputs, outputs=outputs)
    assert "'accel_x'" in err, err


# -- evaluate against a reference that cannot be compared ---------------------------------------------------------
@pytest.mark.parametrize("ref", ["late.csv", "ref_one_row.csv", "one_time.csv"])
def test_evaluate_reference_without_overlap_or_rows(files, ref):
    _, _, err = check(
        ["evaluate", files["est.csv"], "--reference", files[ref]],
        inputs=[files["est.csv"], files[ref]],
        names=[files[ref]],
    )


def test_evaluate_still_compares_an_overlapping_reference(files):
    code, out, err = run(["evaluate", files["est.csv"], "--reference", files["roll.csv"], "--json"])
    assert code == 0, err


# -- options a result cannot take ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "case",
    [
        ["filter", "@roll.csv", "-o", "OUT.csv", "--method", "lpf", "--cutoff", "25"],  # 50 Hz: the Nyquist frequency
        ["filter", "@roll.csv", "-o", "OUT.csv", "--method", "lpf", "--cutoff", "30"],
        ["heave", "@roll.csv", "-o", "OUT.csv", "--delayed-cutoff", "1e6"],  # a high-pass above Nyquist: all gone
        ["simulate", "sea-state", "-o", "OUT.csv", "--duration", "5", "--set", "hs=-2"],
        ["simulate", "sea-state", "-o", "OUT.csv", "--duration", "5", "--set", "components=0"],
        ["simulate", "sea-state", "-o", "OUT.csv", "--duration", "5", "--set", "gamma=0.5"],
        ["simulate", "sea-state", "-o", "OUT.csv", "--duration", "5", "--set", "accel_noise_ug=-1"],
    ],
    ids=["lpf-nyquist", "lpf-above", "heave-delayed-cutoff", "hs-neg", "components0", "gamma", "noise-neg"],
)
def test_option_no_result_can_take(files, tmp_path, case):
    args, inputs, outputs = _args(case, files, tmp_path)
    check(
        [*args, "-q"], inputs=inputs, outputs=outputs, names=[*inputs, *outputs, "hs", "gamma", "components", "noise"]
    )


@pytest.mark.parametrize(
    "topic", ["no slash !!", "/imu//data", "/imu/data/", "/9imu", "/imu/9", "/imu__data", "", "~/imu", "/{ns}/imu"]
)
@pytest.mark.parametrize("opt,ext", [("--imu-topic", ".db3"), ("--mag-topic", ".bag"), ("--imu-topic", "")])
def test_invalid_ros_topic_names_are_refused(files, tmp_path, topic, opt, ext):
    out = tmp_path / ("bag" + ext)
    _, _, err = check(["convert", files["roll.csv"], out, opt, topic, "-q"], inputs=[files["roll.csv"]], outputs=[out])
    assert "ROS topic name" in err


@pytest.mark.parametrize("topic", ["/imu/data", "imu/data", "/vessel_1/imu_raw/data"])
def test_valid_ros_topic_names_are_written(files, tmp_path, topic):
    from formats.bags.writer import check_topic_name

    assert check_topic_name(topic) == topic


@pytest.mark.slow
def test_full_disk_with_a_cold_kernel_cache_is_one_line(files, tmp_path, monkeypatch):
    """After an upgrade the kernels compile again; a cache entry the full disk cannot take is skipped (was: internal
    error OSError 'File too large' from numba's cache), and the output's own error is the one line."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cold-cache"))
    out = tmp_path / "full.csv"
    p = _limited(["convert", files["roll.csv"], out, "-q"], tmp_path, 20_000)
    assert p.returncode == 2, p.stderr
    lines = [ln for ln in p.stderr.strip().splitlines() if not ln.startswith("imutool: compiling")]
    assert len(lines) == 1 and out.name in lines[0] and "internal error" not in p.stderr, p.stderr
    assert not leftovers(out)
