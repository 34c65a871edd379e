"""CLI shell: `imutool --version`, `info` (text and --json), `plot` (PNG/PDF), error conventions."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from formats import Recording
from formats.csv import write_csv
from imutool.cli import cli, main


def _run(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


@pytest.fixture
def messy_csv(tmp_path):
    """100 Hz, a 0.5 s gap, 2 duplicate timestamps (one conflicting), 3 NaN rows, 1 malformed row."""
    t = np.concatenate([np.arange(0, 2, 0.01), np.arange(2.5, 4, 0.01)])
    t = np.insert(t, [10, 20], [t[9], t[19]])
    rng = np.random.default_rng(1)
    rec = Recording(t, meta={"sensor": "unit-test"})
    g = rng.standard_normal((t.size, 3)) * 0.1
    g[10] = g[9]  # identical duplicate row
    g[[40, 41, 42], 1] = np.nan
    rec.add("gyro", g)
    mv = (np.arange(t.size) % 2).astype(float)
    mv[10] = mv[9]
    rec.add("movement", mv)
    p = tmp_path / "messy.csv"
    write_csv(rec, str(p))
    with open(p, "a") as f:
        f.write("4.1,1,2\n")
    return str(p)


def test_version_and_help():
    r = _run("--version")
    assert r.exit_code == 0 and "imutool" in r.output
    for cmd in ("info", "plot"):
        r = _run(cmd, "--help")
        assert r.exit_code == 0 and "Example: imutool" in r.output


def test_info_text_and_json(messy_csv):
    r = _run("info", messy_csv)
    assert r.exit_code == 0, r.output
    assert "gaps:      1" in r.output
    assert "duplicate timestamps: 2 (1 with different data)" in r.output
    assert "rows with NaN: 3 (gyro 3)" in r.output
    assert "malformed rows skipped: 1" in r.output
    assert "[deg/s]" in r.output and "movement" in r.output  # rates in degrees at the user surface
    r = _run("info", messy_csv, "--json")
    s = json.loads(r.stdout)
    assert s["rows"] == 352 and s["rows_after_validation"] == 350
    assert s["duplicate_timestamps"] == 2 and s["rows_with_nan"] == 3
    assert s["gaps"]["count"] == 1 and s["gaps"]["first"][0]["length_s"] == pytest.approx(0.51)
    assert s["rate_hz"] == pytest.approx(100.0, rel=1e-6)
    assert s["step_s"]["min"] == pytest.approx(0.01) and s["step_s"]["max"] == pytest.approx(0.51)
    g = s["channels"]["gyro"]
    assert g["unit"] == "deg/s" and g["unit_in_file"] == "rad/s"
    assert g["columns"] == ["gyro_x", "gyro_y", "gyro_z"] and len(g["mean"]) == 3
    assert s["metadata"]["sensor"] == "unit-test"
    assert s["skipped_rows"] == 1 and "line" in s["skipped_rows_first"][0]
    assert any("dropped 2 rows" in a for a in s["validation_actions"])


def test_info_backwards_is_reported_not_fatal(tmp_path):
    p = tmp_path / "back.csv"
    p.write_text("time,temp\n0,1\n1,2\n0.5,3\n2,4\n")
    r = _run("info", str(p), "--json")
    s = json.loads(r.stdout)
    assert s["backwards_steps"] == 1
    assert any("backwards" in a for a in s["validation_actions"])


def test_info_foreign_csv_prints_mapping(tmp_path):
    p = tmp_path / "f.csv"
    p.write_text(
        "Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),acc_x_g,acc_y_g,acc_z_g\n"
        "0,180,0,0,0,0,1\n0.01,180,0,0,0,0,1\n"
    )
    r = _run("info", str(p))
    assert "column mapping (inferred):" in r.output
    assert "Gyroscope X (deg/s)->gyro_x[deg/s]" in r.output and "acc_z_g->accel_z[g]" in r.output
    s = json.loads(_run("info", str(p), "--json").output)
    assert s["channels"]["gyro"]["max"][0] == pytest.approx(180.0)  # read as rad/s, shown in deg/s
    assert s["channels"]["accel"]["mean"][2] == pytest.approx(9.80665)
    r = _run("info", str(p), "--columns", "acc_z_g=accel_z:m/s^2", "--json")
    assert json.loads(r.stdout)["channels"]["accel"]["mean"][2] == pytest.approx(1.0)


def test_info_real_fusion(shared):
    s = json.loads(_run("info", str(shared("fusion", "sensor_data.csv")), "--json").stdout)  # stderr: z-up warning
    assert s["rows"] == 13514
    assert s["channels"]["gyro"]["unit"] == "deg/s" and s["channels"]["mag"]["unit"] == "uT"
    assert s["column_mapping"]["origin"] == "inferred"
    assert 95 < s["rate_hz"] < 105


def test_errors_are_one_line(tmp_path, capsys):
    p = tmp_path / "bad.csv"
    p.write_text("1,2,3\n")
    with pytest.raises(SystemExit) as e:
        main(["info", str(p)])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "numbers, not column names" in err and "Traceback" not in err


def test_plot_png_and_pdf(messy_csv, tmp_path):
    out = tmp_path / "p.png"
    r = _run("plot", messy_csv, "gyro", "move", "-o", str(out), "--json")
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["channels"] == ["gyro", "movement"]
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pdf = tmp_path / "p.pdf"
    r = _run("plot", messy_csv, "gyro", "-o", str(pdf), "--start", "1", "--end", "3", "-q")
    assert r.exit_code == 0 and pdf.read_bytes()[:5] == b"%PDF-"
    assert not [f for f in tmp_path.iterdir() if f.name.endswith(".tmp")]


def test_plot_decimates_long_series(tmp_path):
    from imutool.plot import envelope

    n = 200_000
    t = np.arange(n) / 1000.0
    y = np.sin(t)[:, None]
    y[123_457, 0] = 50.0  # a spike must survive decimation
    t2, y2 = envelope(t, y, n // 1000)
    assert len(t2) <= 2100 and y2.max() == 50.0 and y2.min() == pytest.approx(-1.0, abs=1e-3)
    p = tmp_path / "long.csv"
    rec = Recording(t)
    rec.add("heave", y[:, 0], unit="m")
    write_csv(rec, str(p))
    s = json.loads(_run("plot", str(p), "heave", "-o", str(tmp_path / "h.png"), "--max-points", "500", "--json").output)
    assert s["rows"] == n and s["points_per_line"] <= 700  # ≈ --max-points (row count estimated)


def test_plot_errors(messy_csv, tmp_path):
    with pytest.raises(Exception, match="no channel matches 'nothing'"):
        _run("plot", messy_csv, "nothing", "-o", str(tmp_path / "x.png"))
    with pytest.raises(Exception, match="must end in"):
        _run("plot", messy_csv, "gyro", "-o", str(tmp_path / "x.jpg"))


def test_plot_refuses_a_channel_without_values(tmp_path, capsys):
    """A channel whose every value is NaN is said in one line (exit 2, nothing written) instead of empty axes;
    beside a channel with values it is left out and named in the summary."""
    t = np.arange(200) / 100.0
    rec = Recording(t)
    rec.add("gyro", np.full((200, 3), 0.1))
    rec.add("heave", np.full(200, np.nan), unit="m")
    p, out = tmp_path / "nan.csv", tmp_path / "h.png"
    write_csv(rec, str(p))
    with pytest.raises(SystemExit) as ei:
        main(["plot", str(p), "heave", "-o", str(out)])
    err = capsys.readouterr().err
    assert ei.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert "every value of heave is NaN or missing: nothing to draw" in err and not out.exists()
    s = json.loads(_run("plot", str(p), "gyro", "heave", "-o", str(out), "--json").output)
    assert s["channels"] == ["gyro"] and s["not_drawn"] == ["heave"] and out.exists()
