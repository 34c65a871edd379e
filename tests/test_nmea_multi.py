"""Logs of many sentences: each sentence type on its own time base (its UTC field, else its arrival stamp or its
place between fixes), rate and gaps per type, bursty streams, and plots/evaluations on each channel's own samples.
The logs are written here from the documented layouts (GGA, RMC, HDT, $PSXN,23) with valid checksums."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import numpy as np
import pytest
from click.testing import CliRunner

from formats import Recording
from formats.csv import write_csv
from formats.nmea import checksum, read_nmea
from formats.timing import stream_timing
from imutool.cli import cli
from imutool.evaluation import evaluate
from imutool.plot import own_samples

DAY = datetime(2024, 5, 17, tzinfo=timezone.utc).timestamp()


def _s(body: str) -> str:
    return f"${body}*{checksum(body)}"


def _hms(t: float) -> str:
    h, rem = divmod(t % 86400.0, 3600.0)
    m, s = divmod(rem, 60.0)
    return f"{int(h):02d}{int(m):02d}{s:05.2f}"


def _gga(t: float) -> str:
    return _s(f"GPGGA,{_hms(t)},5957.1234,N,01043.5678,E,4,14,0.7,3.400,M,40.100,M,1.0,0001")


def _rmc(t: float, sog_kn: float = 5.0) -> str:  # time, status, lat, N, lon, E, speed kn, course, date ddmmyy
    return _s(f"GPRMC,{_hms(t)},A,5957.1234,N,01043.5678,E,{sog_kn:.1f},45.0,170524,,,A")


def _psxn23(roll: float) -> str:  # $PSXN,23,roll,pitch,heading,heave(+ down)
    return _s(f"PSXN,23,{roll:.2f},0.50,120.00,-0.10")


def test_each_sentence_type_on_its_own_times_and_rate(tmp_path):
    """1 Hz GGA and RMC (UTC), 10 Hz $PSXN,23 (no time) and a 1 Hz HDT between them; the RMC comes 5 sentences
    after the GGA of its second: it must sit at its own UTC, not between the GGA and the next one."""
    lines = []
    for k in range(120):
        t = 36000.0 + k
        lines.append(_gga(t))
        for j in range(10):
            lines.append(_psxn23(2.0 * np.sin(0.1 * (10 * k + j))))
            if j == 4:
                lines.append(_rmc(t, 5.0 + 0.01 * k))
            if j == 7:
                lines.append(_s(f"HEHDT,{120.0 + 0.01 * k:.2f},T"))
    p = tmp_path / "multi.nmea"
    p.write_text("\r\n".join(lines) + "\r\n")
    rec = read_nmea(p)
    sog = np.isfinite(rec["sog"])
    assert sog.sum() == 120
    assert np.allclose(rec.time[sog], DAY + 36000.0 + np.arange(120), atol=1e-6)  # RMC at its own UTC
    timing = rec.meta["sentence_timing"]
    assert timing["HDT"]["rate_hz"] == pytest.approx(1.0, rel=0.01) and timing["HDT"]["gaps"] == 0
    assert timing["PSXN,23"]["rate_hz"] == pytest.approx(10.0, rel=0.02) and timing["PSXN,23"]["gaps"] == 0
    assert timing["RMC"]["rate_hz"] == pytest.approx(1.0) and not timing["HDT"]["bursty"]
    assert np.all(np.diff(rec.time) > 0)
    r = CliRunner().invoke(cli, ["info", str(p)])
    assert r.exit_code == 0, r.output
    hdt = next(x for x in r.output.splitlines() if x.strip().startswith("HDT"))
    assert "1 Hz" in hdt and "0 gaps" in hdt and "per sentence type" in r.output


def test_bursty_stream_and_stamped_log_on_the_utc_axis(tmp_path):
    """A 77 Hz sensor read out in bursts of 4 (3 ms apart) with arrival stamps, and 1 Hz GGA/RMC whose stamps run
    0.35 s behind their UTC (the logger's latency): every sentence on one UTC axis; 77 Hz, not 333 Hz."""
    rng = np.random.default_rng(0)
    utc0 = DAY + 43200.0
    events: list[tuple[float, str]] = []
    n_burst = int(60 * 77 / 4)
    for b in range(n_burst):
        t_b = utc0 + b * 4 / 77 + 0.35
        for j in range(4):
            events.append((t_b + 0.003 * j, _psxn23(1.0)))
    for k in range(61):
        st = utc0 + k + 0.35 + 0.01 * rng.standard_normal()
        events += [(st, _gga(43200.0 + k)), (st + 0.001, _rmc(43200.0 + k))]
    events.sort(key=lambda e: e[0])
    p = tmp_path / "stamped.log"
    p.write_text("".join(f"{int(round(ts * 1000))};A;{line}\n" for ts, line in events))
    rec = read_nmea(p)
    tm = rec.meta["sentence_timing"]["PSXN,23"]
    assert tm["rate_hz"] == pytest.approx(77.0, rel=0.01) and tm["bursty"] and tm["burst"]["samples"] == 4
    assert tm["gaps"] == 0
    assert rec.meta["time"]["stamp_offset_s"] == pytest.approx(0.35, abs=0.01)
    h = np.isfinite(rec["gnss_height"])
    assert np.allclose(rec.time[h], utc0 + np.arange(61), atol=1e-6)  # GGA at its UTC, not its stamp
    roll = np.isfinite(rec["roll"])
    assert abs(rec.time[roll][0] - utc0) < 0.02  # the first burst: stamp − offset
    r = CliRunner().invoke(cli, ["info", str(p), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["sentence_timing"]["PSXN,23"]["burst"]["period_s"] == pytest.approx(4 / 77, rel=0.01)


def test_bursty_csv_reports_its_true_rate(tmp_path):
    t = (np.arange(2000) // 4) * (4 / 77) + (np.arange(2000) % 4) * 0.003
    assert stream_timing(t)["rate_hz"] == pytest.approx(77.0, rel=0.01)
    rec = Recording(t, {"mag": np.tile([20.0, 5.0, 40.0], (2000, 1))}, {"mag": "uT"})
    p = tmp_path / "bursty.csv"
    write_csv(rec, p)
    r = CliRunner().invoke(cli, ["info", str(p), "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["rate_hz"] == pytest.approx(77.0, rel=0.01) and s["gaps"]["count"] == 0 and s["bursts"]["samples"] == 4


def test_plot_draws_channels_on_rows_of_their_own(tmp_path):
    t = np.arange(0.0, 60.0, 0.1)
    heading = np.full(len(t), np.nan)
    heading[::10] = 100.0 + np.arange(60)  # 1 Hz values, each on its own row between NaN rows
    heading[300:400] = np.nan  # and a real gap of 10 s
    ts, ys = own_samples(t, heading[:, None])
    assert np.isfinite(ys).sum() == 50 and np.isnan(ys).sum() == 1  # the gap stays open, one break
    rec = Recording(t, {"heading": heading, "roll": np.sin(t)}, {"heading": "deg", "roll": "deg"})
    p = tmp_path / "rows.csv"
    write_csv(rec, p)
    out = tmp_path / "h.png"
    r = CliRunner().invoke(cli, ["plot", str(p), "heading", "roll", "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output and out.exists()


def test_evaluate_against_a_reference_on_rows_of_its_own():
    t = np.arange(0.0, 100.0, 0.1)
    truth = 3.0 * np.sin(2 * np.pi * t / 10.0)
    est = Recording(t.copy(), {"roll": truth + 0.05}, {"roll": "deg"})
    ref_roll = np.full(len(t), np.nan)
    ref_roll[::5] = truth[::5]  # a 2 Hz reference between rows of other channels
    ref = Recording(t.copy(), {"ref_roll": ref_roll}, {"ref_roll": "deg"})
    s = evaluate(est, ref, channel="angles")
    assert s["angles"]["roll"]["rmse"] == pytest.approx(0.05, abs=0.02)


def test_real_chartplotter_log_rates_per_sentence_type():
    """Signal K's GoFree log (no stamps, 1 Hz GGA/RMC/ZDA among AIS and 10 Hz HDG): HDG is ~9.7 Hz without the
    gaps its position-placed times would fake (a sentence without a time field is known only to the fix interval)."""
    from pathlib import Path

    p = Path(__file__).resolve().parents[2] / "shared" / "data" / "nmea_signalk" / "gofree-merrimac.log"
    if not p.exists():
        pytest.skip("../shared/data/nmea_signalk is absent")
    timing = read_nmea(p).meta["sentence_timing"]
    assert timing["HDG"]["rate_hz"] == pytest.approx(9.74, abs=0.05) and timing["HDG"]["gaps"] == 0
    assert timing["HDG"]["gap_longer_than_s"] == pytest.approx(2.0) and timing["RMC"]["rate_hz"] == pytest.approx(1.0)
