"""`imutool nmea`'s heading reference (issue 48, item 10): a recording that says its heading is true (an NMEA log's
HDT/THS/PASHR heading, a filter steered by a true heading, meta heading_reference) is taken as true; magnetic
only when it says magnetic or says nothing; the choice and its reason are in the summary."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from formats import Recording
from imutool.cli import cli, main
from imutool.nmea_out import heading_reference, nmea_lines


def _log_from_real_lines(shared, tmp_path):
    """A log of real $PASHR/$GPHDT/$GPGGA/$GPRMC lines (Hemisphere-style, nmea_gpsd/rst39.log): heading true."""
    src = shared("nmea_gpsd", "rst39.log")
    p = tmp_path / "att.log"
    p.write_text("\n".join(ln for ln in src.read_text().splitlines() if ln.startswith("$")) + "\n")
    return p


def test_nmea_log_heading_is_true_by_default(shared, tmp_path, capsys):
    src = _log_from_real_lines(shared, tmp_path)
    out = tmp_path / "out.nmea"
    r = CliRunner().invoke(cli, ["nmea", str(src), "-o", str(out), "--sentences", "THS", "--json"])
    assert r.exit_code == 0, r.output  # was: exit 2, "the magnetic heading needs the variation"
    s = json.loads(r.output)
    assert s["heading_reference"]["reference"] == "true" and "NMEA" in s["heading_reference"]["why"]
    rec = formats.read(src)
    t_in, h_in = rec.series("heading")
    ths = [ln for ln in out.read_text().splitlines() if ln.startswith("$") and "THS" in ln[:7]]
    first = float(ths[0].split(",")[1])
    assert first == pytest.approx(round(float(h_in[0]), 2), abs=0.051)  # the true heading passed through, unchanged
    with pytest.raises(SystemExit) as e:
        main(["nmea", str(src), "-o", str(tmp_path / "hdg.nmea"), "--sentences", "HDG"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "variation" in err  # true → magnetic needs the variation: said, not guessed


def test_text_summary_names_the_choice(shared, tmp_path):
    src = _log_from_real_lines(shared, tmp_path)
    r = CliRunner().invoke(cli, ["nmea", str(src), "-o", str(tmp_path / "o.nmea"), "--sentences", "HDT"])
    assert r.exit_code == 0, r.output
    assert "heading input true: an NMEA log" in r.output


def _est(**meta) -> Recording:
    t = np.arange(0, 5, 0.5)
    rec = Recording(t, {"roll": np.zeros(t.size), "pitch": np.zeros(t.size), "heading": np.full(t.size, 90.0)})
    rec.meta.update(meta)
    return rec


@pytest.mark.parametrize(
    "meta,expect",
    [
        ({}, "magnetic"),
        ({"heading_reference": "true"}, "true"),
        ({"heading_reference": "magnetic"}, "magnetic"),
        ({"heading_source": "heading_true (external; magnetometer not used)"}, "true"),
        ({"heading_source": "magnetometer"}, "magnetic"),
        ({"format": "nmea0183"}, "true"),
        ({"signs": "roll + starboard down, pitch + bow up, heave + up (m), heading deg true, rot deg/min"}, "true"),
    ],
)
def test_heading_reference_from_what_the_recording_says(meta, expect):
    ref, why = heading_reference(_est(**meta))
    assert ref == expect and why
    if not meta:
        assert "assumed" in why
    assert heading_reference(_est(**meta), "compass")[0] == "compass"  # the user's word wins


def test_true_recording_gives_ths_without_variation():
    lines = [s for _, s in nmea_lines(_est(heading_reference="true"), ["THS"], None)]
    assert lines and all(s.startswith("$IITHS,90.0,") for s in lines)
    with pytest.raises(formats.ImutoolError, match="variation"):
        list(nmea_lines(_est(), ["THS"], None))  # nothing said: magnetic, and THS then needs the variation
