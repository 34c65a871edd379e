"""Every command's library route gives the command line's output bit for bit, and the summary its --json prints.

For each command the CLI (click's CliRunner, in-process) writes into one folder and the Python route (``run_*``)
into another, under the same relative names: the output files must be byte-identical and the route's summary
(:meth:`imutool.routes.RouteResult.full_summary`, as JSON) equal to the CLI's ``--json``. A last test runs
``imutool batch`` over the routes and checks it writes the same files and reports the same rows.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from formats import Recording
from imutool.cli import cli
from imutool.cli.common import json_default
from imutool.events import run_events
from imutool.nmea_out import run_nmea
from imutool.report.heading import HeadingOptions
from imutool.report.inclinometer import InclinometerOptions
from imutool.report.route import run_heading_report, run_inclinometer_report
from imutool.routes import RouteResult
from imutool.routes.gyrofree import run_gyrofree
from imutool.routes.heave import run_heave
from imutool.routes.ins import run_ins_track
from imutool.routes.zvi import run_zvi
from imutool.sim import simulate

INC_STEPS = {
    "steps": (0.0, 5.0, 10.0, 30.0, -5.0, -10.0, -30.0, 0.0),
    "hold_s": 15.0,
    "dynamic": ((8.0, 10.0, 10.0, 5), (12.0, 20.0, 14.0, 4)),
    "long_s": 0.0,
}


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> dict[str, str]:
    """Small inputs, one per kind of command (written once for the module)."""
    from imutool.sim.programmes import heading_test, inclinometer_test

    d = tmp_path_factory.mktemp("inputs")
    paths = {k: str(d / f"{k}.csv") for k in ("sea", "walk", "array", "pr", "att", "inc_dut", "inc_ref", "roll")}
    paths.update({k: str(d / f"{k}.csv") for k in ("hdg_dut", "hdg_ref")})
    formats.write(simulate("sea-state", duration=60, seed=1), paths["sea"])
    formats.write(simulate("ship-roll", duration=30, seed=5), paths["roll"])
    formats.write(simulate("walk", seed=2, n_steps=4), paths["walk"])
    formats.write(simulate("accel-array", duration=20, rate_hz=100, seed=4), paths["array"])
    formats.write(simulate("parametric-roll", duration=400.0, rate_hz=10.0, seed=0), paths["pr"])
    r = simulate("ship-roll", duration=60, seed=3)
    att = Recording(r.time.copy(), meta={"scenario": "ship-roll"})
    for name in ("roll", "pitch", "heading"):
        att.add(name, r[f"ref_{name}"], "deg")
    formats.write(att, paths["att"])
    dut, ref, _ = inclinometer_test(offset_deg=0.3, noise_deg=0.05, seed=2, **INC_STEPS)
    formats.write(dut, paths["inc_dut"])
    formats.write(ref, paths["inc_ref"])
    dut, ref, _ = heading_test(offset_deg=0.2, noise_deg=0.05, hold_s=15.0, rolling_s=40.0)
    formats.write(dut, paths["hdg_dut"])
    formats.write(ref, paths["hdg_ref"])
    return paths


def _cli(args: list[str]) -> tuple[int, dict[str, Any]]:
    """`imutool ARGS --json` in-process: (exit status, the JSON summary)."""
    res = CliRunner().invoke(cli, [*args, "--json"])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.output
    return res.exit_code, json.loads(res.stdout)


def _same(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    args: list[str],
    route: Callable[[], RouteResult],
    outputs: list[str],
    volatile: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Run the CLI in tmp/cli and the route in tmp/lib (same relative output names); assert byte-identical
    outputs and equal summaries (less the ``volatile`` keys, e.g. a wall-clock time). Returns the summary."""
    for side in ("cli", "lib"):
        (tmp_path / side).mkdir()
    monkeypatch.chdir(tmp_path / "cli")
    code, cli_summary = _cli(args)
    monkeypatch.chdir(tmp_path / "lib")
    res = route()
    assert code == res.exit_status
    lib_summary = json.loads(json.dumps(res.full_summary(), default=json_default))
    for k in volatile:
        assert k in cli_summary and k in lib_summary
        cli_summary.pop(k)
        lib_summary.pop(k)
    assert lib_summary == cli_summary
    for name in outputs:
        a, b = tmp_path / "cli" / name, tmp_path / "lib" / name
        assert a.exists() and a.read_bytes() == b.read_bytes(), name
    return cli_summary


def test_heave(data, tmp_path, monkeypatch):
    args = ["heave", data["sea"], "-o", "h.csv", "--nmea", "h.nmea", "--heave-positive", "down", "--hop", "5"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_heave(data["sea"], "h.csv", nmea="h.nmea", heave_positive="down", hop_s=5),
        ["h.csv", "h.nmea"],
    )
    assert s["heave_positive"] == "down" and s["nmea"]["sentences"]["PASHR"] > 0
    # the sign flip is the library's: a Python caller gets heave positive down, the header says so
    up = run_heave(data["sea"], hop_s=5).recording
    down = formats.read(tmp_path / "lib" / "h.csv")
    np.testing.assert_array_equal(down["heave"], -up["heave"])
    assert down.meta["heave_positive"] == "down" and "positive DOWN" in down.meta["heave"]


def test_ins(data, tmp_path, monkeypatch):
    args = ["ins", data["walk"], "-o", "t.csv", "--strides", "s.csv", "--height-update", "--gyro-noise", "0.4"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_ins_track(data["walk"], "t.csv", strides_path="s.csv", height_update=True, gyro_noise_deg=0.4),
        ["t.csv", "s.csv"],
    )
    # the stride table through the imutool CSV number formatter: a header, one row a stride, read back as numbers
    lines = (tmp_path / "lib" / "s.csv").read_text().splitlines()
    assert lines[0] == "start_s,end_s,length_m,height_change_m,swing_s,duration_s"
    assert len(lines) == 1 + s["strides"]["count"] and s["strides"]["count"] >= 3
    lengths = [float(x.split(",")[2]) for x in lines[1:]]
    assert abs(np.mean(lengths) - s["strides"]["mean_length_m"]) < 1e-3
    assert 1.0 < np.mean(lengths) < 1.8  # the simulated 1.4 m strides


def test_zvi(data, tmp_path, monkeypatch):
    args = ["zvi", data["walk"], "-o", "iv.csv", "--flags", "f.csv", "--detector", "paper", "--b-g", "30"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_zvi(data["walk"], "iv.csv", flags_path="f.csv", detector="paper", b_g_deg_s=30),
        ["iv.csv", "f.csv"],
    )
    assert s["params"]["b_g_deg_s"] == 30.0 and s["score_vs_ref_zvi"]["f1"] > 0.9


def test_nmea(data, tmp_path, monkeypatch):
    args = ["nmea", data["att"], "-o", "a.nmea", "--sentences", "HRM,XDR,HDG,THS", "--variation", "-3.5"]
    args += ["--talker", "HRM=YX", "--time-prefix"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_nmea(
            data["att"],
            "a.nmea",
            sentences="HRM,XDR,HDG,THS",
            variation_deg=-3.5,
            talkers={"HRM": "YX"},
            time_prefix=True,
            roll_kw={
                "hysteresis_deg": 0.5,
                "centre": "zero",
                "centre_window_s": 120.0,
                "refine_frac": 0.2,
                "max_period_s": 60.0,
                "resets_s": [],
                "utc_start": None,
            },
        ),
        ["a.nmea"],
        volatile=("generated_utc",),
    )
    assert set(s["sentences"]) == {"HRM", "XDR", "HDG", "THS"} and s["total"] == sum(s["sentences"].values())
    text = (tmp_path / "lib" / "a.nmea").read_text()
    assert "$YXHRM," in text and text.startswith("# imutool nmea from")


def test_gyrofree(data, tmp_path, monkeypatch):
    args = ["gyrofree", data["array"], "--layout", "paper", "-o", "w.csv", "--tilt-gain", "0.05"]
    s = _same(tmp_path, monkeypatch, args, lambda: run_gyrofree(data["array"], "w.csv", tilt_gain=0.05), ["w.csv"])
    assert s["layout"].startswith("paper") and s["rows"] == 2001


def test_events(data, tmp_path, monkeypatch):
    args = ["events", "detect", data["pr"], "-o", "ev.json", "--events-csv", "ev.csv", "--roll-channel", "ref_roll"]
    args += ["--pitch-channel", "ref_pitch"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_events(
            data["pr"], "ev.json", events_csv="ev.csv", roll_channel="ref_roll", pitch_channel="ref_pitch"
        ),
        ["ev.json", "ev.csv"],
    )
    assert s["rows"] == 4001


@pytest.fixture
def fixed_clock(monkeypatch):
    """Reports stamp the time they were made (JSON and PDF): the same for both runs."""
    import imutool.report.heading as hd
    import imutool.report.inclinometer as inc

    monkeypatch.setattr(inc, "now_utc", lambda: "2026-11-27T00:00:00Z")
    monkeypatch.setattr(hd, "now_utc", lambda: "2026-11-27T00:00:00Z")
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")  # matplotlib's PDF creation date


@pytest.mark.slow
def test_report_inclinometer(data, tmp_path, monkeypatch, fixed_clock):
    args = ["report", "inclinometer", data["inc_dut"], "--reference", data["inc_ref"], "-o", "inc.pdf"]
    args += ["--align", "xcorr", "--angle-floor", "1.5"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_inclinometer_report(
            data["inc_dut"],
            data["inc_ref"],
            "inc.pdf",
            options=InclinometerOptions(align="xcorr", angle_floor_deg=1.5),
        ),
        ["inc.pdf", "inc.json"],
    )
    # a CSV heel: amplitude, period and peak hold are not the device's own values, so never PASS (exit status 1)
    assert s["exit_status"] == 1 and s["overall"] != "pass" and "static_heel" in s["items"]


def test_report_heading(data, tmp_path, monkeypatch, fixed_clock):
    args = ["report", "heading", data["hdg_dut"], "--reference", data["hdg_ref"], "-o", "hdg.pdf"]
    args += ["--static-limit", "0.9", "--device", "DUT 1"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_heading_report(
            data["hdg_dut"], data["hdg_ref"], "hdg.pdf", options=HeadingOptions(static_limit_deg=0.9), device="DUT 1"
        ),
        ["hdg.pdf", "hdg.json"],
    )
    assert s["items"]["static"]["status"] == "pass"


def test_route_errors_are_the_commands(data, tmp_path, monkeypatch, capsys):
    """A bad option value is refused by the route with the command's own message (the command adds the input's
    name), before anything is written."""
    from formats.errors import ImutoolError
    from imutool.cli import main

    monkeypatch.chdir(tmp_path)
    cases = [
        (["zvi", data["walk"], "-o", "a.csv", "--detector", "paper", "--gamma", "3"], run_zvi, "does not take --gamma"),
        (["ins", data["walk"], "-o", "b.csv", "--zvi-column", "nosuch"], run_ins_track, "ZVI column 'nosuch' not"),
        (["nmea", data["sea"], "-o", "c.nmea", "--sentences", "HDT"], run_nmea, "HDT need a heading channel"),
    ]
    kws: list[dict[str, Any]] = [{"detector": "paper", "gamma": 3.0}, {"zvi_column": "nosuch"}, {"sentences": "HDT"}]
    for (args, route, expect), kw in zip(cases, kws, strict=True):
        with pytest.raises(SystemExit) as e:
            main(args)
        cli_err = capsys.readouterr().err.strip()
        assert e.value.code == 2 and cli_err.startswith(f"imutool {args[0]}: error: ")
        with pytest.raises(ImutoolError) as err:
            route(args[1], args[3], **kw)
        assert expect in str(err.value) and cli_err.endswith(str(err.value)), (cli_err, str(err.value))
        assert not os.path.exists(args[3])


def test_batch_calls_the_routes(data, tmp_path, monkeypatch, capsys):
    """`imutool batch zvi` runs the library route per input (no stdout read back): the same file as the
    command, the key figures of its summary, a failing input listed with the command's own message."""
    from imutool.cli import main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        main(["batch", "zvi", data["walk"], data["array"], "-o", "b/{stem}.csv", "-j", "1", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert e.value.code == 1, out  # the accelerometer array has no gyro
    res = {Path(r["input"]).stem: r for r in out["results"]}
    assert res["walk"]["status"] == "ok" and res["array"]["status"] == "failed"
    assert res["array"]["error"].startswith(data["array"] + ": needs channel(s) gyro")
    code, single = _cli(["zvi", data["walk"], "-o", "single.csv"])
    assert code == 0 and (tmp_path / "b" / "walk.csv").read_bytes() == (tmp_path / "single.csv").read_bytes()
    assert res["walk"]["figures"]["intervals"] == single["intervals"] > 3
    assert res["walk"]["figures"]["samples"] == single["samples"]


def test_filter(data, tmp_path, monkeypatch):
    """filter: the library's run_filter writes the command's file byte for byte, and its summary with what
    loading did (``validation``) is the command's --json."""
    from imutool.filtering import run_filter
    from imutool.routes import with_inputs

    args = ["filter", data["roll"], "-o", "est.csv", "--lever-arm", "0,0,-3"]

    def route() -> RouteResult:
        res = run_filter(data["roll"], "est.csv", lever_arm=[0.0, 0.0, -3.0])
        inputs = [{"input": data["roll"], **res.validation}]
        return RouteResult(with_inputs(res.summary, inputs), inputs, res.recording)

    s = _same(tmp_path, monkeypatch, args, route, ["est.csv"])
    assert s["method"] == "ekf" and s["rows"] == 6001


def test_batch_filter_calls_the_route(data, tmp_path, monkeypatch, capsys):
    """`imutool batch filter` runs the command's library route in the worker (the command line is never run):
    the same file as `imutool filter`, the same rows."""
    import imutool.cli.batch as cli_batch
    from imutool.cli import main

    def no_cli(*a, **k):
        raise AssertionError("batch ran the command line, not the route")

    monkeypatch.setattr(cli_batch, "run_command", no_cli)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        main(
            ["batch", "filter", data["roll"], "-o", "b/{stem}.csv", "-j", "1", "--json", "--args", "--lever-arm 0,0,-3"]
        )
    out = json.loads(capsys.readouterr().out)
    assert e.value.code == 0, out
    code, single = _cli(["filter", data["roll"], "-o", "single.csv", "--lever-arm", "0,0,-3"])
    assert code == 0 and (tmp_path / "b" / "roll.csv").read_bytes() == (tmp_path / "single.csv").read_bytes()
    assert out["results"][0]["rows"] == single["rows"] == 6001


# -- the other commands: convert, calibrate, roll, allan, info, plot, simulate, events fleet ---------------------
@pytest.fixture(scope="module")
def more(tmp_path_factory, data) -> dict[str, str]:
    """Inputs of the calibration, noise and fleet commands (written once for the module)."""
    d = tmp_path_factory.mktemp("more")
    paths = {k: str(d / f"{k}.csv") for k in ("sphere", "swing", "sixpos", "static")}
    formats.write(simulate("mag-sphere", duration=60, seed=7), paths["sphere"])
    formats.write(simulate("compass-swing", duration=200, rate_hz=5, seed=9), paths["swing"])
    formats.write(simulate("six-position", seed=3), paths["sixpos"])
    formats.write(simulate("static", duration=200, rate_hz=50, seed=1), paths["static"])
    (d / "ev").mkdir()
    run_events(data["pr"], d / "ev" / "pr.json", roll_channel="ref_roll", pitch_channel="ref_pitch")
    run_events(data["att"], d / "ev" / "att.json")
    paths["ev"] = str(d / "ev")
    paths["ev_pr"] = str(d / "ev" / "pr.json")
    return paths


def _same_toml(tmp_path: Path, name: str) -> None:
    """The calibration files of both runs are the same but for the time stamp of the provenance."""
    import re

    a, b = ((tmp_path / side / name).read_text() for side in ("cli", "lib"))
    assert re.sub(r"date_utc = .*", "", a) == re.sub(r"date_utc = .*", "", b) and "[" in a


@pytest.mark.parametrize("ext", [".parquet", ".nmea"])
def test_convert(data, tmp_path, monkeypatch, ext):
    from imutool.convert import run_convert

    args = ["convert", data["att"], f"o{ext}"] + (["--sentences", "HDT,XDR"] if ext == ".nmea" else [])
    s = _same(tmp_path, monkeypatch, args, lambda: run_convert(data["att"], f"o{ext}"), [f"o{ext}"])
    assert s["rows_in"] == 12001 and s["validation"][0]["rows_kept"] == 12001


def test_calibrate_mag(more, tmp_path, monkeypatch):
    from imutool.calibrate import calibrate_mag

    args = ["calibrate", "mag", more["sphere"], "-o", "cal.toml", "--kind", "diag", "--plot", "p.png"]
    route = lambda: calibrate_mag(more["sphere"], "cal.toml", kind="diag", plot="p.png")  # noqa: E731
    s = _same(tmp_path, monkeypatch, args, route, ["p.png"])
    _same_toml(tmp_path, "cal.toml")
    assert s["kind"] == "diag" and s["validation"][0]["input"] == more["sphere"]


def test_calibrate_gyro_and_accel(more, tmp_path, monkeypatch):
    from imutool.calibrate import calibrate_accel, calibrate_gyro, rest_options

    (tmp_path / "g").mkdir()
    args = ["calibrate", "gyro", more["sixpos"], "-o", "g.toml", "--min-rest", "1.5"]
    route = lambda: calibrate_gyro(more["sixpos"], "g.toml", rest=rest_options(min_rest_s=1.5))  # noqa: E731
    _same(tmp_path / "g", monkeypatch, args, route, [])
    _same_toml(tmp_path / "g", "g.toml")
    (tmp_path / "a").mkdir()
    args = ["calibrate", "accel", more["sixpos"], "-o", "a.toml", "--latitude", "59.4"]
    route = lambda: calibrate_accel(more["sixpos"], "a.toml", latitude=59.4)  # noqa: E731
    s = _same(tmp_path / "a", monkeypatch, args, route, [])
    _same_toml(tmp_path / "a", "a.toml")
    assert s["gravity_m_s2"] > 9.81


def test_calibrate_deviation_and_show(more, tmp_path, monkeypatch):
    from imutool.calibrate import deviation_card, show_calibration

    args = ["calibrate", "deviation", more["swing"], "-o", "card.txt", "-o", "cal.toml", "--vessel", "MV T", "--new"]
    route = lambda: deviation_card(more["swing"], ["card.txt", "cal.toml"], vessel="MV T", append=False)  # noqa: E731
    s = _same(tmp_path, monkeypatch, args, route, ["card.txt"])
    _same_toml(tmp_path, "cal.toml")
    assert s["header"]["vessel"] == "MV T"
    for form in ("text", "json"):  # `calibrate show` prints the library's text as it is
        res = CliRunner().invoke(cli, ["calibrate", "show", "cal.toml", "--as", form])
        assert res.exit_code == 0 and res.stdout == show_calibration("cal.toml", form) and "deviation" in res.stdout


def test_roll(data, tmp_path, monkeypatch):
    from imutool.routes.roll import run_roll

    args = ["roll", data["att"], "-o", "rs.csv", "--cycles", "cy.csv", "--hysteresis", "0.7", "--reset", "30"]
    route = lambda: run_roll(data["att"], "rs.csv", cycles_path="cy.csv", hysteresis_deg=0.7, resets_s=[30.0])  # noqa: E731
    s = _same(tmp_path, monkeypatch, args, route, ["rs.csv", "cy.csv"])
    assert s["settings"]["hysteresis_deg"] == 0.7 and s["starboard"]["excursions"] > 3


def test_allan(more, tmp_path, monkeypatch):
    from imutool.noise import allan_noise

    args = ["allan", more["static"], "-o", "n.yaml", "--kalibr", "k.yaml", "--kalibr-fallback", "upper-bound"]
    route = lambda: allan_noise(more["static"], "n.yaml", kalibr="k.yaml", kalibr_fallback="upper-bound")  # noqa: E731
    s = _same(tmp_path, monkeypatch, args, route, ["n.yaml", "k.yaml"])
    assert set(s["channels"]) == {"gyro", "accel", "mag"}


def test_info_plot_simulate(data, tmp_path, monkeypatch):
    from imutool.info import run_info
    from imutool.plot import run_plot
    from imutool.sim import run_simulate

    for sub in "ips":
        (tmp_path / sub).mkdir()
    s = _same(tmp_path / "i", monkeypatch, ["info", data["roll"]], lambda: run_info(data["roll"]), [])
    assert s["rows"] == 6001 and s["channels"]["gyro"]["unit"] == "deg/s"
    args = ["plot", data["roll"], "gyro", "ref_roll", "-o", "p.png", "--max-points", "500"]
    route = lambda: run_plot(data["roll"], ["gyro", "ref_roll"], "p.png", max_points=500)  # noqa: E731
    s = _same(tmp_path / "p", monkeypatch, args, route, ["p.png"])
    assert s["channels"] == ["gyro", "ref_roll"] and s["points_per_line"] <= 502
    args = ["simulate", "static", "-o", "s.csv", "--duration", "5", "--seed", "2", "--set", "rate_hz=50"]
    route = lambda: run_simulate("static", "s.csv", duration=5, seed=2, settings={"rate_hz": 50})  # noqa: E731
    s = _same(tmp_path / "s", monkeypatch, args, route, ["s.csv"])
    assert s["rows"] == 251


def test_events_fleet(more, tmp_path, monkeypatch):
    from imutool.events import run_fleet

    args = ["events", "fleet", more["ev"], "-o", "fleet.csv", "--voyages", "v.csv"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_fleet(more["ev"], "fleet.csv", voyages_path="v.csv"),
        ["fleet.csv", "v.csv"],
    )
    assert s["results"] == 2 and s["parametric_roll_episodes"] >= 1


BATCH_CASES = {
    "convert": (["convert"], "att", ".parquet", ""),
    "roll": (["roll"], "att", ".csv", "--hysteresis 0.7"),
    "info": (["info"], "roll", None, ""),
    "plot": (["plot"], "roll", ".png", "gyro"),
    "allan": (["allan"], "static", ".yaml", "--channels gyro"),  # no top-level figure: --figure below
    "calibrate mag": (["calibrate", "mag"], "sphere", ".toml", ""),
    "calibrate gyro": (["calibrate", "gyro"], "sixpos", ".toml", "--min-rest 1.5"),
    "calibrate accel": (["calibrate", "accel"], "sixpos", ".toml", ""),
    "calibrate deviation": (["calibrate", "deviation"], "swing", ".txt", "--new"),
    "events fleet": (["events", "fleet"], "ev_pr", ".csv", ""),  # a folder input is walked for data files
}


@pytest.mark.parametrize("case", list(BATCH_CASES))
def test_batch_calls_the_route_of_each_command(data, more, tmp_path, monkeypatch, capsys, case):
    """`imutool batch COMMAND` runs the command's library route in the worker (the command line is never run):
    the job succeeds with the summary the command's --json prints."""
    import shlex

    import imutool.cli.batch as cli_batch
    from imutool.cli import main

    def no_cli(*a, **k):
        raise AssertionError("batch ran the command line, not the route")

    monkeypatch.setattr(cli_batch, "run_command", no_cli)
    monkeypatch.chdir(tmp_path)
    words, key, ext, extra = BATCH_CASES[case]
    src = {**data, **more}[key]
    argv = ["batch", " ".join(words), src, "-j", "1", "--json", "--args", extra]
    if ext:
        argv += ["-o", f"b/{{stem}}{ext}"]
    if case == "allan":
        argv += ["--figure", "channels.gyro.samples"]
    with pytest.raises(SystemExit) as e:
        main(argv)
    out = json.loads(capsys.readouterr().out)
    assert e.value.code == 0 and out["results"][0]["status"] == "ok", out
    single = [*words, src, *shlex.split(extra)] + (["-o", f"single{ext}"] if ext else [])
    code, summary = _cli(single)
    assert code == 0
    figures = out["results"][0]["figures"]
    assert figures
    for k, v in figures.items():  # the batch's key figures are the command's
        got: Any = summary
        for part in k.split("."):
            got = got[part]
        assert got == v, (k, v, got)


def test_batch_simulate_calls_the_route(tmp_path, monkeypatch, capsys):
    """Batch inputs are files, so `imutool batch simulate` runs only where a file carries the scenario's name;
    then it is the route that runs."""
    import imutool.cli.batch as cli_batch
    from imutool.cli import main

    monkeypatch.setattr(cli_batch, "run_command", lambda *a, **k: pytest.fail("batch ran the command line"))
    monkeypatch.chdir(tmp_path)
    Path("static").write_text("")
    with pytest.raises(SystemExit) as e:
        main(["batch", "simulate", "static", "-o", "b/{stem}.csv", "-j", "1", "--json", "--args", "--duration 2"])
    out = json.loads(capsys.readouterr().out)
    assert e.value.code == 0 and out["results"][0]["rows"] == len(formats.read("b/static.csv"))


def test_evaluate(data, tmp_path, monkeypatch, capsys):
    """`imutool evaluate` is its route `run_evaluate` (the same --json and plot), and `imutool batch evaluate`
    calls that route (the command line is never run)."""
    import imutool.cli.batch as cli_batch
    from imutool.cli import main
    from imutool.evaluation import run_evaluate

    args = ["evaluate", data["att"], "--reference", data["roll"], "--align-heading", "auto", "--plot", "e.png"]
    s = _same(
        tmp_path,
        monkeypatch,
        args,
        lambda: run_evaluate(data["att"], data["roll"], align_heading="auto", plot="e.png"),
        [],
    )
    assert s["align_heading"]["how"].startswith("auto") and set(s["angles"]) == {"roll", "pitch", "heading"}
    assert (tmp_path / "cli" / "e.png").exists() and (tmp_path / "lib" / "e.png").exists()

    def no_cli(*a, **k):
        raise AssertionError("batch ran the command line, not the route")

    monkeypatch.setattr(cli_batch, "run_command", no_cli)
    with pytest.raises(SystemExit) as e:
        main(["batch", "evaluate", data["att"], "-j", "1", "--json", "--args", f"--reference {data['roll']}"])
    out = json.loads(capsys.readouterr().out)
    assert e.value.code == 0, out
    assert out["results"][0]["status"] == "ok" and out["results"][0]["error"] is None


def test_read_source_takes_a_recording_or_a_path(data):
    """One helper gives every route its input: a Recording as it is (no loading report), a path loaded once."""
    from imutool.routes import read_source

    rec = formats.read(data["roll"])
    rec.meta["source"] = "deck.csv"
    inputs: list[dict[str, Any]] = []
    assert read_source(rec, inputs) == (rec, "deck.csv", {})
    assert inputs == []
    seen = []
    loaded, name, report = read_source(data["roll"], inputs, on_input=lambda p, r: seen.append(p))
    assert name == data["roll"] and len(loaded) == len(rec) and report
    assert seen == [data["roll"]] and inputs == [{"input": data["roll"], **report}]
