"""GNSS heights (GGA, GST, PTNL,GGK/PJK) and the heave from an RTK receiver's height (imutool.gnss_heave)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from formats import Recording
from formats.errors import ImutoolError
from formats.nmea import checksum, decode, read_nmea
from imutool.cli import cli, main
from imutool.evaluation import evaluate
from imutool.gnss_heave import detrend_height, height_heave
from imutool.routes.heave import run_heave


def _s(body: str) -> str:
    return f"${body}*{checksum(body)}"


def _hms(t: float) -> str:
    h, rem = divmod(t % 86400.0, 3600.0)
    m, s = divmod(rem, 60.0)
    return f"{int(h):02d}{int(m):02d}{s:05.2f}"


def _gga(t: float, alt: float | None, sep: str = "-25.300", quality: int = 4) -> str:
    """GGA in the documented order: time, lat, N/S, lon, E/W, quality, satellites, HDOP, altitude, M, separation,
    M, age of corrections, station."""
    a = "" if alt is None else f"{alt:.3f}"
    return _s(f"GPGGA,{_hms(t)},5957.1234,N,01043.5678,E,{quality},14,0.7,{a},M,{sep},M,1.0,0001")


def _rtk_log(
    path, rate_hz: float, duration_s: float, seed: int = 1, bad_every: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """An RTK-like GGA log: altitude = 3.4 m + 0.07 m sin(2π t/6.7) + 1 cm noise (+ a slow 5 cm tide-like drift),
    an HDT between fixes. Returns (times, true heave)."""
    rng = np.random.default_rng(seed)
    t = 43200.0 + np.arange(0.0, duration_s, 1.0 / rate_hz)
    heave = 0.07 * np.sin(2 * np.pi * (t - t[0]) / 6.7)
    alt = 3.4 + heave + 0.05 * (t - t[0]) / duration_s + 0.01 * rng.standard_normal(len(t))
    lines = []
    for i, (ti, ai) in enumerate(zip(t, alt, strict=True)):
        q = 1 if bad_every and i % bad_every == bad_every - 1 else 4
        lines.append(_gga(ti, ai + (0.8 if q == 1 else 0.0), quality=q))
        if i % max(1, int(rate_hz)) == 0:
            lines.append(_s(f"HEHDT,{120 + 0.1 * i % 5:.1f},T"))
    path.write_text("\r\n".join(lines) + "\r\n")
    return t, heave


def test_gga_height_is_altitude_plus_geoid_separation():
    # NMEA's own example line: altitude 545.4 m above the geoid, geoid 46.9 m above the ellipsoid → h = 592.3 m
    d = decode("$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47")
    assert d["gnss_height"] == pytest.approx(592.3) and d["gnss_fix_quality"] == 1
    assert chr(int(d["gnss_height_datum"])) == "E" and d["gnss_geoid_separation"] == 46.9
    # Trimble's manuals print a GGA and a GGK of the same epoch (172814): orthometric 18.893 m, separation
    # −25.669 m (the geoid below the ellipsoid) and the GGK's ellipsoidal height EHT−6.777 m: H + N = −6.776 m
    d = decode("$GPGGA,172814.0,3723.46587704,N,12202.26957864,W,2,6,1.2,18.893,M,-25.669,M,2.0,0031*4F")
    assert d["gnss_height"] == pytest.approx(-6.777, abs=0.0015) and d["gnss_fix_quality"] == 2
    # a negative separation (geoid below the ellipsoid) lowers the ellipsoidal height
    d = decode(_gga(0.0, 3.4, sep="-25.300"))
    assert d["gnss_height"] == pytest.approx(3.4 - 25.3)
    # separation empty: the altitude as sent, flagged A
    d = decode(_gga(0.0, 3.4, sep=""))
    assert d["gnss_height"] == pytest.approx(3.4) and chr(int(d["gnss_height_datum"])) == "A"
    # no fix: no height (time only)
    assert decode(_gga(0.0, 3.4, quality=0)) == {}
    with pytest.raises(ImutoolError):
        decode(_gga(0.0, 3.4, quality=9))


def test_gga_altitude_setting_and_datum_in_metadata(tmp_path):
    p = tmp_path / "ell.nmea"
    p.write_text("\n".join(_gga(10.0 + i, 30.0 + 0.01 * i, sep="0.000") for i in range(5)))
    rec = read_nmea(p)
    gh = rec.meta["gnss_height"]
    assert gh["rows_by_datum"] == {"E": 5} and gh["geoid_separation_zero_rows"] == 5
    assert "ellipsoidal height into the altitude field" in gh["note"]
    p2 = tmp_path / "empty_sep.nmea"
    p2.write_text("\n".join(_gga(10.0 + i, 30.0, sep="") for i in range(5)))
    rec = read_nmea(p2)
    assert rec.meta["gnss_height"]["rows_by_datum"] == {"A": 5} and "gga_altitude" in rec.meta["gnss_height"]["note"]
    # a receiver that writes the ellipsoidal height into the altitude field and a real separation beside it
    p3 = tmp_path / "stated.nmea"
    p3.write_text("\n".join(_gga(10.0 + i, 30.0, sep="40.000") for i in range(5)))
    assert np.allclose(read_nmea(p3)["gnss_height"], 70.0)
    rec = read_nmea(p3, profile={"nmea": {"gga_altitude": "ellipsoid"}})
    assert np.allclose(rec["gnss_height"], 30.0) and rec.meta["motion_options"]["gga_altitude"] == "ellipsoid"
    with pytest.raises(ImutoolError):
        read_nmea(p3, gga_altitude="geoid")


def test_gst_ggk_pjk_real_lines():
    d = decode("$GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031*6A")
    assert d == {"gnss_lat_std": 0.023, "gnss_lon_std": 0.020, "gnss_height_std": 0.031}
    # Trimble receiver help / Kongsberg EK80 manual: quality 5 (SBAS) on Trimble's scale → 2 on GGA's
    d = decode("$PTNL,GGK,102939.00,051910,5000.97323841,N,00827.62010742,E,5,09,1.9,EHT150.790,M*73")
    assert d["gnss_height"] == pytest.approx(150.79) and chr(int(d["gnss_height_datum"])) == "E"
    assert d["ptnl_quality"] == 5 and d["gnss_fix_quality"] == 2
    # Trimble receiver help: GHT = orthometric (the receiver's geoid model), EHT ellipsoidal, signed
    d = decode("$PTNL,PJK,202831.50,011112,+805083.350,N,+388997.346,E,10,09,1.5,GHT+25.478,M*77")
    assert d["gnss_height"] == pytest.approx(25.478) and chr(int(d["gnss_height_datum"])) == "O"
    d = decode("$PTNL,PJK,010717.00,081796,+732646.511,N,+1731051.091,E,1,05,2.7,EHT-28.345,M*7C")
    assert d["gnss_height"] == pytest.approx(-28.345) and chr(int(d["gnss_height_datum"])) == "E"
    # RTK fixed on Trimble's scale (3) is 4 on GGA's
    assert decode(_s("PTNL,GGK,120000.00,112726,5957.1,N,01043.5,E,3,12,1.1,EHT42.000,M"))["gnss_fix_quality"] == 4


@pytest.mark.parametrize("rate_hz, duration_s", [(1.0, 600.0), (10.0, 300.0)])
def test_rtk_gga_log_gives_gnss_height_and_heave(tmp_path, rate_hz, duration_s):
    log = tmp_path / f"rtk_{rate_hz:g}hz.nmea"
    t, truth = _rtk_log(log, rate_hz, duration_s)
    rec = read_nmea(log)
    h = rec["gnss_height"]
    ok = np.isfinite(h)
    assert ok.sum() == len(t) and np.allclose(rec.time[ok], t, atol=1e-6)  # each GGA at its own UTC
    assert rec.meta["sentence_timing"]["GGA"]["rate_hz"] == pytest.approx(rate_hz, rel=1e-3)
    assert rec.meta["sentence_timing"]["HDT"]["rate_hz"] == pytest.approx(1.0, rel=0.02)
    res = run_heave(log, tmp_path / "heave.csv")
    out = res.recording
    s = res.summary
    assert s["heave_method"] == "gnss_height" and "no accelerometer" in s["method_note"]
    assert 60.0 <= s["window_s"] <= 80.0 and s["dominant_period_s"] == pytest.approx(6.7, rel=0.05)
    m = out["settled"] > 0
    err = out["heave"][m] - np.interp(out.time[m], t, truth)
    assert np.sqrt(np.mean(err**2)) < 0.02 and m.sum() > 0.7 * len(t)


def test_fix_quality_below_rtk_is_excluded(tmp_path):
    log = tmp_path / "mixed.nmea"
    t, truth = _rtk_log(log, 1.0, 400.0, bad_every=10)  # every 10th fix autonomous and 0.8 m off
    res = run_heave(log, None, method="gnss")
    s, out = res.summary, res.recording
    assert s["excluded_fix_quality"] == 40 and s["fix_quality"] == {"GNSS": 40, "RTK fixed": 360}
    bad = out["gnss_fix_quality"] == 1
    assert np.all(np.isnan(out["heave"][bad])) and np.all(out["settled"][bad] == 0)
    m = out["settled"] > 0
    assert np.sqrt(np.mean((out["heave"][m] - np.interp(out.time[m], t, truth)) ** 2)) < 0.02
    every = run_heave(log, None, method="gnss", gnss_fix="any").recording
    assert np.nanmax(np.abs(every["heave"])) > 0.5  # taken in, the autonomous fixes spike


def test_lever_arm_with_attitude_on_rows_of_its_own():
    """Antenna 10 m up and 3 m to starboard of the monitoring point; roll ±5° at 9 s. Heights at 1 Hz and roll at
    10 Hz sit on rows of their own (NaN between), as an NMEA log gives them."""
    tg = np.arange(0.0, 400.0, 1.0)
    ta = np.arange(0.05, 400.0, 0.1)
    heave_point = 0.07 * np.sin(2 * np.pi * tg / 6.7)
    roll_a = 5.0 * np.sin(2 * np.pi * ta / 9.0)
    roll_g = np.radians(5.0 * np.sin(2 * np.pi * tg / 9.0))
    lever = np.array([0.0, -3.0, 10.0])  # monitoring point relative to the antenna, body FRD
    h_ant = 3.4 + heave_point + (np.sin(roll_g) * lever[1] + np.cos(roll_g) * lever[2])
    t = np.concatenate([tg, ta])
    order = np.argsort(t)
    gh = np.concatenate([h_ant, np.full(len(ta), np.nan)])[order]
    roll = np.concatenate([np.full(len(tg), np.nan), roll_a])[order]
    rec = Recording(t[order], {"gnss_height": gh, "roll": roll, "pitch": np.where(np.isnan(roll), np.nan, 0.0)})
    rec.units.update({"gnss_height": "m", "roll": "deg", "pitch": "deg"})
    out, s = height_heave(rec, window_s=60.0, lever_arm=lever)
    m = out["settled"] > 0
    assert np.sqrt(np.mean((out["heave"][m] - heave_point[m]) ** 2)) < 0.005
    assert "no gnss_fix_quality" in s["warnings"][0]
    raw, _ = height_heave(rec, window_s=60.0)  # without the lever arm: the antenna's sway in roll is in it
    assert np.sqrt(np.mean((raw["heave"][m] - heave_point[m]) ** 2)) > 0.1


def test_detrend_passes_a_wave_and_removes_a_trend():
    t = np.arange(0.0, 600.0, 0.5)
    wave = 0.1 * np.sin(2 * np.pi * t / 8.0)
    hv, settled = detrend_height(t, 50.0 + 0.002 * t + wave, 80.0)
    m = settled > 0
    assert np.max(np.abs(hv[m] - wave[m])) < 0.002 and not settled[:10].any() and m.sum() > 400


def test_evaluate_heave_against_gnss_height_and_cli(tmp_path, capsys):
    log = tmp_path / "rtk.nmea"
    t, truth = _rtk_log(log, 1.0, 500.0, seed=3)
    est = Recording(t.copy(), {"heave": truth + 0.005 * np.cos(t)}, {"heave": "m"})
    s = evaluate(est, str(log), channel="heave")
    assert "gnss_height" in s["heave"]["reference_heave"] and s["heave"]["heave"]["rmse"] < 0.02
    r = CliRunner().invoke(cli, ["heave", str(log), "-o", str(tmp_path / "h.csv"), "--height-window", "70", "--json"])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.output)
    assert summary["window_s"] == 70.0 and summary["heave_method"] == "gnss_height"
    with pytest.raises(SystemExit) as e:
        main(["heave", str(log), "-o", str(tmp_path / "h2.csv"), "--lever-arm", "0,0,1"])
    assert e.value.code == 2 and "--gnss-lever-arm" in capsys.readouterr().err


def test_accelerometer_heave_checked_against_the_gnss_height():
    """With an accelerometer and a 1 Hz RTK height on rows of its own, the height heave becomes ref_heave and the
    summary compares the two at the height's own times (the delayed heave agrees to about the height noise)."""
    from imutool.sim.sea import sea_state

    rec = sea_state(duration=600, rate_hz=10, hs=2.0, tp=9.0, seed=3)
    truth = np.asarray(rec["ref_heave"], float)
    del rec.channels["ref_heave"]
    rng = np.random.default_rng(5)
    gh = np.full(len(rec), np.nan)
    gh[::10] = 3.4 + truth[::10] + 0.01 * rng.standard_normal(len(gh[::10]))
    rec.add("gnss_height", gh, "m")
    rec.add("gnss_fix_quality", np.where(np.isfinite(gh), 4.0, np.nan), "1")
    res = run_heave(rec, None, method="bandpass")
    g = res.summary["gnss_reference"]
    assert g["ref_heave"] == "added" and g["compared_at"] == "the reference's own times"
    assert g["heave_delayed"]["rmse"] < 0.03 and g["heave_delayed"]["n"] > 400
    assert "gnss_height" in res.recording.meta["ref_heave"]
