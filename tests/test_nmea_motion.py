"""The motion sensors' own sentences (formats/nmea/motion.py) and Kongsberg's binary attitude frames
(formats/nmea/em3000.py): each on a real line from the vendor's public documentation or a public capture (the
source is named at each line), or on a fixture written from the documented layout where no real line was found;
signs checked against cases whose answer is known; empty fields, bad checksums and unknown sentences counted.
"""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pynmea2
import pytest
from click.testing import CliRunner

from formats import ImutoolError
from formats.nmea import (
    MotionOptions,
    NmeaFieldError,
    NmeaUnsupportedError,
    checksum,
    checksum_value,
    decode,
    decode_fast,
    decode_tss1,
    em3000_frame,
    euler_roll_to_tss,
    read_em3000,
    read_nmea,
    scan_frames,
    sentence_summary,
    tss1_frame,
    tss_roll_to_euler,
)


def _s(body: str) -> str:
    """A fixture sentence (written from a documented layout) with its checksum."""
    return f"${body}*{checksum(body)}"


# Real lines, checksums as published (verified in test_real_lines_carry_valid_checksums)
SEAPATH_20 = "$PSXN,20,0,0,0,0*3B"  # Seapath 320+ on R/V Oscar Elton Sette, NOAA NCEI archive 0086548
SEAPATH_23 = "$PSXN,23,1.28,1.93,104.68,-0.24*18"  # same capture
SEAPATH_23B = "$PSXN,23,0.30,-0.97,298.57,0.13*1B"  # pynmea2 types/proprietary/sxn.py sample
PHTRO_SBG = "$PHTRO,0.03,P,0.22,T*56"  # SBG sbgECom doc/nmeaMessages.md
PHTRO_GONMEA = "$PHTRO,10.37,P,177.62,T*65"  # go-nmea phtro.go (citing the iXblue INS interface library)
PHLIN_SBG = "$PHLIN,0.03,0.22,-0.15*68"  # SBG doc: the published checksum is WRONG (the body XORs to 4B)
PHINF_SBG = "$PHINF,08030027*7B"  # SBG doc
PHOCT_SBG = (  # SBG doc
    "$PHOCT,01,000201.000,E,00,356.592,E,+000.225,E,+00.039,E,+00.023,T,+00.023,+00.016,+00.003,+00.002,"
    "-00.001,+00.000,+0001.96*04"
)
PSAT_NOAA = "$PSAT,HPR,235410.50,89.58,3.35,,N*01"  # NOAA PSL, R/V Ron Brown CLIVAR 2010 heading log
PRDID_SBG = "$PRDID,-012.39,+002.14,366.91*7A"  # SBG doc
AVR_TILT = "$PTNL,AVR,212405.20,+52.1531,Yaw,-0.0806,Tilt,,,12.575,3,1.4,16*39"  # Trimble receiver help
AVR_ROLL = "$PTNL,AVR,212604.30,+52.1800,Yaw,,,-0.0807,Roll,12.579,3,1.4,16*21"  # Trimble receiver help
PASHR_NOVATEL = "$PASHR,163029.000,158.09,T,-0.30,+0.31,+0.01,0.029,0.029,0.059,1,1*3B"  # NovAtel OEM7 PASHR
PASHR_POSMV = "$PASHR,183944.821,74.52,T,-1.63,1.51,0.14,0.020,0.020,0.012,2,1*05"  # UHDAS POS MV diagnostics
PASHR_SBG = "$PASHR,123816.80,312.95,T,-000.83,-000.42,-000.01,0.234,0.224,0.298,1,0*09"  # SBG doc (+ down)
PASHR_SBG_EMPTY = "$PASHR,,,T,,,,,,,0,1*21"  # SBG doc: invalid solution
PSBGA_SBG = "$PSBGA,155513.685,V,13.684,-63.139,269.130,0.024,0.006,0.196,p,v,v*74"  # SBG doc
PSBGB_SBG = (  # SBG doc (its '-0.017' printed with a non-breaking hyphen; the checksum is over ASCII '-')
    "$PSBGB,1,000344.000,0,3.529,-12.821,6.122,0.101,0.098,10.117,0,0,0.004,0.050,2,0.772,0.004,-0.017,"
    "1.043,4.476,0.171,866.025,0,*53"
)
TSS1_NOVATEL = ":00FFCA -0003F-0325  0319"  # NovAtel OEM7 TSS1 log example

REAL = [
    SEAPATH_20,
    SEAPATH_23,
    SEAPATH_23B,
    PHTRO_SBG,
    PHTRO_GONMEA,
    PHINF_SBG,
    PHOCT_SBG,
    PSAT_NOAA,
    PRDID_SBG,
    AVR_TILT,
    AVR_ROLL,
    PASHR_NOVATEL,
    PASHR_POSMV,
    PASHR_SBG,
    PASHR_SBG_EMPTY,
    PSBGA_SBG,
    PSBGB_SBG,
]


def test_real_lines_carry_valid_checksums():
    for line in REAL:
        body, cs = line[1:].split("*")
        assert checksum(body) == cs and checksum_value(body.encode()) == int(cs, 16), line
    body, cs = PHLIN_SBG[1:].split("*")
    assert cs == "68" and checksum(body) == "4B"  # a documentation line with a wrong checksum


# -- Kongsberg Seapath / MRU -------------------------------------------------------------------------------------
def test_psxn23_heave_down_becomes_heave_up():
    d = decode(SEAPATH_23)
    assert d == {"roll": 1.28, "pitch": 1.93, "heading_true": 104.68, "heave": 0.24}  # -0.24 m down = 0.24 m up
    p = pynmea2.parse(SEAPATH_23)  # the layout is pynmea2's SXN23
    assert (d["roll"], d["pitch"], d["heading_true"], d["heave"]) == (p.roll, p.pitch, p.head, -p.heave)
    assert decode(SEAPATH_23B)["heave"] == -0.13 and decode(SEAPATH_23B)["pitch"] == -0.97
    # heave may be empty: the other values still come, heave is absent (NaN in a recording)
    assert decode(_s("PSXN,23,0.30,-0.97,298.57,")) == {"roll": 0.3, "pitch": -0.97, "heading_true": 298.57}


def test_psxn20_22_24():
    assert decode(SEAPATH_20) == {
        "psxn_quality_horizontal": 0.0,
        "psxn_quality_height": 0.0,
        "psxn_quality_heading": 0.0,
        "psxn_quality_roll_pitch": 0.0,
    }
    assert decode(_s("PSXN,20,0,1,0,2"))["psxn_quality_roll_pitch"] == 2.0  # 2 = invalid, kept as a channel
    with pytest.raises(NmeaFieldError):
        decode(_s("PSXN,20,0,0,0,7"))  # quality is 0, 1 or 2
    assert decode(_s("PSXN,22,0.12,-0.03")) == {"psxn_gyro_calibration": 0.12, "psxn_gyro_offset": -0.03}
    d = decode(_s("PSXN,24,1.50,-0.20,0.75,0.40"))  # rates deg/s, vertical velocity + down
    assert d == {"roll_rate": 1.5, "pitch_rate": -0.2, "yaw_rate": 0.75, "heave_rate": -0.4}
    with pytest.raises(NmeaUnsupportedError):
        decode("$PSXN,26,0,44.5000,0.7800,-0.9000,NRP*6D")  # pynmea2 sample of a message imutool does not read


# -- iXblue / Exail ------------------------------------------------------------------------------------------------
def test_phtro_sign_letters():
    assert decode(PHTRO_SBG) == {"pitch": -0.03, "roll": 0.22}  # P = bow down, T = port up (starboard down)
    assert decode(PHTRO_GONMEA) == {"pitch": -10.37, "roll": 177.62}
    assert decode(_s("PHTRO,2.50,M,4.00,B")) == {"pitch": 2.5, "roll": -4.0}  # M = bow up, B = port down
    with pytest.raises(NmeaFieldError):
        decode(_s("PHTRO,2.50,X,4.00,B"))
    with pytest.raises(NmeaFieldError):
        decode(_s("PHTRO,-2.50,M,4.00,B"))  # the letter gives the sign: a signed magnitude is contradictory


def test_phlin_phinf_phoct():
    fixed = PHLIN_SBG[:-2] + checksum(PHLIN_SBG[1:-3])  # the SBG line with its checksum corrected
    assert decode(fixed) == {"surge": 0.03, "sway": -0.22, "heave": -0.15}  # sway + port → + starboard
    assert decode(PHINF_SBG) == {"phinf_status": float(0x08030027)}
    d = decode(PHOCT_SBG)  # heading/roll/pitch status E (invalid): dropped; heave status T
    assert "heading_true" not in d and "roll" not in d and "pitch" not in d and "rot" not in d
    assert d["phoct_roll_status"] == ord("E") and d["phoct_heave_status"] == ord("T")
    assert d["heave"] == 0.023 and d["heave_primary"] == 0.023 and d["surge"] == 0.016
    assert d["sway"] == -0.003 and d["heave_rate"] == 0.002 and d["surge_rate"] == -0.001
    assert d["sway_rate"] == 0.0 and math.copysign(1.0, d["sway_rate"]) == 1.0  # no negative zero
    ok = PHOCT_SBG.split("*")[0][1:].replace(",E,", ",T,").replace("+00.039", "+02.500")
    d = decode(_s(ok))
    assert d["pitch"] == -2.5  # PHOCT pitch is + bow DOWN
    assert d["roll"] == 0.225 and d["heading_true"] == 356.592 and d["rot"] == 1.96
    with pytest.raises(NmeaUnsupportedError):
        decode(_s(ok.replace("PHOCT,01,", "PHOCT,02,")))


# -- Hemisphere, Teledyne RDI, Trimble ----------------------------------------------------------------------------
def test_psat_hpr_roll_may_be_empty():
    assert decode(PSAT_NOAA) == {"heading_true": 89.58, "pitch": 3.35, "psat_heading_source": float(ord("N"))}
    d = decode(_s("PSAT,HPR,235410.50,89.58,,-1.25,G"))  # pitch empty, roll given, gyro heading
    assert d == {"heading_true": 89.58, "roll": -1.25, "psat_heading_source": float(ord("G"))}


def test_prdid_pitch_first():
    d = decode(PRDID_SBG)
    assert d["pitch"] == -12.39 and d["roll"] == 2.14  # pitch is the FIRST field
    assert d["heading_true"] == pytest.approx(6.91)  # the documented example's 366.91 wraps into [0, 360)
    p = pynmea2.parse(PRDID_SBG)
    assert (d["pitch"], d["roll"]) == (p.pitch, p.roll)
    tss = decode(_s("PRDID,10.00,19.68,0.00"), options=MotionOptions(tss_roll={"PRDID"}))
    assert tss["roll"] == pytest.approx(20.0, abs=0.01)  # a POS MV set to TSS angles: converted to Euler roll


def test_ptnl_avr_tilt_and_roll():
    d = decode(AVR_TILT)
    assert d == {"heading_true": 52.1531, "pitch": -0.0806, "avr_quality": 3.0, "avr_baseline": 12.575}
    d = decode(AVR_ROLL)
    assert d == {"heading_true": 52.18, "roll": -0.0807, "avr_quality": 3.0, "avr_baseline": 12.579}
    p = pynmea2.parse(AVR_ROLL)
    assert float(p.roll_angle) == d["roll"] and p.roll == "Roll"
    no_fix = decode(_s("PTNL,AVR,212405.20,+52.1531,Yaw,-0.0806,Tilt,,,12.575,0,1.4,16"))
    assert no_fix == {"avr_quality": 0.0, "avr_baseline": 12.575}  # quality 0: no angles


# -- $PASHR -------------------------------------------------------------------------------------------------------
def test_pashr_both_forms_and_heave_sign_setting():
    d = decode(PASHR_NOVATEL)  # 11 fields
    p = pynmea2.parse(PASHR_NOVATEL)
    assert (d["roll"], d["pitch"], d["heading_true"]) == (p.roll, p.pitch, p.true_heading) == (-0.3, 0.31, 158.09)
    assert d["heave"] == 0.01 and d["pashr_imu_status"] == 1.0 and d["heading_std"] == 0.059
    down = MotionOptions(pashr_heave_positive="down")
    assert decode(PASHR_NOVATEL, options=down)["heave"] == -0.01
    assert decode(PASHR_SBG, options=down)["heave"] == 0.01  # SBG: heave + down; -0.01 m down = 0.01 m up
    ten = PASHR_NOVATEL.split("*")[0][1:].rsplit(",", 1)[0]  # NovAtel before firmware 7.03: no INS status
    d10 = decode(_s(ten))
    assert "pashr_imu_status" not in d10 and d10["pashr_aiding"] == 1.0 and d10["heave"] == 0.01
    trimble = decode(_s("PASHR,123816.80,312.95,T,-0.83,-0.42,,0.234,0.224,0.298,4,3"))  # heave reserved
    assert "heave" not in trimble and trimble["roll"] == -0.83
    assert decode(PASHR_SBG_EMPTY) == {"pashr_aiding": 0.0, "pashr_imu_status": 1.0}
    with pytest.raises(ImutoolError):
        MotionOptions(pashr_heave_positive="sideways")


# -- SBG Systems ------------------------------------------------------------------------------------------------
def test_psbga_psbgb():
    d = decode(PSBGA_SBG)
    assert d["roll"] == 13.684 and d["pitch"] == -63.139 and d["heading_true"] == 269.13
    assert d["roll_std"] == 0.024 and d["psbga_solution"] == ord("p") and d["psbga_heading_status"] == ord("v")
    bad = decode(_s("PSBGA,155513.685,V,13.684,-63.139,269.130,0.024,0.006,0.196,p,i,v"))
    assert "roll" not in bad and "pitch" not in bad and bad["heading_true"] == 269.13  # i = invalid: dropped
    d = decode(PSBGB_SBG)  # roll/pitch and heading status 0 (invalid): dropped; heave status 2 (valid)
    assert "roll" not in d and "heading_true" not in d and d["psbgb_roll_pitch_status"] == 0.0
    assert d["heave"] == -0.004  # + down in the sentence
    assert d["roll_rate"] == 0.772 and d["yaw_rate"] == -0.017 and "body_vel_x" not in d  # velocity status 0
    ok = decode(_s(PSBGB_SBG.split("*")[0][1:].replace(",0,0,0.004,", ",1,1,0.004,")))
    assert ok["roll"] == 3.529 and ok["pitch"] == -12.821 and ok["heading_true"] == 6.122


# -- Furuno -------------------------------------------------------------------------------------------------------
def test_pfec_gpatt_gphve():
    # fixtures from the layout in Furuno's SC-120 manual and Kongsberg's third-party datagram pages
    assert decode(_s("PFEC,GPatt,123.4,+1.5,-2.3")) == {"heading_true": 123.4, "pitch": 1.5, "roll": -2.3}
    assert decode(_s("PFEC,GPhve,0.123,A")) == {"heave": 0.123, "pfec_heave_status": float(ord("A"))}
    assert decode(_s("PFEC,GPhve,0.123,V")) == {"pfec_heave_status": float(ord("V"))}
    with pytest.raises(NmeaUnsupportedError):
        decode("$PFEC,AIcmd,0,35,A,01062011,130711*05")  # a real Saab R4 line (gpsd test log): not attitude


# -- TSS1 ----------------------------------------------------------------------------------------------------------
def test_tss1_roll_converted_to_euler():
    d = decode_tss1(TSS1_NOVATEL)
    assert d["heave"] == -0.03 and d["pitch"] == 3.19 and d["tss1_status"] == ord("F") and d["settled"] == 1.0
    assert d["roll"] == pytest.approx(
        math.degrees(math.asin(math.sin(math.radians(-3.25)) / math.cos(math.radians(3.19))))
    )
    # known answer: φ = 20°, θ = 10° → TSS roll asin(sin 20°·cos 10°) = 19.6835°; back to 20° (0.01° frame step)
    r_tss = euler_roll_to_tss(20.0, 10.0)
    assert r_tss == pytest.approx(19.6835, abs=1e-4)
    assert decode_tss1(tss1_frame(0.5, r_tss, 10.0))["roll"] == pytest.approx(20.0, abs=0.012)
    as_sent = decode_tss1(tss1_frame(0.5, r_tss, 10.0), MotionOptions(tss_roll=()))
    assert as_sent["roll"] == pytest.approx(19.68, abs=1e-9)
    for phi, theta in ((0.0, 0.0), (-35.0, 12.0), (5.0, -40.0)):
        assert tss_roll_to_euler(euler_roll_to_tss(phi, theta), theta) == pytest.approx(phi, abs=1e-9)


# -- fast path and pynmea2 layouts ---------------------------------------------------------------------------------
def test_fast_path_agrees_on_every_real_line():
    for line in REAL:
        assert decode_fast(line) == decode(line), line


# -- whole logs ----------------------------------------------------------------------------------------------------
def test_log_empty_fields_nan_bad_checksum_counted_conventions(tmp_path):
    p = tmp_path / "ship.nmea"
    bad23 = SEAPATH_23[:-2] + "00"
    p.write_text(
        "\n".join(
            [
                "1700000000.00 " + SEAPATH_20,
                "1700000000.10 " + SEAPATH_23,
                "1700000001.00 " + _s("PSXN,23,0.30,-0.97,298.57,"),  # heave empty
                "1700000001.50 " + PSAT_NOAA,  # roll empty
                "1700000002.00 " + bad23,
                "1700000002.50 " + PHLIN_SBG,  # the documentation's own bad checksum
                "1700000003.00 " + TSS1_NOVATEL,
                "1700000003.50 $PSXN,26,0,44.5000,0.7800,-0.9000,NRP*6D",
                "1700000004.00 $PTNTHTM,14223,N,169,N,-43,N,13641,2454*15",
            ]
        )
        + "\n"
    )
    rec = read_nmea(p)
    assert rec.meta["time_source"] == "stamp"
    heave = rec["heave"]
    assert heave[1] == pytest.approx(0.24) and np.isnan(heave[2])  # empty heave field → NaN
    assert rec["heading"][3] == 89.58 and np.isnan(rec["roll"][3])  # PSAT roll empty → NaN
    assert rec["heave"][4] == -0.03 and rec["tss1_status"][4] == ord("F")  # TSS1 read as input
    s = rec.meta["sentences"]
    assert s["PSXN,23"]["parsed"] == 2 and s["PSXN,23"]["bad_checksum"] == 1  # counted under its own name
    assert s["PHLIN"]["bad_checksum"] == 1 and s["TSS1"]["parsed"] == 1
    assert s["PSXN,26"]["unsupported"] == 1 and s["PTNTHTM"]["unsupported"] == 1
    summary = sentence_summary(rec.meta)
    assert summary["not_read"] == {"PSXN,26": 1, "PTNTHTM": 1}
    assert summary["bad"] == {"PHLIN": 1, "PSXN,23": 1}
    conv = rec.meta["conventions"]
    assert "heave + DOWN" in conv["PSXN,23"] and "TSS roll" in conv["TSS1"] and "PSAT,HPR" in conv
    assert rec.meta["status_codes"]["tss1_status"].startswith("U unaided")


def test_info_names_and_counts_unknown_sentences(tmp_path):
    from imutool.cli import cli

    p = tmp_path / "seapath.nmea"
    p.write_text(
        "\n".join([SEAPATH_20, SEAPATH_23, SEAPATH_23B, "$PSXN,26,0,44.5000,0.7800,-0.9000,NRP*6D", PHLIN_SBG]) + "\n"
    )
    r = CliRunner().invoke(cli, ["info", str(p)], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert "NMEA sentences read: PSXN,23 2, PSXN,20 1" in r.output
    assert "NMEA sentences not read (imutool does not decode them): PSXN,26 1" in r.output
    assert "NMEA sentences bad (checksum or format): PHLIN 1" in r.output
    r = CliRunner().invoke(cli, ["info", str(p), "--json"], catch_exceptions=False)
    s = json.loads(r.stdout)["nmea_sentences"]
    assert s["read"] == {"PSXN,23": 2, "PSXN,20": 1} and s["not_read"] == {"PSXN,26": 1} and s["bad"] == {"PHLIN": 1}


def test_profile_sets_pashr_heave_sign(tmp_path):
    log = tmp_path / "sbg.nmea"
    log.write_text(PASHR_SBG + "\n")
    assert read_nmea(log)["heave"][0] == -0.01  # default: + up, as sent
    prof = tmp_path / "sbg.toml"
    prof.write_text('name = "SBG Ellipse"\n[nmea]\npashr_heave_positive = "down"\n')
    rec = read_nmea(log, profile=prof)
    assert rec["heave"][0] == 0.01 and rec.meta["motion_options"]["pashr_heave_positive"] == "down"
    assert "negated" in rec.meta["conventions"]["PASHR"]
    assert read_nmea(log, profile=prof, pashr_heave_positive="up")["heave"][0] == -0.01  # the argument wins
    prof.write_text('[nmea]\npashr_heave_positiv = "down"\n')
    with pytest.raises(ImutoolError, match="unknown"):
        read_nmea(log, profile=prof)


def test_utc_anchors_from_psbga(tmp_path):
    log = tmp_path / "psbga.nmea"
    body = PSBGA_SBG.split("*")[0][1:]
    log.write_text("\n".join([PSBGA_SBG, _s(body.replace("155513.685", "155513.785"))]) + "\n")
    rec = read_nmea(log)
    assert rec.meta["time_source"] == "nmea"
    assert rec.time[0] == pytest.approx(15 * 3600 + 55 * 60 + 13.685) and np.diff(rec.time)[0] == pytest.approx(0.1)


# -- Kongsberg EM3000 binary frames --------------------------------------------------------------------------------
def test_em3000_frame_layout_known_bytes():
    # written by hand from the layout: status 90h, sync 90h, roll -3.25° (-325 = FEBBh), pitch +1.50° (150 = 0096h),
    # heave -0.12 m (-12 = FFF4h), heading 359.99° (35999 = 8C9Fh, read unsigned)
    frame = bytes([0x90, 0x90, 0xBB, 0xFE, 0x96, 0x00, 0xF4, 0xFF, 0x9F, 0x8C])
    assert em3000_frame(-3.25, 1.5, -0.12, 359.99) == frame
    frames, skipped = scan_frames(frame)
    assert skipped == 0 and frames.shape == (1, 10)


def test_read_em3000_file(tmp_path):
    good = [em3000_frame(-3.25 + 0.01 * i, 1.5, -0.12, 10.0 * i) for i in range(30)]
    reduced = em3000_frame(2.0, 1.0, 0.5, 90.0, status=0x93)
    invalid = em3000_frame(2.0, 1.0, 0.5, 90.0, status=0x9A)
    em1000 = em3000_frame(4.0, -1.0, 0.25, 180.0, status=0x00)
    data = b"\x13\x37\x01" + b"".join(good[:10]) + b"\xff\xff" + b"".join(good[10:]) + reduced + invalid + em1000
    p = tmp_path / "att.bin"
    p.write_bytes(data)
    rec = read_em3000(p, rate_hz=100.0, start_utc="2024-05-01T12:00:00Z")
    assert len(rec) == 33 and rec.meta["bytes_skipped"] == 5  # the cut start and the noise are counted
    assert rec["roll"][0] == pytest.approx(-3.25) and rec["heave"][0] == pytest.approx(-0.12)  # heave + up
    assert rec["heading"][29] == pytest.approx(290.0) and rec["pitch"][5] == pytest.approx(1.5)
    assert rec.time[1] - rec.time[0] == pytest.approx(0.01) and rec.time[0] == pytest.approx(1714564800.0)
    assert rec["em_status"][30] == 0x93 and rec["roll"][30] == pytest.approx(2.0)  # reduced accuracy: kept
    assert np.isnan(rec["roll"][31]) and np.isnan(rec["heave"][31])  # 9Ah: not valid → NaN
    assert rec["roll"][32] == pytest.approx(4.0)  # EM1000: sync byte 00h, no status
    assert rec.meta["status"] == {
        "valid_full_accuracy": 31,
        "valid_reduced_accuracy": 1,
        "not_valid": 1,
        "sensor_error": 0,
    }
    tss = read_em3000(p, rate_hz=100.0, roll_convention="tss")
    assert tss["roll"][0] == pytest.approx(tss_roll_to_euler(-3.25, 1.5))
    out_of_range = struct.pack("<BBhhhH", 0x90, 0x90, 18000, 0, 1000, 36000)
    p2 = tmp_path / "oor.bin"
    p2.write_bytes(out_of_range * 3)
    r2 = read_em3000(p2, rate_hz=1.0)
    assert np.isnan(r2["roll"]).all() and np.isnan(r2["heave"]).all() and np.isnan(r2["heading"]).all()
    with pytest.raises(ImutoolError, match="rate"):
        read_em3000(p, rate_hz=None)  # the frames carry no time
    with pytest.raises(ImutoolError, match="read_em3000"):
        read_nmea(p)  # the NMEA reader names the right reader


def test_tss1_shaped_noise_is_not_a_frame(tmp_path):
    p = tmp_path / "noise.nmea"
    # a lone ':' (found by the fuzz test), a 25-character line that is not a frame, then one real sentence
    p.write_text(":\n:00FFCA -0003X-0325  0319\n" + SEAPATH_23 + "\n")
    rec = read_nmea(p)
    assert len(rec) == 1 and rec.meta["lines"]["not_nmea"] == 1
    assert rec.meta["sentences"]["TSS1"]["malformed"] == 1  # shaped like TSS1, counted as a bad TSS1 frame
