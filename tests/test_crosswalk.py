"""`calibrate show --as c|matlab|python|json`: each form pastes and compiles/runs as printed, with the file's
numbers (C compiled with the system compiler against FusionMath.h-shaped types; MATLAB parsed back; Python
exec'd; JSON loaded)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner

from calibration.file import load_calibration, update_calibration
from imutool.cli import cli

A = np.array([[1.02, 0.031, -0.004], [0.031, 0.97, 0.012], [-0.004, 0.012, 1.005]])
B = np.array([6.25, -4.125, 1.0e-3])
GB = np.array([0.0012, -0.0031, 0.00045])  # rad/s
GS = np.array([[1.001, 0.002, 0.0], [0.0, 0.998, -0.001], [0.003, 0.0, 1.0]])
AB = np.array([0.05, -0.12, 0.3])  # m/s²
AT = np.array([[0.999, 0.001, 0.0], [0.0, 1.002, 0.0], [0.0, 0.0, 0.997]])

# x-io Fusion FusionMath.h layout (unions of a float array and named members, row-major matrix)
FUSION_STUB = """#ifndef FUSION_H
#define FUSION_H
typedef union { float array[3]; struct { float x; float y; float z; } axis; } FusionVector;
typedef union { float array[9]; struct { float xx; float xy; float xz; float yx; float yy; float yz; float zx;
    float zy; float zz; } element; } FusionMatrix;
#endif
"""


@pytest.fixture()
def cal(tmp_path):
    p = tmp_path / "cal.toml"
    update_calibration(
        str(p), "mag", {"model": "m_true = A (m_meas - b)", "A": A.tolist(), "b": B.tolist(), "field_ut": 49.75}, False
    )
    update_calibration(str(p), "gyro", {"model": "w = S (w_meas - b)", "bias": GB.tolist(), "scale": GS.tolist()}, True)
    update_calibration(str(p), "accel", {"model": "f = T (f_meas - b)", "bias": AB.tolist(), "T": AT.tolist()}, True)
    return p


def show(cal, form: str) -> str:
    r = CliRunner().invoke(cli, ["calibrate", "show", str(cal), "--as", form])
    assert r.exit_code == 0, r.output
    return r.output


def _floats(text: str) -> np.ndarray:
    return np.array([float(x) for x in re.findall(r"[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?", text)])


def test_c_snippet_compiles_and_carries_the_numbers(cal, tmp_path):
    code = show(cal, "c")
    assert code.splitlines()[0].startswith("//") and "# imutool" not in code
    assert show(cal, "fusion") == code
    body = {
        m.group(1): _floats(m.group(2))
        for m in re.finditer(r"const Fusion\w+ (\w+) = \{\.array = \{([^}]*)\}\};", code)
    }
    assert np.allclose(body["softIronMatrix"], A.ravel(), rtol=1e-7)
    assert np.allclose(body["hardIronOffset"], B, rtol=1e-7)
    assert np.allclose(body["gyroscopeOffset"], np.degrees(GB), rtol=1e-7)  # Fusion's gyroscope is deg/s
    assert np.allclose(body["gyroscopeMisalignment"], GS.ravel(), rtol=1e-7)
    assert np.allclose(body["accelerometerOffset"], AB / 9.80665, rtol=1e-7)  # and its accelerometer g
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler on this machine: the C form was checked by parsing only")
    (tmp_path / "Fusion.h").write_text(FUSION_STUB)
    src = tmp_path / "cal.c"
    src.write_text(code)
    res = subprocess.run(
        [cc, "-fsyntax-only", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I", str(tmp_path), str(src)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 0, res.stderr
    # a snippet with the old first line is rejected by the same compiler (the test can tell)
    bad = tmp_path / "bad.c"
    bad.write_text("# imutool: m_true = A (m_meas - b)\n" + code)
    assert (
        subprocess.run([cc, "-fsyntax-only", "-I", str(tmp_path), str(bad)], capture_output=True, timeout=60).returncode
        != 0
    )


def test_matlab_snippet_parses_back(cal):
    code = show(cal, "matlab")
    vals = {}
    for ln in code.splitlines():
        s = ln.strip()
        if not s:
            continue
        if s.startswith("%"):
            continue
        m = re.match(r"^(\w+) = (\[[^\]]*\]|[-+0-9.eE]+|NaN);(\s*%.*)?$", s)
        assert m, f"not a MATLAB assignment or % comment: {s!r}"
        rhs = m.group(2)
        if rhs.startswith("["):
            rows = [_floats(r) for r in rhs[1:-1].split(";")]
            vals[m.group(1)] = np.array(rows) if len(rows) > 1 else rows[0]
        else:
            vals[m.group(1)] = float(rhs)
    assert np.allclose(vals["A"], A, rtol=1e-8) and np.allclose(vals["b"], B, rtol=1e-8)
    assert vals["expmfs"] == pytest.approx(49.75)
    assert np.allclose(vals["gyro_b"], GB) and np.allclose(vals["gyro_S"], GS)
    assert np.allclose(vals["accel_b"], AB) and np.allclose(vals["accel_T"], AT)
    # magcal's C = (D - b) * A equals imutool's A (m - b) (A symmetric)
    d = np.array([[30.0, -12.0, 40.0], [-5.0, 22.0, -33.0]])
    assert np.allclose((d - vals["b"]) @ vals["A"], (A @ (d - B).T).T)


def test_python_snippet_runs(cal):
    code = show(cal, "python")
    ns: dict = {}
    exec(compile(code, "<calibrate show --as python>", "exec"), ns)  # noqa: S102 - the point of the test
    m = np.array([[30.0, -12.0, 40.0], [-5.0, 22.0, -33.0]])
    assert np.allclose(ns["correct_mag"](m), (A @ (m - B).T).T)
    assert np.allclose(ns["correct_gyro"](np.zeros((1, 3))), (GS @ (-GB)).reshape(1, 3))
    assert np.allclose(ns["correct_accel"](np.ones((1, 3))), (AT @ (1.0 - AB)).reshape(1, 3))
    assert ns["field_ut"] == pytest.approx(49.75)
    # the same correction as imutool's own calibration file
    c = load_calibration(cal)
    b, a = c.mag()
    assert np.allclose(ns["A"], a) and np.allclose(ns["b"], b)


def test_json_loads(cal):
    d = json.loads(show(cal, "json"))
    assert np.allclose(d["mag"]["A"], A) and np.allclose(d["gyro"]["bias"], GB)


def test_no_mag_section_is_refused(tmp_path):
    p = tmp_path / "g.toml"
    update_calibration(str(p), "gyro", {"model": "w", "bias": GB.tolist()}, False)
    r = CliRunner().invoke(cli, ["calibrate", "show", str(p), "--as", "c"])
    assert r.exit_code != 0 and "no [mag] section" in str(r.exception)
