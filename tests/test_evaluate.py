"""Evaluation metrics: wrapped heading errors, lag search, SNR (paper eq. 20), BROAD quaternion metrics."""

import numpy as np
from click.testing import CliRunner
from conftest import run_main

import formats
from formats import Recording
from formats.frames import euler_to_quat
from imutool.metrics import evaluate_angle, quat_errors, snr_db


def _cli(capsys, *args: str) -> tuple[int, str]:
    """imutool's entry point in-process: (exit status, stdout when 0 else stderr)."""
    code, out, err = run_main(args, capsys)
    return code, out if not code else err


def test_heading_wrap_and_lag():
    t = np.arange(0, 60, 0.01)
    ref = (355 + 10 * np.sin(2 * np.pi * t / 10)) % 360
    est = (355 + 10 * np.sin(2 * np.pi * (t - 0.12) / 10)) % 360
    s = evaluate_angle(t, est, t, ref, wrap=True, max_lag_s=0.5)
    assert s["max_abs"] < 1.0
    assert abs(s["lag_s"] - 0.12) < 0.01 and s["rmse_lag_removed"] < 0.02


def test_snr_definition():
    s = np.ones(100)
    assert abs(snr_db(s, s + 0.1) - 20.0) < 1e-9


def test_broad_metric_split():
    q_ref = euler_to_quat(np.radians(20.0), np.radians(-10.0), np.radians(100.0))
    yaw = euler_to_quat(0.0, 0.0, np.radians(2.0))
    from formats.frames import quat_multiply

    q_est = quat_multiply(yaw, q_ref)  # a pure heading error of 2° in the world frame
    tot, hd, inc = (np.degrees(x) for x in quat_errors(q_est[None], q_ref[None]))
    assert abs(tot[0] - 2.0) < 1e-9 and abs(hd[0] - 2.0) < 1e-9 and inc[0] < 1e-4  # acos near 1: float precision


def test_evaluate_missing_heave_module_is_one_line(tmp_path):
    from imutool.cli import cli

    rec = Recording(np.arange(5.0), {"roll": np.zeros(5), "ref_roll": np.ones(5)})
    p = tmp_path / "e.csv"
    formats.write(rec, p)
    r = CliRunner().invoke(cli, ["evaluate", str(p), "--json"])
    assert r.exit_code == 0 and '"rmse": 1.0' in r.output


def _mocap(tmp_path, t0=0.0, frame_offset_deg=-90.0):
    """An estimate (roll/pitch/heading + q) and a motion-capture reference holding only a quaternion whose frame's
    x axis is ``frame_offset_deg`` off north; the estimate has a constant 0.2° heading error."""
    t = t0 + np.arange(0, 60, 0.1)
    s = t - t0
    roll, pitch, hdg = (
        5 * np.sin(2 * np.pi * s / 8),
        2 * np.sin(2 * np.pi * s / 6),
        30 + 10 * np.sin(2 * np.pi * s / 30),
    )
    est = Recording(t.copy())
    for n, v in (("roll", roll), ("pitch", pitch), ("heading", (hdg + 0.2) % 360)):
        est.add(n, v, "deg")
    est.add("q", euler_to_quat(np.radians(roll), np.radians(pitch), np.radians(hdg + 0.2)))
    ref = Recording(t.copy())
    ref.add("q", euler_to_quat(np.radians(roll), np.radians(pitch), np.radians((hdg + frame_offset_deg) % 360)))
    paths = (tmp_path / "est.csv", tmp_path / "mocap.csv")
    formats.write(est, paths[0])
    formats.write(ref, paths[1])
    return paths


def test_reference_with_only_a_quaternion_and_align_heading(tmp_path):
    from imutool.evaluation import run_evaluate

    est, mocap = _mocap(tmp_path)
    plain = run_evaluate(est, mocap).summary  # roll/pitch from the reference's quaternion; heading 90° off
    assert plain["angles"]["roll"]["rmse"] < 1e-6 and plain["angles"]["pitch"]["rmse"] < 1e-6
    assert abs(plain["angles"]["heading"]["mae"] - 90.2) < 1e-3
    assert any("derived from ref_q" in n for n in plain["derived"])
    auto = run_evaluate(est, mocap, align_heading="auto").summary  # the offset found and reported
    assert abs(auto["align_heading"]["offset_deg"] - 90.2) < 1e-3 and auto["align_heading"]["resultant_length"] > 0.999
    assert auto["angles"]["heading"]["rmse"] < 1e-3 and auto["quaternion"]["heading"]["rmse"] < 1e-3
    given = run_evaluate(est, mocap, align_heading=90).summary  # a given offset: the 0.2° estimate error remains
    assert (
        abs(given["angles"]["heading"]["mae"] - 0.2) < 1e-6 and abs(given["quaternion"]["total"]["rmse"] - 0.2) < 1e-3
    )
    assert given["align_heading"]["how"].startswith("given")


def test_evaluate_cli_is_the_route_and_prints_utc(tmp_path, capsys):
    import json

    from imutool.cli import main

    def run(*args: str) -> int:
        try:
            main(list(args))
        except SystemExit as e:
            return int(e.code or 0)
        return 0

    est, mocap = _mocap(tmp_path, t0=1406851200.0)  # Unix times: the recording has a date (2014-08-01)
    png = str(tmp_path / "e.png")
    assert run("evaluate", str(est), "--reference", str(mocap), "--align-heading", "auto", "--plot", png) == 0
    out = capsys.readouterr().out
    assert "heading alignment: +90.200°" in out and "compared: 00:00:00.0 … 00:00:59.9 UTC (2014-08-01)" in out
    assert run("evaluate", str(est), "--reference", str(mocap), "--align-heading", "auto", "--json") == 0
    s = json.loads(capsys.readouterr().out)
    assert s["span"]["start_utc"] == "2014-08-01T00:00:00.000Z" and s["span"]["start_s"] == 1406851200.0
    assert (tmp_path / "e.png").stat().st_size > 0
    assert run("evaluate", str(est), "--align-heading", "north") == 2
    assert "--align-heading" in capsys.readouterr().err


def test_reference_loading_options(tmp_path, capsys):
    """A reference file as it comes (a logger's ms time column under a names row and a units row; its heading in a
    file of its own on a clock 2 s ahead): read with the reference's options, stated in the summary."""
    import json

    from imutool.evaluation import run_evaluate

    def run(*args: str) -> tuple[int, str]:
        return _cli(capsys, *args)

    t = np.arange(0.0, 30.0, 0.1)
    roll, pitch, hdg = 10 * np.sin(t), 3 * np.cos(t), (40 + 5 * t) % 360
    est = tmp_path / "est.csv"
    est.write_text(
        "time,roll,pitch,heading\n"
        + "".join(f"{a:.1f},{b + 0.5},{c},{d}\n" for a, b, c, d in zip(t, roll, pitch, hdg, strict=True))
    )
    ref = tmp_path / "logger.csv"
    ref.write_text(
        "Packet time,Roll,Pitch\nms,deg,deg\n"
        + "".join(f"{1000 * a:.0f},{b},{c}\n" for a, b, c in zip(t, roll, pitch, strict=True))
    )
    gyro = tmp_path / "gyro.csv"
    gyro.write_text("time,heading\n" + "".join(f"{a + 2:.1f},{(d - 1.0) % 360}\n" for a, d in zip(t, hdg, strict=True)))
    args = ["evaluate", str(est), "--reference", str(ref), "--ref-time-column", "Packet time:ms"]
    args += ["--ref-header-rows", "2", "--ref-with", str(gyro), "--ref-with-offset", "-2", "--json"]
    code, out = run(*args)
    assert code == 0, out
    s = json.loads(out)
    assert abs(s["angles"]["roll"]["rmse"] - 0.5) < 1e-9 and s["angles"]["pitch"]["rmse"] < 1e-9
    assert abs(s["angles"]["heading"]["rmse"] - 1.0) < 1e-6  # merged onto the reference's times, 2 s back
    ld = s["reference_loading"]
    assert ld["options"] == {
        "--ref-time-column": "Packet time:ms",
        "--ref-header-rows": 2,
        "--ref-with": [str(gyro)],
        "--ref-with-offset": [-2.0],
    }
    assert ld["merged"] == [{"input": str(gyro), "channels": ["heading"], "offset_s": -2.0}] and not ld["dated"]
    assert [v["input"] for v in s["validation"]] == [str(est), str(ref)]
    # the same through the library route; without the options the reference is read as before
    lib = run_evaluate(est, ref, ref_time_column="Packet time:ms", ref_header_rows=2).summary
    assert abs(lib["angles"]["roll"]["rmse"] - 0.5) < 1e-9 and "heading" not in lib["angles"]
    assert "reference_loading" not in run_evaluate(est, est).summary
    # errors name the reference's flags
    code, err = run("evaluate", str(est), "--reference", str(ref), "--ref-header-rows", "2", "--ref-with-offset", "1")
    assert (
        code == 2 and "give the sample rate with --ref-rate HZ, or name the time column with --ref-time-column" in err
    )
    code, err = run(*args[:6], "--ref-header-rows", "2", "--ref-with-offset", "1")
    assert code == 2 and "--ref-with-offset is the clock offset of a --ref-with FILE" in err
    code, err = run("evaluate", str(est), "--ref-rate", "10")
    assert code == 2 and "--ref-rate: say how to read a reference file; give the file with --reference" in err


def test_reference_column_mapping(tmp_path, capsys):
    """A reference whose roll and pitch have foreign names (a ship's log: Time_s, HeelDeg, TrimDeg) mapped with
    --ref-columns (or --ref-profile), the estimate's own names untouched; without it nothing is compared."""
    import json

    from imutool.evaluation import run_evaluate

    def run(*args: str) -> tuple[int, str]:
        return _cli(capsys, *args)

    t = np.arange(0.0, 30.0, 0.1)
    roll, pitch = 10 * np.sin(t), 3 * np.cos(t)
    est = tmp_path / "est.csv"
    est.write_text(
        "time,roll,pitch\n" + "".join(f"{a:.1f},{b + 0.5},{c - 0.2}\n" for a, b, c in zip(t, roll, pitch, strict=True))
    )
    ref = tmp_path / "shiplog.csv"
    ref.write_text(
        "Time_s,HeelDeg,TrimDeg\n" + "".join(f"{a:.1f},{b},{c}\n" for a, b, c in zip(t, roll, pitch, strict=True))
    )
    mapping = "HeelDeg=roll:deg,TrimDeg=pitch:deg"
    code, err = run("evaluate", str(est), "--reference", str(ref))
    assert code == 2 and "nothing to compare" in err
    code, out = run("evaluate", str(est), "--reference", str(ref), "--ref-columns", mapping, "--json")
    assert code == 0, out
    s = json.loads(out)
    assert abs(s["angles"]["roll"]["rmse"] - 0.5) < 1e-9 and abs(s["angles"]["pitch"]["rmse"] - 0.2) < 1e-9
    assert s["reference_loading"]["options"] == {"--ref-columns": mapping}
    profile = tmp_path / "shiplog.toml"
    profile.write_text('[columns]\nHeelDeg = { to = "roll", unit = "deg" }\nTrimDeg = { to = "pitch", unit = "deg" }\n')
    lib = run_evaluate(est, ref, ref_profile=str(profile)).summary
    assert abs(lib["angles"]["roll"]["rmse"] - 0.5) < 1e-9 and lib["reference_loading"]["options"] == {
        "--ref-profile": str(profile)
    }
    # a mapping error names the reference and its flag
    code, err = run("evaluate", str(est), "--reference", str(ref), "--ref-columns", "Heel=roll:deg")
    assert code == 2 and f"{ref}: --ref-columns: no column 'Heel' in the file" in err
