"""Gyro-free angular rate: kinematics vs the paper's closed form, EKF accuracy on the paper's rates, layout
checks (degenerate layouts refused), TOML layouts, real NTNU roll from the accelerometer pair, CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import formats
from formats.errors import ImutoolError
from imutool import gyrofree as G
from imutool.sim.accel_array import accel_array

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "layout_paper.toml"


@pytest.fixture(scope="module")
def paper_rec():
    return accel_array(duration=20, rate_hz=100, seed=4)


def test_least_squares_equals_paper_eq21_and_truth(paper_rec):
    lay = G.paper_layout(0.1)
    y = G.measurements(paper_rec, lay)
    f0, wd, quad, _ = G.solve_kinematics(y, lay)
    m = G.paper_closed_form(y.reshape(len(y), 4, 3), 0.1)
    assert np.allclose(m[:, :3], wd, atol=1e-10) and np.allclose(m[:, 3:], quad, atol=1e-10)
    # noise-free design check: A·u reproduces the sensor model exactly
    clean = accel_array(duration=2, rate_hz=50, seed=1, noise_ug=0.0)
    _, wd0, q0, _ = G.solve_kinematics(G.measurements(clean, lay), lay)
    w = clean["ref_gyro"]
    assert np.allclose(wd0, clean["ref_angular_accel"], atol=1e-9)
    assert np.allclose(q0[:, 5], w[:, 1] * w[:, 2], atol=1e-9)


def test_ekf_rate_rms_per_axis_on_paper_rates(paper_rec):
    out, summ = G.gyrofree_recording(paper_rec, G.paper_layout(0.1))
    e = out["gyro"] - paper_rec["ref_gyro"]
    rms = np.sqrt(np.mean(e**2, axis=0))
    # 100 µg/√Hz at 100 Hz, r = 0.1 m: measured ≈ [0.005, 0.006, 0.004] rad/s
    assert np.all(rms < [0.012, 0.012, 0.010]), rms
    assert np.all(out["gyro_std"][-1] > 0)
    assert np.allclose(np.linalg.norm(out["q"], axis=1), 1.0)
    # the sign ambiguity: started with the wrong sign, the EKF stays on the mirrored branch (h(ω) = h(−ω))
    neg, _ = G.gyrofree_recording(paper_rec, G.paper_layout(0.1), sign=-1.0)
    assert np.mean(neg["gyro"][:, 2]) < 0


@pytest.mark.parametrize("kind", ["collinear", "duplicated"])
def test_degenerate_layouts_are_refused(kind):
    lay = G.degenerate_examples()[kind]
    with pytest.raises(ImutoolError, match="degenerate") as ei:
        G.check_layout(lay)
    msg = str(ei.value)
    assert ("collinear" in msg) if kind == "collinear" else ("distinct sensor position" in msg)
    info = G.check_layout(lay, refuse=False)
    assert info["rank"] < 12 and not info["observable"]


def test_coplanar_and_too_few_axes_refused():
    eye = np.eye(3)
    pts = [(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0), (0.1, 0.1, 0)]
    lay = G.Layout(
        [G.Sensor(f"S{i}", np.array(p, float), eye, [f"s{i}_{c}" for c in "xyz"]) for i, p in enumerate(pts)],
        name="flat",
    )
    with pytest.raises(ImutoolError, match="coplanar"):
        G.check_layout(lay)


def test_toml_example_equals_preset_and_single_axis_layout_works(tmp_path):
    lay = G.load_layout(str(EXAMPLE))
    p1, d1, c1, _ = lay.rows()
    p2, d2, c2, _ = G.paper_layout(0.1).rows()
    assert np.allclose(p1, p2) and np.allclose(d1, d2) and c1 == c2
    # 15 single-axis sensors on a tetrahedron-like frame: full rank, solvable
    rng = np.random.default_rng(0)
    body = [
        f'[[sensor]]\nname = "s{i}"\nposition = [{x}, {y}, {z}]\ndirection = [{a}, {b}, {c}]\n'
        f'column = "c{i}"\nunit = "g"\n'
        for i, ((x, y, z), (a, b, c)) in enumerate(
            zip(rng.normal(0, 0.2, (15, 3)), rng.normal(0, 1, (15, 3)), strict=True)
        )
    ]
    f = tmp_path / "l.toml"
    f.write_text("\n".join(body))
    single = G.load_layout(str(f))
    assert G.check_layout(single)["observable"]
    rec = accel_array(duration=3, rate_hz=50, seed=2, layout=str(f), noise_ug=0.0)
    _, wd, _, _ = G.solve_kinematics(G.measurements(rec, single), single)  # unit g converted to m/s²
    assert np.allclose(wd, rec["ref_angular_accel"], atol=1e-8)
    bad = tmp_path / "bad.toml"
    bad.write_text("[[sensor]]\nname = 'x'\n")
    with pytest.raises(ImutoolError, match="position"):
        G.load_layout(str(bad))


def test_ntnu_roll_from_accelerometer_pair(shared):
    from imutool.metrics import best_lag, interp_to

    rec = formats.read(str(shared("ntnu_waves", "3012_1.csv")))
    res = G.planar_roll(rec.time, rec["acc_heave_ps"], rec["acc_heave_sb"], [0, -0.13, 0], [0, 0.13, 0], [0, 0, -1])
    roll, cam = res["roll"], rec["roll"]  # camera Roll [rad]: found positive starboard down, as FRD
    lag, _ = best_lag(rec.time, roll, rec.time, cam, 0.1)
    m = (rec.time > 1 / res["cutoff_hz"]) & (rec.time < rec.time[-1] - 1 / res["cutoff_hz"])
    ref = interp_to(rec.time[m] - lag, rec.time, cam)
    assert np.corrcoef(roll[m], ref)[0, 1] >= 0.95
    assert np.sqrt(np.mean((roll[m] - ref) ** 2)) < 0.01  # rad (measured 0.0058 rad = 0.33°)


def test_cli_check_layout_and_refusal(tmp_path):
    from click.testing import CliRunner

    from imutool.cli import main

    runner = CliRunner()
    from imutool.cli import cli

    res = runner.invoke(cli, ["gyrofree", "--layout", str(EXAMPLE), "--check-layout", "--json"])
    assert res.exit_code == 0 and "condition_number" in res.output
    f = tmp_path / "c.toml"
    f.write_text(
        "".join(
            f"[[sensor]]\nposition = [{0.1 * i}, 0, 0]\naxes = 'xyz'\ncolumns = ['a{i}', 'b{i}', 'c{i}']\n"
            for i in range(4)
        )
    )
    with pytest.raises(SystemExit) as ei:
        main(["gyrofree", "--layout", str(f), "--check-layout", "-q"])
    assert ei.value.code == 2


def test_check_layout_takes_every_loading_option(tmp_path, capsys):
    """--check-layout loads INPUT as the route does: --rate (a CSV without a time column) reaches the loader."""
    import json

    from imutool.cli import main

    cols = [f"a{i}_{a}" for i in range(1, 5) for a in "xyz"]
    f = tmp_path / "array.csv"
    rows = "\n".join(",".join(f"{0.01 * i + j:.3f}" for j in range(12)) for i in range(50))
    f.write_text(",".join(cols) + "\n" + rows + "\n")
    args = ["gyrofree", str(f), "--layout", str(EXAMPLE), "--check-layout", "--json"]
    with pytest.raises(SystemExit) as ei:
        main(args)  # no time column: needs --rate
    assert ei.value.code == 2 and "--rate" in capsys.readouterr().err
    with pytest.raises(SystemExit) as ei:
        main([*args, "--rate", "100"])
    assert ei.value.code in (0, None)
    assert json.loads(capsys.readouterr().out)["input"] == str(f)


def test_planar_options_without_planar_are_refused(tmp_path, capsys):
    """--cutoff and --causal belong to the --planar roll: without --planar they would be silently unused."""
    from imutool.cli import main

    src, out = tmp_path / "array.csv", tmp_path / "o.csv"
    formats.write(accel_array(duration=2, rate_hz=50, seed=1), str(src))
    for extra, needle in (
        (["--cutoff", "0.2"], "--cutoff applies only with --planar"),
        (["--cutoff", "0.2", "--causal"], "--cutoff and --causal apply only with --planar"),
    ):
        with pytest.raises(SystemExit) as ei:
            main(["gyrofree", str(src), "--layout", "paper", "-o", str(out), *extra])
        err = capsys.readouterr().err
        assert ei.value.code == 2 and needle in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists()
