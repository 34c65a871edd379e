"""A foreign CSV whose header is two rows (issue 48, item 10): a row of group names with blank cells carried
forward (``Time (s);Vicon Orientation;;;;IMU Acceleration;;;...``), then a row of axis letters (``;W;X;Y;Z;X;...``)
— RepoIMU's layout (Szczęsna et al. 2016: TStick/Pendulum trials, Vicon reference, acc m/s², gyro rad/s,
magnetometer normalised, unit-less)."""

from __future__ import annotations

import numpy as np
import pytest

from formats import ImutoolError
from formats.csv import read_csv, read_header

# RepoIMU's own header (';', trailing separators on the header rows) and three of its data rows
REPOIMU = (
    "Time (s);Vicon Orientation;;;;IMU Acceleration;;;IMU Gyroscope;;;IMU Magnetometer;;;\n"
    ";W;X;Y;Z;X;Y;Z;X;Y;Z;X;Y;Z;\n"
    "0.08;1;0;1.6232e-035;0;-0.071594;0.21157;9.7958;0.002314;-0.00634;0.001322;-0.33533;0.19856;-0.88708\n"
    "0.09;1;1.4021e-006;1.8673e-006;-2.9199e-007;-0.071702;0.21878;9.7911;0.000533;-0.007287;-0.000957;"
    "-0.33402;0.20025;-0.88472\n"
    "0.1;1;2.8249e-006;3.7031e-006;-2.5293e-007;-0.081245;0.20916;9.7764;0.009342;-0.000424;0.003585;"
    "-0.33514;0.19707;-0.88613\n"
)


def test_repoimu_group_and_axis_rows_are_read(tmp_path):
    p = tmp_path / "TStick_Test01_Trial1.csv"
    p.write_text(REPOIMU)
    hdr = read_header(str(p))
    targets = {c.source: c.target for c in hdr.mapping.columns}
    assert targets["Time (s)"] == "time"
    assert [targets[f"Vicon Orientation {a}"] for a in "WXYZ"] == ["ref_qw", "ref_qx", "ref_qy", "ref_qz"]
    assert [targets[f"IMU Acceleration {a}"] for a in "XYZ"] == ["accel_x", "accel_y", "accel_z"]
    assert [targets[f"IMU Gyroscope {a}"] for a in "XYZ"] == ["gyro_x", "gyro_y", "gyro_z"]
    assert [targets[f"IMU Magnetometer {a}"] for a in "XYZ"] == ["mag_x", "mag_y", "mag_z"]
    rec = read_csv(str(p))
    assert len(rec) == 3 and np.allclose(rec.time, [0.08, 0.09, 0.1])
    np.testing.assert_allclose(rec["accel"][0], [-0.071594, 0.21157, 9.7958])  # m/s²
    np.testing.assert_allclose(rec["gyro"][1], [0.000533, -0.007287, -0.000957])  # rad/s, as RepoIMU gives it
    np.testing.assert_allclose(rec["ref_q"][0], [1, 0, 1.6232e-35, 0])
    assert rec.meta["source_header_rows"] == 2 and "axis row" in rec.meta["source_header"]
    assert "IMU Gyroscope X->gyro_x[rad/s]" in rec.meta["column_mapping"]
    assert set(rec.meta["units_assumed"].split(",")) == {"accel", "gyro", "mag"}  # the file states none of them


def test_group_header_with_commas_and_a_plain_orientation(tmp_path):
    p = tmp_path / "grouped.csv"
    p.write_text(
        "Time,Orientation,,,,Accelerometer,,,Gyroscope (deg/s),,,Magnetometer,,\n"
        ",w,x,y,z,x,y,z,x,y,z,x,y,z\n"
        "0,1,0,0,0,0,0,9.81,10,0,0,20,0,40\n"
        "0.5,1,0,0,0,0,0,9.81,10,0,0,20,0,40\n"
    )
    rec = read_csv(str(p))
    assert list(rec.channels) == ["q", "accel", "gyro", "mag"]
    np.testing.assert_allclose(rec["gyro"][0], [np.radians(10.0), 0, 0])  # the group's unit applies to its axes
    np.testing.assert_allclose(rec["q"][1], [1, 0, 0, 0])


def test_blank_header_cells_over_numbers_stay_refused(tmp_path):
    p = tmp_path / "blank.csv"
    p.write_text("a,,c\n1,2,3\n")
    with pytest.raises(ImutoolError, match="empty column name"):
        read_csv(str(p))
    q = tmp_path / "grouped.csv"
    q.write_text("Time,Gyroscope,,\n,x,y,z\n0,1,2,3\n1,1,2,3\n")
    assert len(read_csv(str(q))) == 2
    with pytest.raises(ImutoolError, match="empty column name"):  # one header row said: the blanks are an error
        read_csv(str(q), header_rows=1)
