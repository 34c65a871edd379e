"""The certification reports on many-clock logs (issue 48 items 2 and 3).

A Seapath-like NMEA log — 1 Hz ``$PSXN,23`` (roll, pitch, heading, heave) interleaved with GGA, RMC, VTG, ZDA
and HDT at their own rates — is one table whose rows are the union of the sentences' times. The reports take
each channel on its own samples: every figure of ``report inclinometer`` and ``report heading`` on such a pair
of logs must equal the same report on roll-only / heading-only CSVs of the same samples.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import formats
from formats import Recording
from formats.nmea import checksum
from imutool.cli import cli
from imutool.report.route import run_heading_report, run_inclinometer_report
from imutool.roll import MOTION_TABLE, roll_cycles
from imutool.sim.programmes import irregular_roll

N_S = 624  # seconds of log: 624 one-second PSXN,23 samples per unit
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _line(body: str) -> str:
    return f"${body}*{checksum(body)}"


def _lat_lon(k: int) -> tuple[str, str, str, str]:
    """A ship steaming slowly north-east off Bergen (ddmm.mmmm, N/E)."""
    lat = 60.0 + 23.5 / 60 + 1e-5 * k
    lon = 5.0 + 18.2 / 60 + 1e-5 * k
    la = f"{int(lat):02d}{(lat - int(lat)) * 60:07.4f}"
    lo = f"{int(lon):03d}{(lon - int(lon)) * 60:07.4f}"
    return la, "N", lo, "E"


def seapath_log(
    path: Path,
    seed: int,
    offset_deg: float = 0.0,
    noise_deg: float = 0.02,
    t0_s: int = 12 * 3600,
    psxn_heading: bool = True,
) -> dict[str, np.ndarray]:
    """Write a Seapath-like log (real sentence formats, real checksums) and return the truth it carries.

    Per second: ZDA every 5 s, GGA, then PSXN,23 (roll + port up = + starboard down, pitch + bow up, true
    heading, heave + down), HDT at 2 Hz around it, VTG, RMC. Times come from the UTC fields (ZDA/GGA/RMC); the
    other sentences sit by their position between them, as on a real logger without time stamps.
    ``psxn_heading`` False leaves PSXN,23's heading field empty (the heading then comes from HDT only, on rows
    where there is no roll).
    """
    rng = np.random.default_rng(seed)
    _, roll = irregular_roll(float(N_S), 1.0, tp_s=9.0, std_deg=1.2, seed=7)
    k = np.arange(N_S)
    heading = 218.45 + 1.6 * np.sin(2 * np.pi * k / 400.0) + 0.2 * np.sin(2 * np.pi * k / 37.0)
    pitch = 0.4 * np.sin(2 * np.pi * k / 6.5 + 0.3)
    heave = 0.6 * np.sin(2 * np.pi * k / 8.0)
    roll_u = np.round(roll + offset_deg + rng.normal(0, noise_deg, N_S), 2)
    head_u = np.round((heading + offset_deg + rng.normal(0, noise_deg, N_S)) % 360.0, 2)
    lines = []
    for i in range(N_S):
        s = t0_s + i
        hh, mm, ss = s // 3600, (s // 60) % 60, s % 60
        utc = f"{hh:02d}{mm:02d}{ss:02d}.00"
        la, ns, lo, ew = _lat_lon(i)
        hd = f"{head_u[i]:.2f}" if psxn_heading else ""
        if i % 5 == 0:
            lines.append(_line(f"GPZDA,{utc},06,12,2026,00,00"))
        lines.append(_line(f"GPGGA,{utc},{la},{ns},{lo},{ew},2,12,0.8,12.3,M,46.1,M,1.0,0120"))
        lines.append(_line(f"GPHDT,{(head_u[i] - 0.03) % 360:.2f},T"))
        lines.append(
            _line(f"PSXN,23,{roll_u[i]:.2f},{pitch[i]:.2f},{hd},{-heave[i]:.2f}")  # heave + down
        )
        lines.append(_line(f"GPVTG,{head_u[i]:.1f},T,,M,8.2,N,15.2,K,D"))
        lines.append(_line(f"GPHDT,{(head_u[i] + 0.02) % 360:.2f},T"))
        lines.append(_line(f"GPRMC,{utc},A,{la},{ns},{lo},{ew},8.2,{head_u[i]:.1f},061226,1.0,W,D"))
    path.write_text("\r\n".join(lines) + "\r\n")
    return {"roll": roll_u, "heading": head_u}


def _approx_equal(a, b, path="") -> None:
    """Recursive equality of two JSON figures, floats within float noise."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {sorted(set(a) ^ set(b))}"
        for k in a:
            _approx_equal(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: {len(a)} vs {len(b) if isinstance(b, list) else b}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _approx_equal(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert b == pytest.approx(a, rel=1e-9, abs=1e-9), f"{path}: {a} vs {b}"
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


def _figures(ev: dict) -> dict:
    """Every figure of an evidence JSON that does not depend on the file's type: the items (but the interface
    item, which inspects an NMEA capture's sentences), the alignment and the warnings."""
    return {
        "items": [it for it in ev["items"] if it["id"] != "interface"],
        "alignment": ev["alignment"],
        "warnings": ev["warnings"],
    }


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """SEAP_A (reference) and SEAP_B (DUT: 0.15° offset, its own noise) and their readings."""
    d = tmp_path_factory.mktemp("seapath")
    a, b = d / "SEAP_A.log", d / "SEAP_B.log"
    seapath_log(a, seed=1)
    seapath_log(b, seed=2, offset_deg=0.15)
    return d, a, b


def _roll_csv(log: Path, out: Path) -> tuple[np.ndarray, np.ndarray]:
    """A roll-only imutool CSV of the log's roll samples (its own PSXN,23 rows), and those samples."""
    t, v = formats.read(str(log)).series("roll")
    formats.write(Recording(t.copy(), {"roll": v.copy()}, {"roll": "deg"}), str(out))
    back = formats.read(str(out))
    assert np.array_equal(back.time, t) and np.array_equal(back["roll"], v, equal_nan=True)  # exact round trip
    return t, v


def test_seapath_log_is_many_clock(logs):
    _, a, _ = logs
    rec = formats.read(str(a))
    assert rec.multi_clock and len(rec) > 4 * N_S  # the table has ~5 rows per roll sample
    t, roll = rec.series("roll")
    assert t.size == N_S and np.isfinite(roll).all()
    assert np.median(np.diff(t)) == pytest.approx(1.0, abs=0.01)


def test_inclinometer_on_logs_equals_roll_only_csvs(logs):
    d, a, b = logs
    res = run_inclinometer_report(b, a, d / "incl_log.pdf")
    ev = res.data["evidence"]
    tb, _ = _roll_csv(b, d / "B_roll.csv")
    ta, ra = _roll_csv(a, d / "A_roll.csv")
    ev_csv = run_inclinometer_report(d / "B_roll.csv", d / "A_roll.csv", d / "incl_csv.pdf").data["evidence"]
    _approx_equal(_figures(ev_csv), _figures(ev))
    it = {i["id"]: i for i in ev["items"]}
    # durations from the samples used: 624 one-second samples stand for 624 s (main: 101 s)
    assert it["dynamic_heel"]["stats"]["n"] == N_S
    assert it["dynamic_heel"]["duration_s"] == pytest.approx(N_S, abs=1.5)
    # each input's own rate: 1 Hz for a 1 Hz roll (main: the table's 6 Hz), its stream named, the file's listed
    for k in ("dut", "reference"):
        inp = ev["inputs"][k]
        assert inp["rate_hz"] == pytest.approx(1.0, abs=0.01) and inp["rows"] == N_S
        assert inp["stream"] == "PSXN,23" and inp["streams"]["PSXN,23"]["samples"] == N_S
        assert inp["file_rows"] > 4 * N_S and len(inp["streams"]) == 4
    assert "PSXN,23" in ev["conventions"]["time_base"]
    # periods judged are roll.py's on the reference's own roll samples
    cyc = roll_cycles(ta, ra, 0.5, crest_band_deg=0.05, **MOTION_TABLE)
    own = cyc.period_s[np.isfinite(cyc.period_s)]
    rows = it["roll_period"]["rows"]
    assert len(rows) >= 20
    for r in rows:
        assert np.min(np.abs(own - r["reference_s"])) < 1e-9, r
    assert abs(ev["alignment"]["linear_fit"]["offset_deg"] - 0.15) < 0.01
    assert ev["alignment"]["overlap_s"] == pytest.approx(tb[-1] - tb[0], abs=0.6)


def test_inclinometer_plots_and_pdf_on_logs(logs):
    d, a, b = logs
    from imutool.report.inclinometer import inclinometer_evidence

    _, plots = inclinometer_evidence(formats.read(str(b)), formats.read(str(a)))
    assert plots["t"].size == N_S and np.isfinite(plots["ref"]).all()  # a line, not points between NaN rows
    assert np.isfinite(plots["err"]).mean() > 0.99 and np.isfinite(plots["tol"]).all()
    if shutil.which("pdftoppm") is None or shutil.which("pdftotext") is None:
        pytest.skip("pdftoppm/pdftotext (poppler-utils) not installed: the PDF page is not rendered")
    from PIL import Image

    pdf = d / "incl_pdf.pdf"
    run_inclinometer_report(b, a, pdf)
    text = subprocess.run(["pdftotext", str(pdf), "-"], capture_output=True, text=True, check=True).stdout
    page = 1 + text.split("\f").index(next(p for p in text.split("\f") if "Heel: DUT vs reference" in p))
    subprocess.run(
        ["pdftoppm", "-f", str(page), "-l", str(page), "-r", "50", "-png", str(pdf), str(d / "heel")], check=True
    )
    img = np.asarray(Image.open(next(d.glob("heel*.png"))).convert("RGB")).astype(int)
    h = img.shape[0]
    mid = img[h // 3 : 2 * h // 3]  # the error panel
    r, g, bl = mid[..., 0], mid[..., 1], mid[..., 2]
    red = int(((r > 150) & (g < 110) & (bl < 110)).sum())  # the DUT − reference trace (C3)
    band = int(((abs(r - 202) < 20) & (abs(g - 231) < 15) & (abs(bl - 202) < 20)).sum())  # tolerance fill
    assert red > 200, f"no error trace on the heel page ({red} red pixels; the legend alone has ~10)"
    assert band > 15000, f"tolerance panel not filled ({band} pixels)"


def _heading_csv(log: Path, out: Path) -> None:
    """A single-clock CSV of the log's heading samples (its own rows), with the roll interpolated linearly from
    its own samples onto them (what the report states it does with the platform roll)."""
    rec = formats.read(str(log))
    t, h = rec.series("heading")
    tr, r = rec.series("roll")
    roll = np.interp(t, tr, r, left=np.nan, right=np.nan)
    formats.write(Recording(t.copy(), {"heading": h.copy(), "roll": roll}, {"heading": "deg", "roll": "deg"}), str(out))


@pytest.mark.parametrize("psxn_heading", [True, False], ids=["psxn+hdt", "hdt-only"])
def test_heading_on_logs_equals_heading_only_csvs(tmp_path, psxn_heading):
    a, b = tmp_path / "SEAP_A.log", tmp_path / "SEAP_B.log"
    seapath_log(a, seed=1, psxn_heading=psxn_heading)
    seapath_log(b, seed=2, offset_deg=0.15, psxn_heading=psxn_heading)
    res = run_heading_report(b, a, tmp_path / "head_log.pdf")
    ev = res.data["evidence"]
    _heading_csv(a, tmp_path / "A.csv")
    _heading_csv(b, tmp_path / "B.csv")
    ev_csv = run_heading_report(tmp_path / "B.csv", tmp_path / "A.csv", tmp_path / "head_csv.pdf").data["evidence"]
    _approx_equal(_figures(ev_csv), _figures(ev))
    # a ship holding 216.6-220.3°: no phantom turn (main: "82.8 s of turning faster than 20 °/s")
    assert not any("turning faster" in w for w in ev["warnings"]), ev["warnings"]
    it = {i["id"]: i for i in ev["items"]}
    assert it["follow_up_10"]["status"] == "not tested" and it["follow_up_20"]["status"] == "not tested"
    # roll range on the roll's own samples (main: only rows where the heading and the roll coincide)
    rec = formats.read(str(a))
    _, roll = rec.series("roll")
    true_range = float(np.ptp(roll))
    dyn = it["dynamic"]
    assert 0.85 * true_range <= dyn["roll_range_deg"] <= true_range + 1e-9, (dyn["roll_range_deg"], true_range)
    # the dynamic item's time: the heading samples at constant heading, ~ the whole log (main: ~100 s)
    assert 560.0 < dyn["duration_s"] < N_S
    th, _ = rec.series("heading")
    inp = ev["inputs"]["reference"]
    assert inp["rows"] == th.size and inp["rate_hz"] == pytest.approx(1.0 / np.median(np.diff(th)), rel=1e-6)
    assert inp["stream"] == rec.stream_of("heading")


def test_heading_rate_of_turn_ignores_missing_headings():
    """A single-clock heading with a missing stretch: the smoothing leaves it out, never takes it as 0°."""
    from imutool.report.heading import heading_evidence

    t = np.arange(0.0, 300.0, 0.1)
    h = 218.0 + 0.5 * np.sin(2 * np.pi * t / 120.0)
    h_ref = h.copy()
    h_ref[1000:1050] = np.nan  # 5 s without a heading
    ref = Recording(t, {"heading": h_ref}, {"heading": "deg"})
    dut = Recording(t.copy(), {"heading": h + 0.1}, {"heading": "deg"})
    ev, plots = heading_evidence(dut, ref)
    rot = plots["rot"]
    assert np.nanmax(np.abs(rot)) < 0.1  # main: ±2000 °/s at the edges of the gap
    assert not any("turning faster" in w for w in ev["warnings"])


def test_cli_inclinometer_on_logs(logs):
    d, a, b = logs
    out = d / "cli.pdf"
    r = CliRunner().invoke(cli, ["report", "inclinometer", str(b), "--reference", str(a), "-o", str(out), "--json"])
    assert r.exit_code in (0, 1), r.output
    summary = json.loads(r.stdout[r.stdout.index("{") :])
    lib = run_inclinometer_report(b, a, d / "lib.pdf").summary
    _approx_equal(lib["items"], summary["items"])
    assert summary["items"]["dynamic_heel"]["n"] == N_S
    ev = json.loads(out.with_suffix(".json").read_text())
    assert ev["inputs"]["dut"]["rate_hz"] == pytest.approx(1.0, abs=0.01)


def test_gofree_xdr_heel_is_not_silent(tmp_path):
    """The gofree-merrimac log: XDR heel (a constant 0.5°) among HDG, GPS and AIS. Against a copy of itself
    with the heel 0.2° higher: the heel's own 141 samples, no invented lag, and every gap said."""
    src = DATA / "nmea_signalk" / "gofree-merrimac.log"
    if not src.exists():
        pytest.skip(f"{src} not present (../shared/data)")
    lines = src.read_text(encoding="latin-1").splitlines()
    out = []
    for ln in lines:
        if ln.startswith("$IIXDR") and ",A,0.5,D,HEEL" in ln:
            body = ln[1 : ln.index("*")].replace(",A,0.5,D,HEEL", ",A,0.7,D,HEEL")
            ln = _line(body)
        out.append(ln)
    ref = tmp_path / "gofree_ref.log"
    ref.write_text("\r\n".join(out) + "\r\n", encoding="latin-1")
    ev = run_inclinometer_report(src, ref, tmp_path / "g.pdf").data["evidence"]
    assert ev["inputs"]["dut"]["rows"] == 141 and ev["inputs"]["dut"]["stream"] == "XDR:roll"
    assert ev["inputs"]["dut"]["rate_hz"] == pytest.approx(1.0, abs=0.02)
    assert ev["alignment"]["lag_s"] == 0.0 and ev["alignment"]["lag_measurable"] is False
    assert any("does not move" in w or "stays within" in w for w in ev["warnings"])
    assert not any("search limit" in w for w in ev["warnings"])
    it = {i["id"]: i for i in ev["items"]}
    assert it["static_heel"]["stats"]["max_abs"] == pytest.approx(0.2, abs=1e-9)
    for i in ev["items"]:
        assert i["reason"], i["id"]  # no item without its reason


def test_lateral_acceleration_from_its_own_stream():
    """A reference whose lateral acceleration is a stream of its own (5 Hz beside a 10 Hz heel): taken from its
    own samples onto the heel's times, the same as a single-clock reference carrying those values."""
    from formats.recording import join_streams
    from imutool.report.inclinometer import inclinometer_evidence
    from imutool.sim.programmes import inclinometer_test

    short = {"steps": (0.0, 5.0, -5.0, 0.0), "hold_s": 15.0, "dynamic": ((8.0, 10.0, 10.0, 5),), "long_s": 0.0}
    dut, ref, _ = inclinometer_test(lat_accel_ms2=1.0, lat_accel_s=40.0, accel_coupling=0.5, **short)
    heel = Recording(ref.time.copy(), {"roll": ref["roll"].copy()}, {"roll": "deg"})
    acc = Recording(ref.time[::2] + 0.05, {"lat_accel": ref["lat_accel"][::2].copy()}, {"lat_accel": "m/s^2"})
    many = join_streams([heel, acc], ["heel", "acc"])
    assert many.multi_clock and len(many) == len(ref) + len(acc)
    single = Recording(
        ref.time.copy(),
        {"roll": ref["roll"].copy(), "lat_accel": np.interp(ref.time, acc.time, acc["lat_accel"], np.nan, np.nan)},
        {"roll": "deg", "lat_accel": "m/s^2"},
    )
    ev_many, _ = inclinometer_evidence(dut, many)
    ev_single, _ = inclinometer_evidence(dut, single)
    _approx_equal(_figures(ev_single), _figures(ev_many))
    it = {i["id"]: i for i in ev_many["items"]}
    assert it["lateral_acceleration"]["status"] != "not tested"
    assert it["lateral_acceleration"]["duration_s"] > 10.0
