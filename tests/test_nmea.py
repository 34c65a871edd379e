"""NMEA 0183 (formats/nmea.py): framing, checksums, decoders, writers, whole logs, real data, fuzz.

Run as a script (``python tests/test_nmea.py``) to print the agreement table against gpsd's own decode.
"""

from __future__ import annotations

import collections
import json
import math
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pynmea2
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from formats import ImutoolError, Recording  # noqa: E402
from formats.nmea import (  # noqa: E402
    MAX_SENTENCE_LENGTH,
    NmeaChecksumError,
    NmeaFieldError,
    NmeaParseError,
    NmeaUnsupportedError,
    checksum,
    decode,
    decode_checked,
    format_sentence,
    hdg_sentence,
    hdt_sentence,
    hrm_sentence,
    iter_sentences,
    parse_sentence,
    pashr_sentence,
    read_nmea,
    rot_sentence,
    ths_sentence,
    write_nmea,
    xdr_roll_pitch,
    xdr_sentence,
)

GPSD_LOGS = [
    "bundg_zeus_9.log",
    "hemi.log",
    "pypilot.log",
    "rst39.log",
    "saab-r4.log",
    "skytraq-PX1172RH_DS.log",
    "tnt-revolution.log",
]


def _valid_for_pynmea2(s: str) -> None:
    """pynmea2 checks the framing and checksum independently of our code (types it lacks: only framing)."""
    try:
        pynmea2.parse(s, check=True)
    except pynmea2.SentenceTypeError:
        body = s[1 : s.index("*")]
        assert pynmea2.NMEASentence.checksum(body) == int(s[-2:], 16)


# -- framing and checksums -------------------------------------------------------------------------------------
def test_checksum_matches_known_sentences():
    assert checksum("GPHDT,25.50,T") == "37"
    assert checksum("HEHDT,4.0,T") == "2B"
    assert checksum("") == "00"


def test_hrm_example_from_standards_is_exact():
    s = hrm_sentence(-3.2, 12.0, 8.5, 9.1, True, 21.0, 19.5, datetime(2024, 11, 15, 8, 30, 0))
    assert s == "$IIHRM,-3.2,12.0,8.5,9.1,A,21.0,19.5,083000,15,11*0D"
    # a tz-aware reset time is converted to UTC; fractions of seconds are never written
    cet = datetime(2024, 11, 15, 9, 30, 0, 999000).astimezone(timezone.utc).replace(tzinfo=timezone.utc)
    assert ",0830" in hrm_sentence(-3.2, 12.0, 8.5, 9.1, True, reset_utc=cet.replace(hour=8))
    d = decode(s)
    assert d["heel"] == -3.2 and d["roll_period"] == 12.0 and d["amp_port"] == 8.5 and d["amp_stbd"] == 9.1
    assert d["peak_port"] == 21.0 and d["peak_stbd"] == 19.5
    assert d["peak_reset_time"] == 8 * 3600 + 30 * 60 and d["peak_reset_day"] == 15 and d["peak_reset_month"] == 11


def test_hrm_invalid_and_amplitudes_positive():
    s = hrm_sentence(None, None, -7.0, 6.0, False)
    assert s.startswith("$IIHRM,,,7.0,6.0,V,,,,,*")
    d = decode(s)
    assert "heel" not in d and "amp_port" not in d  # status V: measured values dropped
    # hhmmss.ss accepted on input (standards.md §2.2 pitfall), status A keeps everything
    body = "IIHRM,1.0,10.0,2.0,3.0,A,,,083000.50,15,11"
    assert decode(f"${body}*{checksum(body)}")["peak_reset_time"] == pytest.approx(30600.5)


def test_xdr_example_from_standards_is_exact():
    assert xdr_roll_pitch(3.4, -1.2) == "$YXXDR,A,-1.2,D,PTCH,A,3.4,D,ROLL*74"
    d = decode("$YXXDR,A,-1.2,D,PTCH,A,3.4,D,ROLL*74")
    assert d == {"pitch": -1.2, "roll": 3.4}


def test_parse_sentence_checksum_policies():
    good = "$HEHDT,4.0,T*2B"
    s = parse_sentence(good)
    assert (s.talker, s.formatter, s.fields, s.checksum_ok, s.type) == ("HE", "HDT", ["4.0", "T"], True, "HDT")
    with pytest.raises(NmeaChecksumError):
        parse_sentence("$HEHDT,4.0,T*2C")
    assert parse_sentence("$HEHDT,4.0,T*2C", "ignore").checksum_ok is False
    with pytest.raises(NmeaChecksumError):
        parse_sentence("$HEHDT,4.0,T")
    assert parse_sentence("$HEHDT,4.0,T", "accept-missing").checksum_ok is None
    with pytest.raises(NmeaChecksumError):
        parse_sentence("$HEHDT,4.0,T*2C", "accept-missing")
    with pytest.raises(ImutoolError):
        parse_sentence(good, "sometimes")
    # lower-case hex, CR/LF and numeric talker ids are fine; proprietary address kept whole
    assert parse_sentence("$24HDG,182.1,00.0,E,00.0,E*45\r\n").talker == "24"
    p = parse_sentence("$PASHR,204132.000,010.51,T,+00.39,-00.79,-00.84,0.151,0.075,0.555,1,0*03")
    assert (p.talker, p.formatter, p.type) == ("P", "ASHR", "PASHR")
    assert parse_sentence("!AIVDM,1,1,,B,13aGhtw0R<OJf=6LgQ?Ad1FF05`L,0*24").type == "VDM"


@pytest.mark.parametrize(
    "line",
    [
        "",
        "hello",
        "$",
        "$GP",
        "$GPHDT",
        "#comment",
        "$G\x00HDT,1,T*00",
        "$SDVLW,$SDVLW,,N,322.0,N*4E",
        "$gphdt,1.0,T",
        "$GPHDT,1*2*00",
    ],
)
def test_parse_sentence_garbage_raises_parse_error(line):
    with pytest.raises(NmeaParseError):
        parse_sentence(line, "ignore")


# -- decoders -----------------------------------------------------------------------------------------------------
def _s(body: str) -> str:
    return f"${body}*{checksum(body)}"


def test_decode_heading_sentences():
    assert decode(_s("HEHDT,274.07,T")) == {"heading_true": 274.07}
    assert decode(_s("GPHDT,,T")) == {}
    assert decode(_s("APHDM,218.634,M")) == {"heading_mag": 218.634}
    d = decode(_s("HCHDG,100.0,2.0,W,3.5,E"))
    assert d["heading_sensor"] == 100.0 and d["deviation"] == -2.0 and d["variation"] == 3.5
    assert d["heading_mag"] == pytest.approx(98.0) and d["heading_true"] == pytest.approx(101.5)
    d = decode(_s("SDHDG,229.8,,,1.3,E"))  # deviation unknown: no magnetic/true heading invented
    assert d == {"heading_sensor": 229.8, "variation": 1.3}
    assert decode(_s("HCHDG,359.5,1.0,E,,"))["heading_mag"] == pytest.approx(0.5)
    with pytest.raises(NmeaFieldError):
        decode(_s("HCHDG,100.0,2.0,X,,"))
    assert decode(_s("GNTHS,244.28,A")) == {"heading_true": 244.28, "ths_mode": float(ord("A"))}
    assert decode(_s("GNTHS,244.28,V")) == {"ths_mode": float(ord("V"))}
    with pytest.raises(NmeaFieldError):
        decode(_s("GNTHS,244.28,Q"))
    assert decode(_s("APROT,-0.008,A")) == {"rot": -0.008}
    assert decode(_s("TIROT,12.0,V")) == {}
    assert decode(_s("GPGGA,,,,,,0,,,,M,,M,,")) == {}  # no fix: no height (the sentence gives its time only)
    with pytest.raises(NmeaUnsupportedError):
        decode(_s("GPGSV,1,1,00"))


def test_decode_xdr_mapping_signs_and_misalignment():
    line = "$IIXDR,C,,C,AIRTEMP,A,-1.0,D,HEEL,A,2.9,D,TRIM,P,,B,BARO,A,-3.9,D,RUDDER*29"
    assert decode(line) == {"roll": -1.0, "pitch": 2.9}
    # configurable map: a device that sends roll with the opposite sign under its own id
    assert decode(line, xdr_map={"HEEL": "-roll"}) == {"roll": 1.0}
    assert decode(line, xdr_map={"RUDDER": ("roll", -1)}) == {"roll": 3.9}
    assert decode(_s("YXXDR,A,5.0,D,Heel Angle")) == {"roll": 5.0}
    with pytest.raises(ImutoolError):
        decode(line, xdr_map={"HEEL": "yaw"})
    # B&G GoFree: stray field shifts the groups, and "-1.-3" is not a number
    gofree = "$IIXDR,C,C,10.7,C,AIRTEMP,A,0.5,D,HEEL,A,-1.-3,D,TRIM,P,1.026,B,BARO,A,A,-4.-3,D,RUDDER*18"
    vals, problems = decode_checked(gofree)
    assert vals == {"roll": 0.5}
    assert len(problems) == 2 and "multiple of 4" in problems[0] and "-1.-3" in problems[1]
    with pytest.raises(NmeaFieldError):
        decode(_s("YXXDR,A,-1.-3,D,ROLL"))
    with pytest.raises(NmeaFieldError, match="not an angle"):  # a temperature called ROLL is not an angle
        decode(_s("YXXDR,C,12.0,C,ROLL"))


def test_decode_pashr_attitude_and_heave():
    d = decode("$PASHR,204132.000,010.51,T,+00.39,-00.79,-00.84,0.151,0.075,0.555,1,0*03")
    assert d == {
        "heading_true": 10.51,
        "roll": 0.39,
        "pitch": -0.79,
        "heave": -0.84,
        "roll_std": 0.151,  # accuracy and status fields are kept as channels (issue 38)
        "pitch_std": 0.075,
        "heading_std": 0.555,
        "pashr_aiding": 1.0,
        "pashr_imu_status": 0.0,
    }
    with pytest.raises(NmeaUnsupportedError):
        decode(_s("PASHR,ACK,GPS"))


# -- writers: round trips ----------------------------------------------------------------------------------------
def test_a_heading_is_wrapped_at_the_resolution_it_is_printed_with():
    """Wrap after rounding: −0.03125° is 359.97 with PASHR's two decimals and 0.0 with HDT's one (359.97 → 360.0)."""
    assert ",359.97,T," in pashr_sentence(None, -0.03125, 0.0, 0.0, 0.0)
    assert ",0.00,T," in pashr_sentence(None, 359.996, 0.0, 0.0, 0.0)
    assert hdt_sentence(-0.03125).startswith("$HEHDT,0.0,T")
    assert hdt_sentence(359.94).startswith("$HEHDT,359.9,T")


@settings(max_examples=150, deadline=None)
@given(
    h=st.floats(-720, 720),
    r=st.floats(-90, 90),
    p=st.floats(-90, 90),
    hv=st.floats(-20, 20),
    dev=st.floats(-30, 30),
    var=st.floats(-60, 60),
    rot=st.floats(-9999, 9999),
    per=st.floats(0, 99),
    ap=st.floats(0, 90),
    asb=st.floats(0, 90),
    tod=st.floats(0, 86399.9),
)
# examples that once failed, kept explicit: PASHR wrapped −0.03125° to 0.00 (it is 359.97 at two decimals)
@example(h=-0.03125, r=0.0, p=0.0, hv=0.0, dev=0.0, var=0.0, rot=0.0, per=0.0, ap=0.0, asb=0.0, tod=0.0)
def test_every_writer_round_trips(h, r, p, hv, dev, var, rot, per, ap, asb, tod):
    wrapped = h % 360.0

    def close_deg(a, b, tol):
        return abs((a - b + 180.0) % 360.0 - 180.0) <= tol

    sents = {
        "hdt": hdt_sentence(h),
        "ths": ths_sentence(h, "E"),
        "hdg": hdg_sentence(h, dev, var),
        "rot": rot_sentence(rot),
        "xdr": xdr_roll_pitch(r, p),
        "hrm": hrm_sentence(r, per, ap, asb, True, ap, asb, datetime(2025, 1, 2, 3, 4, 5)),
        "pashr": pashr_sentence(tod, h, r, p, hv),
        "xdr4": xdr_sentence([("A", r, "D", "ROLL"), ("A", p, "D", "PTCH"), ("D", hv, "M", "HEAVE")]),
    }
    for s in sents.values():
        assert len(s) + 2 <= MAX_SENTENCE_LENGTH
        assert parse_sentence(s).checksum_ok is True
        _valid_for_pynmea2(s)
    assert close_deg(decode(sents["hdt"])["heading_true"], wrapped, 0.05 + 1e-9)
    d = decode(sents["ths"])
    assert close_deg(d["heading_true"], wrapped, 0.05 + 1e-9) and chr(int(d["ths_mode"])) == "E"
    d = decode(sents["hdg"])
    assert close_deg(d["heading_sensor"], wrapped, 0.05 + 1e-9)
    assert abs(d["deviation"] - dev) <= 0.05 + 1e-9 and abs(d["variation"] - var) <= 0.05 + 1e-9
    assert abs(decode(sents["rot"])["rot"] - rot) <= 0.05 + 1e-9
    d = decode(sents["xdr"])
    assert abs(d["roll"] - r) <= 0.05 + 1e-9 and abs(d["pitch"] - p) <= 0.05 + 1e-9
    d = decode(sents["hrm"])
    assert abs(d["heel"] - r) <= 0.05 + 1e-9 and abs(d["roll_period"] - per) <= 0.05 + 1e-9
    assert abs(d["amp_port"] - ap) <= 0.05 + 1e-9 and abs(d["peak_stbd"] - asb) <= 0.05 + 1e-9
    assert d["peak_reset_time"] == 3 * 3600 + 4 * 60 + 5
    d = decode(sents["pashr"])
    assert close_deg(d["heading_true"], wrapped, 0.005 + 1e-9)
    assert abs(d["roll"] - r) <= 0.005 + 1e-9 and abs(d["pitch"] - p) <= 0.005 + 1e-9
    assert abs(d["heave"] - hv) <= 0.005 + 1e-9
    d = decode(sents["xdr4"], xdr_map={"ROLL": "roll", "PTCH": "pitch", "HEAVE": "heave"})
    assert abs(d["heave"] - hv) <= 0.05 + 1e-9


def test_format_sentence_limits():
    with pytest.raises(ImutoolError, match="82"):
        format_sentence("YX", "XDR", ["A", 1.23456, "D", "ROLL"] * 5)
    with pytest.raises(ImutoolError, match="reserved"):
        format_sentence("II", "TXT", ["a,b"])
    with pytest.raises(ImutoolError):
        format_sentence("IIX", "HDT", [1.0])
    assert format_sentence("HE", "HDT", [-0.0001, "T"], 1) == "$HEHDT,0.0,T*" + checksum("HEHDT,0.0,T")
    assert format_sentence("HE", "HDT", [float("nan"), "T"], 1).startswith("$HEHDT,,T*")
    with pytest.raises(ImutoolError):
        ths_sentence(10.0, "X")
    assert ths_sentence(float("nan")).startswith("$HETHS,,V*")
    assert rot_sentence(None).startswith("$TIROT,,V*")


def _sim_recording(n: int = 200, rate: float = 10.0) -> Recording:
    t = 1000.0 + np.arange(n) / rate
    rec = Recording(t)
    rec.meta["start_utc"] = "1970-01-01T00:16:40Z"  # real time of the first row (PASHR never invents a UTC)
    rec.add("heading", (30.0 + 5.0 * t) % 360.0)
    rec.add("roll", 15.0 * np.sin(2 * np.pi * t / 8.0))
    rec.add("pitch", 3.0 * np.sin(2 * np.pi * t / 5.0))
    rec.add("heave", 0.8 * np.sin(2 * np.pi * t / 7.0))
    return rec


def test_write_then_read_round_trip(tmp_path):
    rec = _sim_recording()
    out = tmp_path / "out.nmea"
    info = write_nmea(rec, out, sentences=("HDT", "THS", "XDR", "ROT", "PASHR", "HRM", "HDG"))
    assert info["sentences"]["HDT"] == len(rec) and info["sentences"]["PASHR"] == len(rec)
    raw = out.read_bytes()
    assert raw.count(b"\r\n") == info["total"] and b"\n" not in raw.replace(b"\r\n", b"")
    for line in raw.decode("ascii").splitlines():
        assert len(line) + 2 <= MAX_SENTENCE_LENGTH
        _valid_for_pynmea2(line)
    back = read_nmea(out)
    assert back.meta["time_source"] == "nmea"  # PASHR carries the UTC time of day
    assert back.meta["sentences"]["XDR"]["parsed"] == len(rec)
    # PASHR rows carry the original times (to the ms) and values (to 0.01)
    m = np.isfinite(back["heave"])
    assert m.sum() == len(rec)
    assert np.allclose(back.time[m], rec.time, atol=6e-4)
    assert np.allclose(back["heave"][m], rec["heave"], atol=0.005 + 1e-9)
    assert np.allclose(back["roll"][m], rec["roll"], atol=0.005 + 1e-9)
    err = (back["heading"][m] - rec["heading"] + 180) % 360 - 180
    assert np.abs(err).max() <= 0.005 + 1e-9
    # decimation to 2 Hz keeps recorded values and roughly the rate
    out2 = tmp_path / "slow.nmea"
    info2 = write_nmea(rec, out2, sentences=("XDR",), rate_hz=2.0, talker="II")
    assert info2["sentences"] == {"XDR": 40}
    assert out2.read_text().startswith("$IIXDR,")


def test_write_errors_leave_no_file(tmp_path):
    rec = Recording(np.arange(5.0))
    rec.add("temp", np.ones(5), "degC")
    out = tmp_path / "none.nmea"
    with pytest.raises(ImutoolError, match="no sentence"):
        write_nmea(rec, out, sentences=("HDT",))
    assert not out.exists() and not list(tmp_path.iterdir())
    with pytest.raises(ImutoolError):
        list(iter_sentences(_sim_recording(), sentences=("GGA",)))


def test_iter_sentences_derives_rot_from_heading():
    rec = _sim_recording()
    rots = [decode(s)["rot"] for _, s in iter_sentences(rec, ("ROT",))]
    assert np.allclose(rots[5:-5], 300.0, atol=0.05 + 1e-9)  # 5 deg/s = 300 deg/min


# -- whole logs: time bases, prefixes, errors ---------------------------------------------------------------------
def test_read_log_with_timestamps_and_comments(tmp_path):
    lines = [
        "# comment",
        "",
        "1700000000.000 $HEHDT,10.0,T*" + checksum("HEHDT,10.0,T"),
        "2023-11-14T22:13:20.500Z " + _s("HEHDT,11.0,T"),
        "1700000001000;N;" + _s("YXXDR,A,1.5,D,ROLL"),
        "\\s:GYRO,c:1700000001.5*00\\" + _s("HEHDT,12.0,T"),
        "1700000002 $HEHDT,13.0,T*FF",
        "1700000003 $HEHDT,1",
        '1700000004 {"class":"X"}',
    ]
    p = tmp_path / "stamped.log"
    p.write_text("\n".join(lines) + "\n")
    rec = read_nmea(p)
    assert rec.meta["time_source"] == "stamp"
    assert np.allclose(rec.time, [1700000000.0, 1700000000.5, 1700000001.0, 1700000001.5])
    assert np.allclose(rec["heading"][[0, 1, 3]], [10.0, 11.0, 12.0]) and np.isnan(rec["heading"][2])
    assert rec["roll"][2] == 1.5
    hdt = rec.meta["sentences"]["HDT"]
    assert hdt["parsed"] == 3 and hdt["bad_checksum"] == 2  # the '*FF' line and the truncated one
    assert [b["line"] for b in rec.meta["bad_lines"]] == [7, 8]
    assert rec.meta["lines"]["comment"] == 1 and rec.meta["lines"]["not_nmea"] == 1
    rec_i = read_nmea(p, time_source="index", nominal_rate_hz=2.0)
    assert rec_i.meta["time_source"] == "index" and np.allclose(np.diff(rec_i.time), 0.5)
    with pytest.raises(ImutoolError):
        read_nmea(p, time_source="nmea")


def test_nmea_time_base_dates_rollover_and_spliced_prefix(tmp_path):
    lines = [
        _s("GPZDA,235959,16,04,14,-02,00"),  # 2-digit year as B&G GoFree sends it
        _s("HEHDT,1.0,T"),
        _s("HEHDT,2.0,T"),
        _s("GPGGA,000001,,,,,0,,,,M,,M,,"),  # after midnight, no new date yet
        _s("HEHDT,3.0,T"),
        "garbage" + _s("HEHDT,4.0,T"),  # not a timestamp: counted, sentence still read
        _s("GPGGA,000000,,,,,0,,,,M,,M,,"),  # backwards: not used as a time anchor
        _s("HEHDT,5.0,T"),
    ]
    p = tmp_path / "midnight.nmea"
    p.write_text("\r\n".join(lines))
    rec = read_nmea(p)
    t0 = datetime(2014, 4, 16, 23, 59, 59, tzinfo=timezone.utc).timestamp()
    assert rec.meta["time_source"] == "nmea" and rec.meta["time"]["anchors_rejected_going_backwards"] == 1
    assert np.allclose(rec.time[:3], t0 + np.array([1, 2, 4]) / 3 * 2, atol=1e-6)
    assert np.all(np.diff(rec.time) > 0) and rec.meta["lines"]["unrecognised_prefix"] == 1
    assert rec.meta["time"]["start_utc"].startswith("2014-04-16T23:59:59")


@pytest.mark.parametrize(
    "zda",
    [
        "GPZDA,235959,31,12,9999,,",
        "GPZDA,000000,01,01,0001,,",
        "GPZDA,99,99,99,99,,",
        "GPRMC,000000,A,,,,,,,311299,,,A",
        "GPGGA,123456.789,,,,,0,,,,M,,M,,",
    ],
)
def test_extreme_dates_do_not_crash(tmp_path, zda):
    p = tmp_path / "dates.log"
    p.write_text("\n".join([_s("HEHDT,1.0,T"), _s(zda), _s("HEHDT,2.0,T"), _s(zda), _s("HEHDT,3.0,T")]))
    rec = read_nmea(p)
    assert len(rec) == 3 and np.all(np.diff(rec.time) > 0)


def test_decode_psti036():
    d = decode("$PSTI,036,003832.000,290322,244.28,2.77,0.00,R*5D")
    assert d == {"heading_true": 244.28, "pitch": 2.77, "roll": 0.0}
    assert decode(_s("PSTI,036,003832.000,290322,244.28,2.77,0.00,N")) == {}
    with pytest.raises(NmeaUnsupportedError):
        decode(_s("PSTI,030,003832.000,A"))


def test_read_rejects_files_without_usable_sentences(tmp_path):
    p = tmp_path / "empty.log"
    p.write_text("# nothing\n$GPGGA,,,,,,0,,,,M,,M,,*66\n$GPHDT,,T*1B\n")
    with pytest.raises(ImutoolError, match="no usable"):
        read_nmea(p)
    with pytest.raises(ImutoolError, match="cannot read"):
        read_nmea(tmp_path / "missing.log")
    with pytest.raises(ImutoolError):
        read_nmea(p, checksum_policy="never")


def test_formats_read_dispatches_to_nmea(shared):
    import formats

    rec = formats.read(shared("nmea_gpsd", "saab-r4.log"))
    assert rec.meta["format"] == "nmea0183" and np.nanmax(rec["heading"]) == 4.1


# -- real data ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", GPSD_LOGS)
def test_every_gpsd_log_reads(shared, name):
    rec = read_nmea(shared("nmea_gpsd", name))
    assert len(rec) > 0
    assert np.all(np.diff(rec.time) > 0)
    for c in rec.meta["sentences"].values():
        assert c["bad_checksum"] == 0 and c["malformed"] == 0  # manifest: all checksums verify


def test_gpsd_logs_expected_content(shared):
    r = read_nmea(shared("nmea_gpsd", "pypilot.log"))
    assert r.meta["time_source"] == "index"
    assert np.isfinite(r["pitch"]).sum() == 8 and np.isfinite(r["roll"]).sum() == 7
    assert np.nanmin(r["rot"]) == pytest.approx(-0.008)
    r = read_nmea(shared("nmea_gpsd", "hemi.log"))
    assert r.meta["sentences"]["HDT"] == {
        "parsed": 4,
        "partial": 0,
        "no_data": 211,
        "bad_checksum": 0,
        "malformed": 0,
        "unsupported": 0,
    }
    r = read_nmea(shared("nmea_gpsd", "rst39.log"))
    assert r.meta["time_source"] == "nmea" and r.meta["time"]["origin"].startswith("unix")
    # every PASHR row sits at the time its own hhmmss.sss field gives (2014-02-19, from RMC)
    base = datetime(2014, 2, 19, tzinfo=timezone.utc).timestamp()
    pashr_t = [
        base + 20 * 3600 + 41 * 60 + float(ln.split(",")[1][4:])
        for ln in Path(shared("nmea_gpsd", "rst39.log")).read_text().splitlines()
        if ln.startswith("$PASHR")
    ]
    m = np.isfinite(r["heave"])
    assert np.allclose(r.time[m], pashr_t, atol=1e-6)
    r = read_nmea(shared("nmea_gpsd", "bundg_zeus_9.log"))
    assert np.isfinite(r["roll"]).sum() == 148 and np.isfinite(r["heading_sensor"]).sum() == 1457
    assert np.allclose(np.nanmax(r["variation"]), 1.3)


def test_signalk_corrupted_lines_counted(shared):
    r = read_nmea(shared("nmea_signalk", "gofree-merrimac.log"))
    s = r.meta["sentences"]
    assert s["VLW"]["malformed"] == 142 and s["VLW"]["parsed"] == 0  # spliced "$SDVLW,$SDVLW,..." lines
    assert s["XDR"]["parsed"] == 141 and s["XDR"]["partial"] == 141  # stray field + "-1.-3"
    assert s["VDM"]["unsupported"] == 1507 and s["HDG"]["parsed"] == 1375
    assert np.isfinite(r["roll"]).sum() == 141 and np.isfinite(r["heading_sensor"]).sum() == 1375
    assert r.meta["bad_lines"] and r.meta["bad_lines"][0]["type"] == "VLW"
    r = read_nmea(shared("nmea_signalk", "n2kd-183-merrimac.log"))  # numeric talkers $24HDG, $04HDM
    s = r.meta["sentences"]
    assert s["HDG"]["parsed"] == 123 and s["HDM"]["parsed"] == 247
    assert np.isfinite(r["heading"]).sum() == 123  # explicit 0.0 deviation and variation → true heading


# gpsd's .chk echoes each input sentence followed by the JSON it produced for it.
_GPSD_KEYS = {
    "heading_true": "heading",
    "heading_mag": "mheading",
    "roll": "roll",
    "pitch": "pitch",
    "rot": "rot",
    "heave": "heave",
}


def _decodes(raw: str) -> bool:
    try:
        decode_checked(parse_sentence(raw, "accept-missing"))
    except NmeaParseError:
        return False
    return True


def gpsd_agreement(chk: Path, lookahead: int = 12) -> tuple[collections.Counter, list[tuple]]:
    """Compare our decode with gpsd's ATT output sentence by sentence.

    'compared': gpsd printed an ATT record right after that sentence; 'compared_cycle': gpsd printed its ATT
    later in the same cycle (within ``lookahead`` sentences) after a sentence type we do not decode (SkyTraq
    $PSTI,036 closes the cycle that $GNTHS/$GNHDT started): a same-cycle consistency check.
    """
    groups: list[tuple[str, list[dict]]] = []
    for line in chk.read_text(errors="replace").splitlines():
        line = line.strip()
        if line.startswith(("$", "!")):
            groups.append((line, []))
        elif line.startswith("{") and groups:
            try:
                groups[-1][1].append(json.loads(line))
            except ValueError:
                pass
    stats: collections.Counter = collections.Counter()
    bad: list[tuple] = []
    for gi, (raw, recs) in enumerate(groups):
        att = [r for r in recs if r.get("class") == "ATT"]
        try:
            s = parse_sentence(raw, "accept-missing")
            vals, _ = decode_checked(s)
        except NmeaParseError:
            if att:
                stats["gpsd only: " + raw[1:].split(",")[0]] += 1
            continue
        mine = {k: v for k, v in vals.items() if k in _GPSD_KEYS}
        if not mine:
            continue
        how = "compared"
        if not att:
            nxt = next(
                (g for g in groups[gi + 1 : gi + 1 + lookahead] if any(r.get("class") == "ATT" for r in g[1])), None
            )
            if nxt is not None and _decodes(nxt[0]):
                nxt = None  # that ATT belongs to a sentence we decode ourselves: not this sentence's value
            if nxt is None:
                stats[f"ours only: {s.type}"] += 1
                continue
            att, how = [r for r in nxt[1] if r.get("class") == "ATT"], "compared_cycle"
        a = att[-1]
        for k, v in mine.items():
            g = a.get(_GPSD_KEYS[k])
            if g is None:
                stats[f"gpsd lacks: {s.type}.{k}"] += 1
                continue
            stats[f"{how}: {s.type}.{k}"] += 1
            if abs(g - v) > 5e-4 + 1e-12:
                bad.append((raw, k, v, g))
                stats[f"DISAGREE: {s.type}.{k}"] += 1
    return stats, bad


def test_agrees_with_gpsd_decode(shared):
    total = collections.Counter()
    for name in GPSD_LOGS:
        stats, bad = gpsd_agreement(shared("nmea_gpsd", name + ".chk"))
        assert not bad, (name, bad[:5])
        total.update(stats)
    n = sum(v for k, v in total.items() if k.startswith("compared"))
    assert n >= 80
    for key in (
        "compared: HDT.heading_true",
        "compared: HDM.heading_mag",
        "compared: XDR.roll",
        "compared: XDR.pitch",
        "compared: ROT.rot",
        "compared: PSTI.pitch",
    ):
        assert total[key] > 0, key


# -- fuzz: only counted skips or ImutoolError ------------------------------------------------------------------
_nmeaish = st.text(alphabet=st.sampled_from(list("$!*,.-+0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ \\:;#\t")), max_size=90)


@settings(max_examples=200, deadline=None)
@given(line=st.one_of(st.text(max_size=120), _nmeaish, _nmeaish.map(lambda b: _s("YXXDR," + b.lstrip("$!")))))
def test_fuzz_parse_sentence(line):
    for policy in ("require", "ignore", "accept-missing"):
        try:
            s = parse_sentence(line, policy)
        except NmeaParseError:
            continue
        try:
            decode(s)
        except NmeaParseError:
            pass


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    data=st.one_of(
        st.binary(max_size=400),
        st.lists(st.one_of(_nmeaish, _nmeaish.map(lambda b: _s("HEHDT," + b.lstrip("$!")))), max_size=20).map(
            lambda ls: "\n".join(ls).encode()
        ),
    )
)
def test_fuzz_read_nmea(tmp_path, data):
    p = tmp_path / "fuzz.log"
    p.write_bytes(data)
    try:
        rec = read_nmea(p, checksum_policy="accept-missing")
    except ImutoolError:
        return
    assert len(rec) > 0 and all(np.all(np.diff(rec.time) > 0) or len(rec) == 1 for _ in [0])


def test_fuzz_hits_valid_sentences_too():
    """Guard for the fuzzers above: a line built like theirs does decode."""
    assert math.isclose(decode(_s("HEHDT,12.5,T"))["heading_true"], 12.5)


if __name__ == "__main__":  # print the agreement table against gpsd's decode
    from conftest import shared_data  # noqa: E402

    grand: collections.Counter = collections.Counter()
    for name in GPSD_LOGS:
        stats, bad = gpsd_agreement(shared_data("nmea_gpsd", name + ".chk"))
        grand.update(stats)
        line = ", ".join(f"{k} {v}" for k, v in sorted(stats.items()))
        print(f"{name}: {line}" + (f"; BAD {bad[:3]}" if bad else ""))
    print(
        "TOTAL compared:",
        sum(v for k, v in grand.items() if k.startswith("compared")),
        "disagreements:",
        sum(v for k, v in grand.items() if k.startswith("DISAGREE")),
    )


def test_decode_rmc_vtg_sog_cog(tmp_path):
    kn = 1852.0 / 3600.0
    d = decode(_s("GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W"))
    assert d["sog"] == pytest.approx(22.4 * kn) and d["cog"] == pytest.approx(84.4)
    assert decode(_s("GPRMC,123519,V,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W")) == {}  # void fix
    assert decode(_s("GNRMC,123519,A,4807.038,N,01131.000,E,1.0,360.0,230394,,,N")) == {}  # FAA mode N
    assert decode(_s("GPRMC,000000,A,,,,,,,311299,,,A")) == {}  # no speed/course: time only
    d = decode(_s("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,A"))
    assert d["sog"] == pytest.approx(5.5 * kn) and d["cog"] == pytest.approx(54.7)
    assert decode(_s("GPVTG,,T,,M,,N,036.0,K,A"))["sog"] == pytest.approx(10.0)  # km/h when knots are empty
    d = decode(_s("GPVTG,054.7,034.4,005.5,010.2"))  # pre-2.3 layout without unit letters
    assert d["sog"] == pytest.approx(5.5 * kn) and d["cog"] == pytest.approx(54.7)
    assert decode(_s("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,N")) == {}
    with pytest.raises(NmeaFieldError, match="speed"):
        decode(_s("GPVTG,054.7,T,034.4,M,fast,N,010.2,K,A"))
    p = tmp_path / "gnss.nmea"
    p.write_text(
        "\n".join(f"{t:.1f};A;" + _s(f"GPRMC,12000{t},A,,,,,{10 * t:.1f},{359.5 + t:.1f},230394,,,A") for t in range(3))
        + "\n"
    )
    rec = read_nmea(p)
    assert np.allclose(rec.get("sog", "m/s"), [0, 10 * kn, 20 * kn]) and np.allclose(rec["cog"], [359.5, 0.5, 1.5])
