"""`imutool nmea`: HRM/XDR/HDG/THS sentences validate with the project's parser and pynmea2; file and serial out."""

from __future__ import annotations

import json
import os
import threading
import time

import numpy as np
import pynmea2
import pytest
from click.testing import CliRunner

import formats
from formats import Recording
from formats.nmea import decode, parse_sentence
from imutool.cli import cli
from imutool.cli.nmea import nmea_lines
from imutool.roll import roll_stats


def est(duration=60.0, fs=10.0) -> Recording:
    t = np.arange(0.0, duration, 1.0 / fs)
    s = np.sin(2 * np.pi * t / 8.0)
    roll = np.where(s > 0, 12.0 * s, 7.0 * s)
    pitch = 2.0 * np.sin(2 * np.pi * t / 5.0)
    heading = (350.0 + 2.0 * t) % 360.0
    return Recording(t, {"roll": roll, "pitch": pitch, "heading": heading})


def test_sentences_validate_and_decode_back():
    rec = est()
    lines = list(nmea_lines(rec, ["HRM", "XDR", "HDG", "THS"], None, deviation_deg=-1.5, variation_deg=3.0))
    assert len(lines) == 4 * len(rec)
    rs = roll_stats(rec.time, rec["roll"])
    by_t: dict[float, dict[str, str]] = {}
    for t, s in lines:
        assert len(s) + 2 <= 82
        ps = parse_sentence(s)  # checksum required
        assert ps.checksum_ok
        pyn = pynmea2.parse(s, check=True)  # HRM/THS types registered by formats.nmea
        assert pyn.sentence_type == ps.formatter
        by_t.setdefault(t, {})[ps.formatter] = s
    i = len(rec) - 1
    last = by_t[float(rec.time[i])]
    hrm = decode(last["HRM"])
    assert hrm["heel"] == pytest.approx(round(rec["roll"][i], 1), abs=1e-9)
    assert hrm["roll_period"] == pytest.approx(round(rs.roll_period[i], 1), abs=1e-9)
    assert hrm["amp_port"] == pytest.approx(round(rs.amp_port[i], 1), abs=1e-9)
    assert hrm["amp_stbd"] == pytest.approx(round(rs.amp_stbd[i], 1), abs=1e-9)
    assert hrm["peak_stbd"] == pytest.approx(round(rs.peak_stbd[i], 1), abs=1e-9)
    assert last["HRM"].split(",")[5] == "A"
    xdr = decode(last["XDR"])
    assert xdr["roll"] == pytest.approx(round(rec["roll"][i], 1)) and xdr["pitch"] == pytest.approx(
        round(rec["pitch"][i], 1))
    hdg = decode(last["HDG"])
    # heading channel is magnetic: sensor = magnetic − deviation; deviation W 1.5, variation E 3.0
    assert hdg["deviation"] == pytest.approx(-1.5) and hdg["variation"] == pytest.approx(3.0)
    assert hdg["heading_sensor"] == pytest.approx(round((rec["heading"][i] + 1.5) % 360.0, 1))
    ths = decode(last["THS"])
    assert ths["heading_true"] == pytest.approx(round((rec["heading"][i] + 3.0) % 360.0, 1))
    assert last["THS"].split(",")[2][0] == "A"


def test_hrm_before_first_cycle_has_null_period_and_valid_heel():
    rec = est(duration=5.0)
    (_, s0), *_ = nmea_lines(rec, ["HRM"], None)
    f = s0.split("*")[0].split(",")
    assert f[2] == f[3] == f[4] == "" and f[5] == "A"


def test_xdr_ids_signs_talkers_and_ths_mode():
    rec = est(duration=3.0)
    lines = [s for _, s in nmea_lines(rec, ["XDR", "THS"], None, xdr_roll_id="HEEL", xdr_pitch_id="TRIM",
                                      xdr_roll_sign=-1, heading_ref="true", ths_mode="S",
                                      talkers={"XDR": "II", "THS": "IN"})]
    xdr = [s for s in lines if "XDR" in s][-1]
    assert xdr.startswith("$IIXDR") and ",HEEL" in xdr and ",TRIM" in xdr
    vals = decode(xdr, xdr_map={"HEEL": "-roll", "TRIM": "pitch"})  # receiver undoes the sign
    assert vals["roll"] == pytest.approx(round(rec["roll"][-1], 1))
    ths = [s for s in lines if "THS" in s][-1]
    assert ths.startswith("$INTHS") and ths.split(",")[2][0] == "S"


def test_ths_refuses_magnetic_heading_without_variation():
    with pytest.raises(formats.ImutoolError, match="variation"):
        list(nmea_lines(est(duration=2.0), ["THS"], None))
    with pytest.raises(formats.ImutoolError, match="unknown sentence"):
        list(nmea_lines(est(duration=2.0), ["GGA"], None))


def test_cli_file_rate_and_stamp_roundtrip(tmp_path):
    src = tmp_path / "est.csv"
    formats.write(est(), src)
    out = tmp_path / "out.nmea"
    r = CliRunner().invoke(cli, ["nmea", str(src), "-o", str(out), "--sentences", "HRM,XDR", "--rate", "2",
                                 "--time-prefix", "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.output)
    assert s["sentences"] == {"HRM": 120, "XDR": 120}
    raw = out.read_bytes()
    assert raw.count(b"\r\n") == 240
    back = formats.read(out)
    assert back.meta["time_source"] == "stamp"
    ref = est()
    idx = np.searchsorted(ref.time, back.time)
    assert np.max(np.abs(back["roll"] - ref["roll"][idx])) <= 0.05 + 1e-9
    assert np.allclose(np.diff(back.time), 0.5)
    r = CliRunner().invoke(cli, ["nmea", str(src), "-o", str(tmp_path / "x.nmea"), "--sentences", "THS"])
    assert r.exit_code != 0 and "variation" in str(r.exception)
    assert not (tmp_path / "x.nmea").exists()


def test_serial_output_through_a_pseudo_terminal(tmp_path):
    pytest.importorskip("serial")
    master, slave = os.openpty()
    import termios
    import tty

    tty.setraw(slave)
    attrs = termios.tcgetattr(slave)
    termios.tcsetattr(slave, termios.TCSANOW, attrs)
    port = os.ttyname(slave)
    src = tmp_path / "est.csv"
    formats.write(est(duration=4.0), src)
    got = bytearray()
    stop = threading.Event()

    def reader():
        os.set_blocking(master, False)
        while not stop.is_set():
            try:
                chunk = os.read(master, 4096)
                got.extend(chunk)
            except BlockingIOError:
                time.sleep(0.01)
            except OSError:
                break

    th = threading.Thread(target=reader, daemon=True)
    th.start()
    try:
        r = CliRunner().invoke(cli, ["nmea", str(src), "--serial", port, "--baud", "38400", "--no-realtime",
                                     "--sentences", "HRM,XDR", "--json"])
        assert r.exit_code == 0, r.output
        deadline = time.monotonic() + 5.0
        while got.count(b"\r\n") < 80 and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        stop.set()
        th.join(2.0)
        os.close(master)
        os.close(slave)
    lines = [x for x in got.decode("ascii").split("\r\n") if x]
    assert len(lines) == 80
    for s in lines:
        assert parse_sentence(s).checksum_ok
        pynmea2.parse(s, check=True)
