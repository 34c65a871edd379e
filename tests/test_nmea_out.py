"""`imutool nmea` / `heave --nmea` (imutool.nmea_out): every sentence type validates with our parser and pynmea2
(checksum, ≤ 82 characters), HDG carries the card's deviation, flags are honest (settling, no GNSS, UTC), TSS1
frames follow the published layout, the rate fits the baud, the heave sign is selectable and stated."""

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
from calibration.deviation import DeviationCard
from formats import Recording
from formats.nmea import MAX_SENTENCE_LENGTH, decode, parse_sentence, parse_tss1, tss1_frame
from imutool.cli import cli
from imutool.nmea_out import SENTENCES, nmea_lines, plan_rate, resolve_headings, row_bytes, write_log
from imutool.roll import roll_stats


def est(duration=60.0, fs=10.0) -> Recording:
    t = np.arange(0.0, duration, 1.0 / fs)
    s = np.sin(2 * np.pi * t / 8.0)
    roll = np.where(s > 0, 12.0 * s, 7.0 * s)
    pitch = 2.0 * np.sin(2 * np.pi * t / 5.0)
    heading = (350.0 + 2.0 * t) % 360.0
    return Recording(t, {"roll": roll, "pitch": pitch, "heading": heading})


def motion(duration=40.0, fs=10.0, settle_s=10.0, gnss=False, start_utc=None) -> Recording:
    """Roll/pitch/heading (true) + heave (m, up) + heave rate + settled flag (0 for the first settle_s)."""
    rec = est(duration, fs)
    t = rec.time
    rec.add("heave", 0.8 * np.sin(2 * np.pi * t / 9.0), "m")
    rec.add("heave_rate", 0.8 * 2 * np.pi / 9.0 * np.cos(2 * np.pi * t / 9.0), "m/s")
    rec.add("settled", (t >= settle_s).astype(float), "1")
    if gnss:
        rec.add("sog", np.full(len(t), 5.0), "m/s")
    if start_utc:
        rec.meta["start_utc"] = start_utc
    return rec


def _check_line(s: str) -> None:
    """Our framing + checksum, pynmea2's parse (type known) or its checksum (type not known), length ≤ 82."""
    assert len(s) + 2 <= MAX_SENTENCE_LENGTH
    ps = parse_sentence(s)  # checksum required
    assert ps.checksum_ok
    try:
        pyn = pynmea2.parse(s, check=True)
        if ps.talker != "P":
            assert pyn.sentence_type == ps.formatter
    except pynmea2.SentenceTypeError:
        body = s[1 : s.index("*")]
        assert pynmea2.NMEASentence.checksum(body) == int(s[-2:], 16)


def test_every_sentence_type_validates_and_decodes():
    rec = motion(gnss=True, start_utc="2026-03-05T10:00:00Z")
    card = DeviationCard(1.0, -2.0, 1.5, 0.5, -0.3)
    kinds = set()
    for _, s in nmea_lines(rec, list(SENTENCES), 2.0, heading_ref="true", variation_deg=-3.5, card=card):
        if s.startswith(":"):
            d = parse_tss1(s)
            assert len(s) + 2 == 27 and d["status"] in "UuGg"
            kinds.add("TSS1")
            continue
        _check_line(s)
        decode(s)  # our decoder reads every type we write
        kinds.add(parse_sentence(s).type)
    assert kinds == set(SENTENCES)


def test_sentences_decode_back_with_fixed_deviation():
    rec = est()
    lines = list(nmea_lines(rec, ["HRM", "XDR", "HDG", "THS"], None, deviation_deg=-1.5, variation_deg=3.0))
    assert len(lines) == 4 * len(rec)
    rs = roll_stats(rec.time, rec["roll"])
    by_t: dict[float, dict[str, str]] = {}
    for t, s in lines:
        _check_line(s)
        by_t.setdefault(t, {})[parse_sentence(s).formatter] = s
    i = len(rec) - 1
    last = by_t[float(rec.time[i])]
    hrm = decode(last["HRM"])
    assert hrm["heel"] == pytest.approx(round(rec["roll"][i], 1), abs=1e-9)
    assert hrm["roll_period"] == pytest.approx(round(rs.roll_period[i], 1), abs=1e-9)
    assert hrm["amp_port"] == pytest.approx(round(rs.amp_port[i], 1), abs=1e-9)
    assert last["HRM"].split(",")[5] == "A"
    xdr = decode(last["XDR"])
    assert xdr["roll"] == pytest.approx(round(rec["roll"][i], 1))
    hdg = decode(last["HDG"])
    # heading channel is magnetic: sensor = magnetic − deviation; deviation W 1.5, variation E 3.0
    assert hdg["deviation"] == pytest.approx(-1.5) and hdg["variation"] == pytest.approx(3.0)
    assert last["HDG"].split(",")[3] == "W" and last["HDG"].split(",")[5][0] == "E"
    assert hdg["heading_sensor"] == pytest.approx(round((rec["heading"][i] + 1.5) % 360.0, 1))
    ths = decode(last["THS"])
    assert ths["heading_true"] == pytest.approx(round((rec["heading"][i] + 3.0) % 360.0, 1))
    assert last["THS"].startswith("$IITHS")  # a magnetic heading corrected by variation is not a gyro (HE)


def test_hdg_carries_the_cards_deviation_from_the_solved_inverse():
    card = DeviationCard(1.5, 3.0, -2.0, 0.8, -0.6)
    rec = est(duration=20.0)
    for ref in ("magnetic", "compass"):
        lines = [s for _, s in nmea_lines(rec, ["HDG"], None, heading_ref=ref, card=card, variation_deg=-3.5)]
        for s, h in zip(lines, rec["heading"], strict=True):
            d = decode(s)
            sensor, dev = d["heading_sensor"], d["deviation"]
            if ref == "compass":
                assert sensor == pytest.approx(round(h, 1) % 360.0, abs=1e-9)
                assert dev == pytest.approx(round(float(card.deviation_deg(h)), 1), abs=1e-9)
            else:  # magnetic given: sensor solves ψ + δ(ψ) = magnetic; deviation = δ(ψ) (not −δ(magnetic))
                psi = float(card.compass_from_magnetic(np.array([h]))[0])
                assert abs(((psi + float(card.deviation_deg(psi)) - h + 180) % 360) - 180) < 1e-9
                assert sensor == pytest.approx(round(psi, 1) % 360.0, abs=1e-9)
                assert dev == pytest.approx(round(float(card.deviation_deg(psi)), 1), abs=1e-9)
            assert d["variation"] == pytest.approx(-3.5)
    # the old −δ(magnetic) shortcut is measurably wrong on this card (it would fail the checks above)
    m = np.arange(0.0, 360.0, 1.0)
    exact = card.compass_from_magnetic(m)
    approx = (m - card.deviation_deg(m)) % 360.0
    assert np.max(np.abs((exact - approx + 180) % 360 - 180)) > 0.2  # > the 0.05° print rounding


def test_heading_resolution_refuses_missing_inputs():
    h = np.array([10.0, 20.0])
    with pytest.raises(formats.ImutoolError, match="either"):
        resolve_headings(h, "compass", DeviationCard(), 1.0)
    with pytest.raises(formats.ImutoolError, match="variation"):
        list(nmea_lines(est(duration=2.0), ["THS"], None))
    with pytest.raises(formats.ImutoolError, match="deviation"):
        list(nmea_lines(est(duration=2.0), ["THS"], None, heading_ref="compass", variation_deg=1.0))
    with pytest.raises(formats.ImutoolError, match="unknown sentence"):
        list(nmea_lines(est(duration=2.0), ["GGA"], None))
    with pytest.raises(formats.ImutoolError, match="roll and pitch"):
        list(nmea_lines(Recording(np.arange(5.0), {"heave": np.zeros(5)}), ["TSS1"], None))


def test_talkers_follow_the_heading_source_and_ths_mode_is_honest():
    rec = est(duration=3.0)
    gyro = [s for _, s in nmea_lines(rec, ["THS", "HDT", "ROT"], None, heading_ref="true", heading_source="gyro")]
    assert all(s.startswith(("$HETHS", "$HEHDT", "$HEROT")) for s in gyro)
    mag = [s for _, s in nmea_lines(rec, ["THS", "HDG"], None, variation_deg=2.0)]
    assert {s[:6] for s in mag} == {"$IITHS", "$HCHDG"}
    assert all(s.split(",")[2][0] == "A" for s in mag if "THS" in s)
    rec.meta["scenario"] = "ship-roll"  # simulated → S
    assert all(s.split(",")[2][0] == "S" for _, s in nmea_lines(rec, ["THS"], None, heading_ref="true"))
    rec.channels["heading"][3] = np.nan
    modes = [s.split(",")[2][0] for _, s in nmea_lines(rec, ["THS"], None, heading_ref="true", ths_mode="A")]
    assert modes[3] == "V" and modes[0] == "A"


def test_xdr_ids_signs_and_forced_talkers():
    rec = est(duration=3.0)
    lines = [
        s
        for _, s in nmea_lines(
            rec,
            ["XDR", "THS"],
            None,
            xdr_roll_id="HEEL",
            xdr_pitch_id="TRIM",
            xdr_roll_sign=-1,
            heading_ref="true",
            ths_mode="S",
            talkers={"XDR": "II", "THS": "IN"},
        )
    ]
    xdr = [s for s in lines if "XDR" in s][-1]
    assert xdr.startswith("$IIXDR") and ",HEEL" in xdr and ",TRIM" in xdr
    vals = decode(xdr, xdr_map={"HEEL": "-roll", "TRIM": "pitch"})  # receiver undoes the sign
    assert vals["roll"] == pytest.approx(round(rec["roll"][-1], 1))
    ths = [s for s in lines if "THS" in s][-1]
    assert ths.startswith("$INTHS") and ths.split(",")[2][0] == "S"


def test_rot_from_gyro_and_from_heading():
    rec = est(duration=5.0)
    rec.channels["heading"][0] = 200.0  # an initialisation jump must not come out as a huge rate of turn
    out = list(nmea_lines(rec, ["ROT"], None))
    for t, s in out:
        _check_line(s)
        if t < 1.0 - 1e-9:  # causal 1 s window: not valid before a full window
            assert s.split(",")[2][0] == "V"
        else:
            assert s.split(",")[2][0] == "A"
        if t > 1.1:  # once the window has passed the jump: 2 °/s = 120 °/min, bow to starboard
            assert decode(s)["rot"] == pytest.approx(120.0, abs=0.06)
    g = np.zeros((len(rec), 3))
    g[:, 2] = np.radians(-0.5)
    rec.add("gyro", g, "rad/s")
    assert [decode(s)["rot"] for _, s in nmea_lines(rec, ["ROT"], None)][0] == pytest.approx(-30.0)


def test_pashr_flags_settling_no_gnss_and_utc():
    rec = motion(settle_s=10.0)
    lines = [(t, s) for t, s in nmea_lines(rec, ["PASHR"], None, heading_ref="true")]
    for t, s in lines:
        _check_line(s)
        f = s.split("*")[0].split(",")
        assert f[1] == ""  # no real time in the recording: no UTC (never made up from the recording clock)
        assert f[10] == "0"  # no GNSS channel: no aiding
        if t < 10.0:
            assert f[6] == "" and f[11] == "0"  # settling: heave empty, IMU status 0 (not valid)
        else:
            assert float(f[6]) == pytest.approx(round(0.8 * np.sin(2 * np.pi * t / 9.0), 2), abs=1e-9)
            assert f[11] == "1"
        assert f[2] != "" and f[3] == "T"
    # with GNSS and a real start time: aiding 1 and the UTC of each row
    rec = motion(gnss=True, start_utc="2026-03-05T10:00:00Z")
    (t0, s0), (t1, s1) = list(nmea_lines(rec, ["PASHR"], None, heading_ref="true"))[100:102]
    f = s0.split(",")
    assert f[1] == "100010.000" and f[10] == "1"  # row 100 at 10 Hz = 10 s after 10:00:00
    # the filter's one-sigma channels fill the accuracy fields
    rec.add("roll_std", np.full(len(rec), 0.05), "deg")
    rec.add("heading_std", np.full(len(rec), 0.8), "deg")
    f = next(iter(nmea_lines(rec, ["PASHR"], None, heading_ref="true")))[1].split("*")[0].split(",")
    assert f[7:10] == ["0.050", "", "0.800"]
    # no heading channel: heading and its 'T' both empty (the old writer sent ',,T,')
    rec.remove("heading")
    s = next(iter(nmea_lines(rec, ["PASHR"], None)))[1]
    assert s.split(",")[2] == "" and s.split(",")[3] == ""


def test_tss1_matches_the_published_layout():
    # NovAtel OEM7 TSS1 log example: ":00FFCA -0003F-0325  0319" (horizontal acc 00, vertical acc FFCA,
    # heave −3 cm, status F, roll −3.25°, pitch +3.19°)
    d = parse_tss1(":00FFCA -0003F-0325  0319\r\n")
    assert d["heave"] == pytest.approx(-0.03) and d["roll"] == pytest.approx(-3.25)
    assert d["pitch"] == pytest.approx(3.19) and d["status"] == "F"
    assert d["vertical_accel"] == pytest.approx(-54 * 0.000625)
    assert tss1_frame(-0.03, -3.25, 3.19, "F", 0.0, -54 * 0.000625) == ":00FFCA -0003F-0325  0319"
    # field positions (1-based after ':'): XX 2-3, AAAA 4-7, space 8, M 9, HHHH 10-13, Q 14, M 15, RRRR 16-19,
    # space 20, M 21, PPPP 22-25
    f = tss1_frame(1.234, 12.346, -4.5, "u", 2.0, -9.81)
    assert len(f) == 25 and f[0] == ":" and f[7] == " " and f[19] == " "
    assert f[8:13] == " 0123" and f[13] == "u" and f[14:19] == " 1235" and f[20:25] == "-0450"
    assert int(f[1:3], 16) == round(2.0 / 0.0383) and int(f[3:7], 16) == (round(-9.81 / 0.000625) & 0xFFFF)
    with pytest.raises(formats.ImutoolError, match="range"):
        tss1_frame(120.0, 0.0, 0.0)


def test_tss1_stream_flags_and_heave_sign():
    rec = motion(settle_s=10.0)
    up = [(t, parse_tss1(s)) for t, s in nmea_lines(rec, ["TSS1"], None)]
    down = [parse_tss1(s) for _, s in nmea_lines(rec, ["TSS1"], None, heave_positive="down")]
    for (t, a), b in zip(up, down, strict=True):
        assert a["status"] == ("U" if t >= 10.0 else "u")  # unaided (no GNSS); lower case while settling
        assert a["heave"] == pytest.approx(round(0.8 * np.sin(2 * np.pi * t / 9.0), 2), abs=1e-9)
        assert b["heave"] == pytest.approx(-a["heave"], abs=1e-9)
        assert a["roll"] == pytest.approx(round(rec["roll"][int(round(t * 10))], 2), abs=1e-9)
    # vertical acceleration from the heave rate: amplitude 0.8 (2π/9)² ≈ 0.39 m/s²
    va = np.array([d["vertical_accel"] for _, d in up])
    assert 0.35 < np.max(np.abs(va)) < 0.42
    g = motion(gnss=True)
    assert {parse_tss1(s)["status"] for _, s in nmea_lines(g, ["TSS1"], None)} == {"g", "G"}
    # a recording that already holds heave positive down is converted, not flipped twice
    rec.meta["heave_positive"] = "down"
    same = [parse_tss1(s)["heave"] for _, s in nmea_lines(rec, ["TSS1"], None, heave_positive="down")]
    assert same == [d["heave"] for _, d in up]


def test_rate_is_planned_against_the_baud():
    rec = motion()
    nb = row_bytes(rec, ["HRM", "XDR", "THS"], heading_ref="true")
    assert 100 < nb < 200
    p = plan_rate(nb, 4800, None, 100.0)
    assert p.chosen and p.bytes_per_s <= 0.9 * 480 and p.rate_hz in (1.0, 2.0)
    assert plan_rate(nb, 38400, None, 10.0).rate_hz == 10.0  # never above the input rate
    with pytest.raises(formats.ImutoolError, match=r"does not fit.*--rate [12] or less.*--baud"):
        plan_rate(nb, 4800, 10.0, 100.0)
    with pytest.raises(formats.ImutoolError, match="0.1 Hz"):
        plan_rate(10_000, 300, None, 10.0)


def test_cli_file_header_rate_and_stamp_roundtrip(tmp_path):
    src = tmp_path / "est.csv"
    formats.write(est(), src)
    out = tmp_path / "out.nmea"
    r = CliRunner().invoke(
        cli, ["nmea", str(src), "-o", str(out), "--sentences", "HRM,XDR", "--rate", "2", "--time-prefix", "--json"]
    )
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["sentences"] == {"HRM": 120, "XDR": 120} and s["rate_hz"] == 2.0 and not s["rate_chosen"]
    text = out.read_bytes().decode("ascii")
    head = [ln for ln in text.split("\r\n") if ln.startswith("#")]
    assert any("heave: m, positive UP" in h for h in head) and any("UTC: not known" in h for h in head)
    assert text.count("\r\n") == 240 + len(head)
    back = formats.read(out)  # the '#' header is skipped by our reader
    assert back.meta["time_source"] == "stamp"
    ref = est()
    idx = np.searchsorted(ref.time, back.time)
    assert np.max(np.abs(back["roll"] - ref["roll"][idx])) <= 0.05 + 1e-9
    assert np.allclose(np.diff(back.time), 0.5)
    r = CliRunner().invoke(cli, ["nmea", str(src), "-o", str(tmp_path / "x.nmea"), "--sentences", "THS"])
    assert r.exit_code != 0 and "variation" in str(r.exception)
    assert not (tmp_path / "x.nmea").exists()
    # too fast for 4800 Bd: refused with the rate that fits; without --rate one is chosen
    r = CliRunner().invoke(
        cli, ["nmea", str(src), "-o", str(tmp_path / "y.nmea"), "--sentences", "HRM,XDR", "--rate", "10"]
    )
    assert r.exit_code != 0 and "does not fit" in str(r.exception) and not (tmp_path / "y.nmea").exists()
    r = CliRunner().invoke(cli, ["nmea", str(src), "-o", str(tmp_path / "z.nmea"), "--sentences", "HRM,XDR", "--json"])
    s = json.loads(r.stdout)
    assert s["rate_chosen"] and s["rate_hz"] <= 5.0 and s["bytes_per_s"] <= 432


def test_cli_hdg_uses_the_calibration_card(tmp_path):
    from calibration.file import update_calibration

    card = DeviationCard(2.0, -1.0, 3.0, 0.0, 0.5)
    cal = tmp_path / "cal.toml"
    update_calibration(str(cal), "deviation", card.to_section(), False)
    src = tmp_path / "est.csv"
    formats.write(est(duration=10.0, fs=2.0), src)
    out = tmp_path / "hdg.nmea"
    r = CliRunner().invoke(
        cli,
        [
            "nmea",
            str(src),
            "-o",
            str(out),
            "--sentences",
            "HDG",
            "--calibration",
            str(cal),
            "--heading-ref",
            "compass",
            "--variation",
            "-2.5",
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    lines = [ln for ln in out.read_text().splitlines() if ln.startswith("$")]
    assert any(f"card {cal}" in ln for ln in out.read_text().splitlines() if ln.startswith("#"))
    ref = est(duration=10.0, fs=2.0)
    for ln, h in zip(lines, ref["heading"], strict=True):
        d = decode(ln)
        assert d["deviation"] == pytest.approx(round(float(card.deviation_deg(h)), 1), abs=1e-9)
        assert d["variation"] == pytest.approx(-2.5)
    r = CliRunner().invoke(
        cli,
        [
            "nmea",
            str(src),
            "-o",
            str(tmp_path / "h2.nmea"),
            "--sentences",
            "HDG",
            "--calibration",
            str(cal),
            "--deviation",
            "1",
        ],
    )
    assert r.exit_code != 0 and "one of them" in str(r.exception)


def test_write_log_and_heave_nmea_cli(tmp_path):
    rec = motion(settle_s=10.0)
    info = write_log(
        rec,
        str(tmp_path / "m.nmea"),
        ["PASHR", "TSS1"],
        baud=9600,
        source="test",
        heading_ref="true",
        heave_positive="down",
    )
    text = (tmp_path / "m.nmea").read_text()
    assert "# heave: m, positive DOWN" in text and info["sentences"]["TSS1"] == info["sentences"]["PASHR"]
    for ln in text.splitlines():
        if ln.startswith("$"):
            _check_line(ln)
        elif ln.startswith(":"):
            parse_tss1(ln)
    # heave --nmea on a short simulated sea: same library writer, flags and sign in the header and CSV
    sea = tmp_path / "sea.csv"
    r = CliRunner().invoke(cli, ["simulate", "sea-state", "-o", str(sea), "--set", "duration=120"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(
        cli,
        [
            "heave",
            str(sea),
            "-o",
            str(tmp_path / "h.csv"),
            "--nmea",
            str(tmp_path / "h.nmea"),
            "--heave-positive",
            "down",
            "--order",
            "4",
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["heave_positive"] == "down" and s["nmea"]["sentences"]["PASHR"] > 0
    h = formats.read(tmp_path / "h.csv")
    assert h.meta["heave_positive"] == "down" and "positive DOWN" in h.meta["heave"]
    lines = (tmp_path / "h.nmea").read_text().splitlines()
    assert "# heave: m, positive DOWN (--heave-positive down; TSS1 defines + up)" in lines
    pashr = [ln for ln in lines if ln.startswith("$PASHR")]
    settled = h["settled"]
    rows = np.searchsorted(h.time, h.time[0] + np.arange(len(pashr)) / s["nmea"]["rate_hz"] - 1e-9)
    for ln, i in zip(pashr, rows, strict=True):
        _check_line(ln)
        f = ln.split("*")[0].split(",")
        assert f[1] == "" and f[10] == "0"  # simulated clock: no UTC; no GNSS: no aiding
        if settled[i] < 0.5:
            assert f[6] == "" and f[11] == "0"
        else:  # CSV and NMEA agree on the (flipped) sign
            assert float(f[6]) == pytest.approx(round(float(h["heave"][i]), 2), abs=0.0051) and f[11] == "1"


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
        r = CliRunner().invoke(
            cli,
            [
                "nmea",
                str(src),
                "--serial",
                port,
                "--baud",
                "38400",
                "--no-realtime",
                "--sentences",
                "HRM,XDR",
                "--json",
            ],
        )
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
    assert len(lines) == 80  # no '#' header on the line
    for s in lines:
        _check_line(s)
