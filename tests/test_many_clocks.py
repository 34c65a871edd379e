"""A recording with many clocks (issue 48): each stream keeps its own samples, and every command takes a channel on
its own samples — the same answer as a file of that stream alone.

Logs built from real sentence layouts: a Seapath-like log (1 Hz ``$PSXN,23,roll,pitch,heading,heave`` — heave + down
in the sentence — interleaved with ZDA, GGA, HDT at 5 Hz, VTG, RMC and ``$PSXN,20``, real checksums) and
``../shared/data/nmea_signalk/gofree-merrimac.log`` as it is (XDR heel among HDG, wind and GPS).
"""

from __future__ import annotations

import json
import math
from functools import reduce
from pathlib import Path

import numpy as np
import pytest

import formats
from formats import Recording
from formats.recording import join_streams
from tests.conftest import run_main, shared_data

N_S = 60  # seconds of log


def _line(body: str) -> str:
    return f"${body}*{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def seapath_truth(k: int) -> tuple[float, float, float, float]:
    """Roll (deg, + stbd down), pitch (deg), heading (deg true), heave (m, + up) of second ``k``."""
    return (
        round(5.0 * math.sin(2 * math.pi * k / 8.0), 2),
        round(1.0 * math.cos(2 * math.pi * k / 6.0), 2),
        round((120.0 + 0.1 * k) % 360, 2),
        round(0.5 * math.sin(2 * math.pi * k / 7.0), 2),
    )


def seapath_log(path: Path, n_s: int = N_S, hdt_hz: int = 5, empty_roll_at: int | None = None) -> Path:
    """A Seapath-like log: per second ZDA, GGA, PSXN,23 (1 Hz), PSXN,20, ``hdt_hz`` HDT, VTG, RMC. With
    ``empty_roll_at``: that second's PSXN,23 has an empty roll field (a missing sample of the roll stream)."""
    out = []
    for k in range(n_s):
        hms = f"12{k // 60:02d}{k % 60:02d}.00"
        roll, pitch, head, heave = seapath_truth(k)
        rf = "" if k == empty_roll_at else f"{roll:.2f}"
        out.append(_line(f"GPZDA,{hms},05,12,2026,00,00"))
        out.append(_line(f"GPGGA,{hms},7830.0000,N,01530.0000,E,2,12,0.8,10.0,M,30.0,M,,"))
        out.append(_line(f"PSXN,23,{rf},{pitch:.2f},{head:.2f},{-heave:.2f}"))
        out.append(_line("PSXN,20,0,0,0,0"))
        for j in range(hdt_hz):
            out.append(_line(f"GPHDT,{(head + 0.02 * j) % 360:.2f},T"))
        out.append(_line(f"GPVTG,{head:.1f},T,,M,5.0,N,9.3,K,D"))
        out.append(_line(f"GPRMC,{hms},A,7830.0000,N,01530.0000,E,5.0,{head:.1f},051226,,,D"))
    path.write_text("\r\n".join(out) + "\r\n", encoding="ascii")
    return path


@pytest.fixture
def sea(tmp_path: Path) -> Path:
    return seapath_log(tmp_path / "seapath.log")


def _stream_csv(rec: Recording, channel: str, path: Path) -> Path:
    """A single-clock CSV of the stream of ``channel`` alone: the 'roll-only file of the same data'."""
    formats.write(rec.stream(channel), path)
    return path


def _sentences(path: Path) -> list[str]:
    return [x for x in path.read_text().splitlines() if x and not x.startswith("#")]


# -- the core -------------------------------------------------------------------------------------------------------
def test_reader_gives_each_sentence_type_its_own_samples(sea: Path) -> None:
    rec = formats.read(sea)
    assert rec.multi_clock
    k = rec.stream_of("roll")
    assert k == "PSXN,23" and rec.stream_of("heave") == k
    t, roll = rec.series("roll")
    assert len(t) == N_S and np.all(np.isfinite(roll))  # another sentence's row is not a sample of roll
    assert np.allclose(roll, [seapath_truth(i)[0] for i in range(N_S)])
    t_h, heave = rec.series("heave")
    assert np.allclose(heave, [seapath_truth(i)[3] for i in range(N_S)])  # + down in PSXN,23 → + up
    th, _ = rec.series("heading")
    assert len(th) == N_S * 6  # HDT (5 Hz) and PSXN,23's heading share the heading channel
    s = rec.stream("roll")
    assert not s.multi_clock and set(s.channels) == {"roll", "pitch", "heave"} and len(s) == N_S
    summ = rec.stream_summary()
    assert summ[k]["rate_hz"] == pytest.approx(1.0) and summ[k]["gaps"] == 0 and summ[k]["samples"] == N_S
    assert summ[rec.stream_of("heading")]["rate_hz"] == pytest.approx(6.0, rel=0.02)


def test_validation_counts_nan_and_gaps_per_stream(tmp_path: Path) -> None:
    rec = formats.read(seapath_log(tmp_path / "a.log", empty_roll_at=10))
    clean, rep = rec.validated()
    assert rep.nan_by_channel == {"roll": 1}  # the empty field, not the 480 rows of other sentences
    assert rep.gaps == [] and all(g == [] for g in rep.stream_gaps.values())
    assert rep.stream_median_dt[rec.stream_of("roll")] == pytest.approx(1.0)


def test_gap_is_found_on_its_stream(tmp_path: Path) -> None:
    p = seapath_log(tmp_path / "g.log")
    lines = p.read_text().splitlines()
    # 10 s without PSXN,23 (the other sentences go on)
    keep = [x for i, x in enumerate(lines) if not ("PSXN,23" in x and 20 * 11 <= i < 30 * 11)]
    p.write_text("\r\n".join(keep) + "\r\n")
    rec = formats.read(p)
    summ = rec.stream_summary()
    assert summ["PSXN,23"]["gaps"] == 1 and summ["PSXN,23"]["missing_s"] == pytest.approx(10.0, abs=0.01)
    assert summ["GGA"]["gaps"] == 0
    _, rep = rec.validated()
    assert len(rep.stream_gaps["PSXN,23"]) == 1 and rep.stream_gaps["GGA"] == []


def test_slice_select_copy_keep_streams(sea: Path) -> None:
    rec = formats.read(sea)
    t0 = rec.time[0]
    part = rec.slice_time(t0 + 10.05, t0 + 20.05)
    assert part.multi_clock and part.streams == rec.streams
    t, roll = part.series("roll")
    assert len(t) == 10 and np.all(np.isfinite(roll))
    assert part.copy().stream_rows.keys() == rec.stream_rows.keys()


def test_duplicates_across_streams_are_not_duplicates() -> None:
    a = Recording(np.array([0.0, 1.0, 2.0]), {"roll": np.array([1.0, 2.0, 3.0])}, {"roll": "deg"})
    b = Recording(np.array([0.5, 1.0, 1.5, 2.0]), {"heading": np.array([10.0, 11.0, 12.0, 13.0])}, {"heading": "deg"})
    j = join_streams([a, b], ["A", "B"])
    assert len(j) == 5  # join_streams: one row per distinct time
    # a table with two rows at t = 1 and at t = 2 (one per stream), as a file written by another tool may hold it
    t = np.array([0.0, 0.5, 1.0, 1.0, 1.5, 2.0, 2.0])
    roll = np.array([1.0, np.nan, 2.0, np.nan, np.nan, 3.0, np.nan])
    head = np.array([np.nan, 10.0, np.nan, 11.0, 12.0, np.nan, 13.0])
    r = Recording(t, {"roll": roll, "heading": head}, {"roll": "deg", "heading": "deg"})
    r.set_stream("A", ["roll"], np.isfinite(roll))
    r.set_stream("B", ["heading"], np.isfinite(head))
    for how in ("drop", "mean", "error"):
        out, rep = r.validated(duplicates=how)
        assert len(out) == 5 and rep.duplicates == 0
        assert np.allclose(out.series("roll")[1], [1, 2, 3]) and np.allclose(out.series("heading")[1], [10, 11, 12, 13])
    # a true duplicate: two samples of one stream at one time
    roll2 = roll.copy()
    r2 = Recording(np.array([0.0, 0.5, 1.0, 1.0, 1.5, 2.0, 2.0]), {"roll": roll2, "heading": head}, {})
    r2.set_stream("A", ["roll"], np.array([1, 0, 1, 1, 0, 1, 0], bool))
    r2.channels["roll"][3] = 4.0
    r2.set_stream("B", ["heading"], np.isfinite(head))
    out, rep = r2.validated(duplicates="mean")
    assert rep.duplicates == 1 and np.allclose(out.series("roll")[1], [1, 3, 3])
    assert rep.duplicates_conflicting == 1  # averaged, but still said: the two samples disagreed
    out, rep = r2.validated(duplicates="drop")
    assert np.allclose(out.series("roll")[1], [1, 2, 3]) and rep.duplicates_conflicting == 1
    with pytest.raises(formats.ImutoolError):
        r2.validated(duplicates="error")
    # join_streams takes validated inputs: a repeated time would silently keep only its last row
    rep_t = Recording(np.array([0.0, 1.0, 1.0]), {"pitch": np.array([1.0, 2.0, 5.0])}, {"pitch": "deg"})
    with pytest.raises(formats.ImutoolError, match="not strictly increasing"):
        join_streams([a, rep_t], ["A", "P"])


def test_held_and_on_clock() -> None:
    a = Recording(np.arange(0.0, 10.0, 1.0), {"roll": np.arange(10.0)}, {"roll": "deg"})
    b = Recording(np.arange(0.25, 10.0, 0.5), {"heading": np.arange(0.25, 10.0, 0.5) * 10}, {"heading": "deg"})
    j = join_streams([a, b], ["roll", "hdg"])
    assert j.multi_clock
    on = j.on_clock("roll")
    assert not on.multi_clock and len(on) == 10 and "heading held" in on.meta["resampled"]
    # heading at each roll time: its latest own sample at or before (0.25 s before); none before its first
    assert np.isnan(on["heading"][0]) and np.allclose(on["heading"][1:], (np.arange(1.0, 10.0) - 0.25) * 10)
    # a gap is not bridged: more than 3 own steps old → NaN
    h = j.held("heading", np.array([9.75, 11.0, 12.0]))
    assert h[0] == pytest.approx(97.5) and np.isnan(h[2])


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_file_round_trip_restores_streams(sea: Path, tmp_path: Path, ext: str, capsys) -> None:
    rec = formats.read(sea)
    out = tmp_path / f"x.{ext}"
    code, _, err = run_main(["convert", sea, out], capsys)
    assert code == 0, err
    back = formats.read(out)
    assert back.streams == rec.streams
    assert all(np.array_equal(back.stream_rows[k], rec.stream_rows[k]) for k in rec.stream_rows)
    chunks = list(formats.iter_chunks(out, chunk_rows=97))
    assert all(c.multi_clock for c in chunks)  # each chunk of a streamed read knows its streams' rows
    assert sum(int(c.own_rows("roll").sum()) for c in chunks) == N_S


# -- imutool nmea ------------------------------------------------------------------------------------------------
def test_nmea_out_each_sentence_on_its_own_stream(sea: Path, tmp_path: Path, capsys) -> None:
    """Issue 48 (1): HRM/XDR from the roll stream, THS from the heading stream — what a file of each stream alone
    gives, line for line; not one HRM with an empty heel."""
    rec = formats.read(sea)
    roll_csv = _stream_csv(rec, "roll", tmp_path / "roll.csv")
    head_csv = _stream_csv(rec, "heading", tmp_path / "head.csv")
    o = tmp_path / "all.nmea"
    code, out, err = run_main(
        ["nmea", sea, "-o", o, "--sentences", "HRM,XDR,THS", "--heading-ref", "true", "--rate", "2", "--json"], capsys
    )
    assert code == 0, err
    s = json.loads(out)
    assert s["sentences"] == {"HRM": N_S, "XDR": N_S, "THS": 2 * N_S}
    lines = _sentences(o)
    assert all(",V," not in x and not x.startswith("$IIHRM,,") for x in lines if "HRM" in x)
    code, _, err = run_main(
        ["nmea", roll_csv, "-o", tmp_path / "r.nmea", "--sentences", "HRM,XDR", "--rate", "2"], capsys
    )
    assert code == 0, err
    code, _, err = run_main(
        ["nmea", head_csv, "-o", tmp_path / "h.nmea", "--sentences", "THS", "--heading-ref", "true", "--rate", "2"],
        capsys,
    )
    assert code == 0, err
    assert [x for x in lines if "THS" not in x] == _sentences(tmp_path / "r.nmea")
    assert [x for x in lines if "THS" in x] == _sentences(tmp_path / "h.nmea")


def test_nmea_out_rate_is_the_streams_not_the_tables(sea: Path, tmp_path: Path) -> None:
    from imutool.nmea_out import input_rate, run_nmea

    rec = formats.read(sea)
    assert input_rate(rec, ["HRM", "XDR"]) == pytest.approx(1.0)
    res = run_nmea(sea, tmp_path / "x.nmea", sentences="HRM,XDR")
    assert res.summary["rate_hz"] == 1.0 and res.summary["sentences"] == {"HRM": N_S, "XDR": N_S}


def test_nmea_out_gofree_xdr_heel(tmp_path: Path) -> None:
    """gofree-merrimac: XDR heel (1 Hz) among 10 Hz HDG, wind and GPS — the XDR out is the heel stream's."""
    log = shared_data("nmea_signalk", "gofree-merrimac.log")
    from imutool.nmea_out import run_nmea

    rec = formats.read(log)
    only = _stream_csv(rec, "roll", tmp_path / "heel.csv")
    a = run_nmea(log, tmp_path / "a.nmea", sentences="XDR,HDG", heading_ref="compass")
    b = run_nmea(only, tmp_path / "b.nmea", sentences="XDR", rate_hz=a.summary["rate_hz"])
    assert a.summary["sentences"]["XDR"] == b.summary["sentences"]["XDR"] == len(rec.series("roll")[0])
    assert [x for x in _sentences(tmp_path / "a.nmea") if "XDR" in x] == _sentences(tmp_path / "b.nmea")


# -- imutool info / plot / convert ----------------------------------------------------------------------------------
def test_info_json_per_stream(sea: Path, capsys) -> None:
    code, out, err = run_main(["info", sea, "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert s["rate_hz"] is None  # the table's rows have no rate of their own
    st = s["streams"]["PSXN,23"]
    assert st["rate_hz"] == pytest.approx(1.0) and st["samples"] == N_S and st["gaps"] == 0
    assert st["duration_s"] == pytest.approx(N_S - 1)
    assert s["gaps"]["count"] == 0
    assert s["channels"]["roll"]["samples"] == N_S and s["channels"]["roll"]["stream"] == "PSXN,23"
    code, out, _ = run_main(["info", sea], capsys)
    assert "PSXN,23        1 Hz, 60 samples" in out


def test_plot_draws_each_channel_on_its_own_samples(tmp_path: Path) -> None:
    from imutool.plot import _collect

    log = seapath_log(tmp_path / "p.log", empty_roll_at=30)
    series, _, _ = _collect(str(log), ("roll", "heading"), None, None, 20000, {}, [])
    t, y = series["roll"]
    assert np.isfinite(y[:, 0]).sum() == N_S - 1
    assert np.isnan(y[30, 0])  # the empty field breaks the line; another sentence's row is not in it
    th, yh = series["heading"]
    assert len(th) == N_S * 6 and np.all(np.isfinite(yh))


def test_convert_to_bag_and_back_one_message_per_attitude_sample(sea: Path, tmp_path: Path, capsys) -> None:
    pytest.importorskip("rosbags")
    code, out, err = run_main(["convert", sea, tmp_path / "s.bag", "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert s["messages_out"] == {"/imu/data": N_S}  # the bag writer: one Imu per own attitude sample
    back = formats.read(tmp_path / "s.bag")
    assert len(back) == N_S and not np.isnan(back["q"]).any()
    from formats.frames import quat_to_euler

    r, p, h = quat_to_euler(back["q"])
    truth = np.array([seapath_truth(i) for i in range(N_S)])
    assert np.allclose(np.degrees(r), truth[:, 0], atol=1e-9)
    assert np.allclose(np.degrees(h) % 360, truth[:, 2], atol=1e-9)


def test_convert_to_nmea_each_sentence_on_its_stream(sea: Path, tmp_path: Path, capsys) -> None:
    rec = formats.read(sea)
    code, _, err = run_main(["convert", sea, tmp_path / "c.nmea", "--sentences", "HDT,XDR"], capsys)
    assert code == 0, err
    lines = _sentences(tmp_path / "c.nmea")
    assert sum("XDR" in x for x in lines) == N_S and sum("HDT" in x for x in lines) == 6 * N_S
    only = _stream_csv(rec, "roll", tmp_path / "r.csv")
    code, _, err = run_main(["convert", only, tmp_path / "r.nmea", "--sentences", "XDR"], capsys)
    assert code == 0, err
    assert [x for x in lines if "XDR" in x] == _sentences(tmp_path / "r.nmea")


# -- the other routes: each on its channel's own samples, as on a file of that stream alone ---------------------
def _same(a: dict, b: dict, skip: tuple[str, ...] = ()) -> list[str]:
    """Keys whose values differ between two summaries (paths, loading reports and ``skip`` left out)."""
    ignore = {"input", "output", "validation", "generated_utc", "cycles_output", "clock", "voyage", *skip}
    return [
        k
        for k in set(a) | set(b)
        if k not in ignore and json.dumps(a.get(k), default=str) != json.dumps(b.get(k), default=str)
    ]


def test_roll_and_events_on_the_heel_stream(sea: Path, tmp_path: Path) -> None:
    from imutool.events import run_events
    from imutool.routes.roll import run_roll

    rec = formats.read(sea)
    only = _stream_csv(rec, "roll", tmp_path / "roll.csv")
    a = run_roll(sea, tmp_path / "a.csv")
    b = run_roll(only, tmp_path / "b.csv")
    assert _same(a.summary, b.summary) == []
    assert a.full_summary()["validation"][0]["clock"]["stream"] == "PSXN,23"
    ra, rb = formats.read(tmp_path / "a.csv"), formats.read(tmp_path / "b.csv")
    assert len(ra) == N_S and np.array_equal(ra["roll_period"], rb["roll_period"], equal_nan=True)
    assert "clock" in ra.meta  # the output says which clock it was computed on
    ea, eb = run_events(sea).summary, run_events(only).summary
    assert _same(ea, eb) == [] and ea["rows"] == N_S


def test_heave_from_gnss_height_on_the_gga_stream(sea: Path, tmp_path: Path) -> None:
    from imutool.routes.heave import run_heave

    rec = formats.read(sea)
    only = _stream_csv(rec, "gnss_height", tmp_path / "gga.csv")
    a = run_heave(sea, tmp_path / "a.csv", gnss_fix="any")
    b = run_heave(only, tmp_path / "b.csv", gnss_fix="any")
    assert _same(a.summary, b.summary) == []
    ha, hb = formats.read(tmp_path / "a.csv"), formats.read(tmp_path / "b.csv")
    assert len(ha) == len(hb) == N_S and np.allclose(ha["heave"], hb["heave"], equal_nan=True)


def test_evaluate_a_many_clock_estimate(sea: Path, tmp_path: Path) -> None:
    from imutool.evaluation import run_evaluate

    rec = formats.read(sea)
    only = _stream_csv(rec, "roll", tmp_path / "roll.csv")
    t, roll = rec.series("roll")
    ref = Recording(t.copy(), {"ref_roll": roll + 0.1}, {"ref_roll": "deg"}, {"source": "ref"})
    formats.write(ref, tmp_path / "ref.csv")
    a = run_evaluate(sea, tmp_path / "ref.csv").summary
    b = run_evaluate(only, tmp_path / "ref.csv").summary
    assert a["angles"]["roll"] == b["angles"]["roll"]
    assert a["angles"]["roll"]["rmse"] == pytest.approx(0.1, abs=1e-9)


def _imu_with_aux(tmp_path: Path, scenario: str, seconds: float) -> tuple[Path, Path]:
    """A simulated IMU and a 1 Hz temperature stream on its own clock, joined as one many-clock CSV; and the IMU
    alone."""
    from imutool.sim import simulate

    imu = simulate(scenario, duration=seconds, seed=3)
    imu.meta.pop("streams", None)
    keep = [c for c in imu.channels if c in ("gyro", "accel", "mag")]
    imu = Recording(imu.time, {c: imu[c] for c in keep}, {c: imu.units[c] for c in keep}, dict(imu.meta))
    ta = np.arange(imu.time[0] + 0.0037, imu.time[-1], 1.0)
    aux = Recording(ta, {"temp": 20.0 + 0.01 * np.arange(len(ta))}, {"temp": "degC"})
    j = join_streams([imu, aux], ["imu", "aux"])
    assert j.multi_clock and len(j) == len(imu) + len(ta)
    formats.write(j, tmp_path / "many.csv")
    formats.write(imu, tmp_path / "imu.csv")
    return tmp_path / "many.csv", tmp_path / "imu.csv"


def test_filter_on_the_imu_stream(tmp_path: Path) -> None:
    from imutool.filtering import run_filter

    many, only = _imu_with_aux(tmp_path, "ship-roll", 30)
    a = run_filter(many, tmp_path / "a.csv")
    run_filter(only, tmp_path / "b.csv")
    ra, rb = formats.read(tmp_path / "a.csv"), formats.read(tmp_path / "b.csv")
    assert len(ra) == len(rb) and np.array_equal(ra.time, rb.time)
    for c in ("roll", "pitch", "heading"):
        assert np.allclose(ra[c], rb[c], equal_nan=True), c
    assert a.validation["clock"]["stream"] == "imu"


def test_zvi_on_the_imu_stream(tmp_path: Path) -> None:
    from imutool.routes.zvi import run_zvi

    many, only = _imu_with_aux(tmp_path, "walk", 20)
    a = run_zvi(many, tmp_path / "a.csv")
    b = run_zvi(only, tmp_path / "b.csv")
    za, zb = a.recording, b.recording
    assert len(za) == len(zb) and np.array_equal(za["zvi"], zb["zvi"]) and za["zvi"].any()
    assert _same(a.summary, b.summary) == []


def test_merge_interpolates_each_channel_from_its_own_samples() -> None:
    a = Recording(np.arange(0.0, 10.0, 1.0), {"roll": np.arange(10.0)}, {"roll": "deg"})
    b = Recording(np.arange(0.5, 10.0, 1.0), {"heading": np.arange(0.5, 10.0, 1.0) * 2}, {"heading": "deg"})
    j = join_streams([a, b], ["a", "b"])
    m = formats.merge([j], np.arange(1.0, 9.0, 0.25))
    assert np.allclose(m["roll"], np.arange(1.0, 9.0, 0.25)) and np.allclose(
        m["heading"], np.arange(1.0, 9.0, 0.25) * 2
    )


def test_mounting_keeps_streams_and_plausibility_on_one_clock() -> None:
    from formats import plausibility

    t = np.arange(0.0, 20.0, 0.01)
    g = np.zeros((len(t), 3))
    a = np.tile([0.0, 0.0, -9.81], (len(t), 1))
    imu = Recording(t, {"gyro": g, "accel": a}, {"gyro": "rad/s", "accel": "m/s^2"})
    tm = np.arange(0.005, 20.0, 0.1)
    mag = Recording(tm, {"mag": np.tile([20.0, 0.0, 40.0], (len(tm), 1))}, {"mag": "uT"})
    j = join_streams([imu, mag], ["imu", "mag"])
    m = j.mounted("x,-y,-z")
    assert m.multi_clock and np.array_equal(m.own_rows("mag"), j.own_rows("mag"))
    assert np.allclose(m.series("accel")[1][:, 2], 9.81)  # z flipped, on the IMU's own rows only
    rep = plausibility.check_recording(j)  # on the IMU's clock: the mag's NaN rows are not missing samples
    assert not any("mag" in w and "unit" in w for w in rep.warnings), rep.warnings


def test_info_text_of_a_many_clock_csv(sea: Path, tmp_path: Path, capsys) -> None:
    formats.write(formats.read(sea), tmp_path / "s.csv")
    code, out, err = run_main(["info", tmp_path / "s.csv"], capsys)
    assert code == 0, err
    assert "PSXN,23        1 Hz, 60 samples in 59 s, 0 gaps (roll, pitch, heave)" in out
    # a many-clock CSV from elsewhere (no NMEA sentence timing): the rate is per stream
    a = Recording(np.arange(0.0, 10.0, 1.0), {"roll": np.arange(10.0)}, {"roll": "deg"})
    b = Recording(np.arange(0.05, 10.0, 0.1), {"heading": np.arange(0.05, 10.0, 0.1)}, {"heading": "deg"})
    formats.write(join_streams([a, b], ["att", "hdg"]), tmp_path / "j.csv")
    code, out, err = run_main(["info", tmp_path / "j.csv"], capsys)
    assert code == 0, err
    assert "rate:      per stream (2 streams" in out and "att            1 Hz, 10 samples in 9 s, 0 gaps" in out


def test_xdr_transducers_on_lines_of_their_own_are_streams_of_their_own(tmp_path, capsys):
    """A device that sends XDR ROLL and XDR PITCH on lines of their own (50 ms apart): two streams, no missing
    samples counted, and every XDR written by `imutool nmea` carries the pitch (held from its own stream)."""
    from formats.nmea import xdr_sentence

    t0, lines = 1_700_000_000.0, []
    for i in range(300):
        t = t0 + i * 0.1
        lines.append(f"{t:.3f} " + xdr_sentence([("A", 6 * math.sin(0.2 * math.pi * i * 0.1), "D", "ROLL")]))
        lines.append(f"{t + 0.05:.3f} " + xdr_sentence([("A", 2.0 + 0.01 * i, "D", "PITCH")]))
    log = tmp_path / "xdr_split.log"
    log.write_text("\n".join(lines) + "\n")
    rec = formats.read(log)
    assert set(rec.streams) == {"XDR:roll", "XDR:pitch"} and rec.multi_clock
    _, rep = rec.validated()
    assert rep.nan_by_channel == {}  # main counted 300 missing rolls and 300 missing pitches
    code, _, err = run_main(["nmea", log, "-o", tmp_path / "o.nmea", "--sentences", "XDR"], capsys)
    assert code == 0, err
    xdr = [x for x in (tmp_path / "o.nmea").read_text().splitlines() if x.startswith("$") and "XDR" in x]
    assert len(xdr) >= 290
    assert sum(",PTCH," in x and "A,,D,PTCH" not in x for x in xdr[1:]) == len(xdr) - 1
