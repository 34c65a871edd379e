"""Rotations, Euler angles and frame conventions (vectorised numpy).

Conventions (docs/architecture.md): body frame FRD (x bow, y starboard, z down), world frame NED. Quaternions are
scalar-first ``[w, x, y, z]`` and rotate body vectors into NED: ``v_ned = q ⊗ v_body ⊗ q*``.
Euler angles are the aerospace ZYX sequence: heading ψ about z (clockwise from north seen from above),
pitch θ about y (bow up positive), roll φ about x (starboard down positive); all in radians here.
ROS REP-103 uses FLU body / ENU world; the conversions live here and are used only at the bag boundary.
"""

from __future__ import annotations

import numpy as np

from .errors import ImutoolError

# FLU <-> FRD is a rotation of 180 deg about x: (x, y, z) -> (x, -y, -z); it is its own inverse.
FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])
# ENU <-> NED: (e, n, u) -> (n, e, -d); a symmetric permutation, its own inverse.
ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
# The same two as quaternions (rotation matrices R with v' = R v).
Q_FLU_TO_FRD = np.array([0.0, 1.0, 0.0, 0.0])
Q_ENU_TO_NED = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q for arrays of shape (..., 4)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate (inverse of a unit quaternion), shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion with non-negative scalar part (a canonical sign), shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    q = q / n
    return np.where(q[..., :1] < 0, -q, q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices R (..., 3, 3) with v_ned = R v_body, from unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q, -1, 0)
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) from rotation matrices (..., 3, 3) (Shepperd's method)."""
    r = np.asarray(r, dtype=float)
    tr = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    cand = np.stack(
        [
            np.stack(
                [1 + tr, r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1
            ),
            np.stack(
                [
                    r[..., 2, 1] - r[..., 1, 2],
                    1 + 2 * r[..., 0, 0] - tr,
                    r[..., 0, 1] + r[..., 1, 0],
                    r[..., 0, 2] + r[..., 2, 0],
                ],
                -1,
            ),
            np.stack(
                [
                    r[..., 0, 2] - r[..., 2, 0],
                    r[..., 0, 1] + r[..., 1, 0],
                    1 + 2 * r[..., 1, 1] - tr,
                    r[..., 1, 2] + r[..., 2, 1],
                ],
                -1,
            ),
            np.stack(
                [
                    r[..., 1, 0] - r[..., 0, 1],
                    r[..., 0, 2] + r[..., 2, 0],
                    r[..., 1, 2] + r[..., 2, 1],
                    1 + 2 * r[..., 2, 2] - tr,
                ],
                -1,
            ),
        ],
        axis=-2,
    )
    diag = np.stack([tr, r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]], -1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    return quat_normalize(q)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate body vectors v (..., 3) into the world frame with q (..., 4)."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), np.asarray(v, dtype=float))


def euler_to_quat(roll: np.ndarray, pitch: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Quaternion body→NED from ZYX Euler angles in radians (roll φ, pitch θ, heading ψ)."""
    cr, sr = np.cos(np.asarray(roll) / 2), np.sin(np.asarray(roll) / 2)
    cp, sp = np.cos(np.asarray(pitch) / 2), np.sin(np.asarray(pitch) / 2)
    cy, sy = np.cos(np.asarray(heading) / 2), np.sin(np.asarray(heading) / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )


def quat_to_euler(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX Euler angles (roll, pitch, heading) in radians from body→NED quaternions; heading in [0, 2π)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q, -1, 0)
    if w.ndim == 0:
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        heading = np.mod(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)), 2 * np.pi)
        return roll, pitch, heading
    # the same values, bit for bit, faster on many rows: the components contiguous (strided arithmetic costs 4×) and
    # mod 2π as a conditional 2π added (np.mod costs more than the two arctan2; the same single rounding; -0 → +0)
    w, x, y, z = np.ascontiguousarray(np.moveaxis(q, -1, 0))
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    heading = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    heading += np.where(heading < 0.0, 2 * np.pi, 0.0)
    return roll, pitch, heading


def wrap_deg180(a: np.ndarray) -> np.ndarray:
    """Wrap angles in degrees to [-180, 180)."""
    return (np.asarray(a, dtype=float) + 180.0) % 360.0 - 180.0


def angle_diff_deg(a: np.ndarray, b: np.ndarray | float = 0.0) -> np.ndarray:
    """``a − b`` compared on the circle: degrees in (−180, 180] (NaN kept). The one rule for every angle error
    (roll, pitch, heading, heel): a roll of 179° against −179° is 2° apart, not 358°. Differences already within
    ±180° are returned exactly as subtracted (bit for bit)."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    with np.errstate(invalid="ignore"):
        out = np.where(np.abs(d) <= 180.0, d, 180.0 - np.mod(180.0 - d, 360.0))
        return np.where(out == -180.0, 180.0, out)


def wrap_deg360(a: np.ndarray) -> np.ndarray:
    """Wrap angles in degrees to [0, 360)."""
    return np.asarray(a, dtype=float) % 360.0


def rotation_about_axes(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """3×3 rotation matrix R = Rz(yaw) Ry(pitch) Rx(roll) for small misalignment angles in radians."""
    return quat_to_matrix(euler_to_quat(roll, pitch, yaw))


_AXES = {"x": 0, "y": 1, "z": 2}


def parse_axis_remap(spec: str) -> np.ndarray:
    """Parse an axis remap such as ``"x,-y,-z"`` into a signed permutation matrix M (body = M · sensor).

    The i-th item names the sensor axis (with sign) that becomes body axis i (x bow, y starboard, z down).
    ``"x,-y,-z"`` turns a FLU-mounted sensor into FRD; ``"y,x,-z"`` an ENU-style board into FRD.
    """
    items = [s.strip().lower() for s in spec.split(",")]
    if len(items) != 3:
        raise ImutoolError(f"mounting {spec!r}: expected three comma-separated axes such as 'x,-y,-z'")
    m = np.zeros((3, 3))
    used = set()
    for i, item in enumerate(items):
        sign = -1.0 if item.startswith("-") else 1.0
        name = item.lstrip("+-")
        if name not in _AXES:
            raise ImutoolError(f"mounting {spec!r}: {item!r} is not one of x, y, z, -x, -y, -z")
        if name in used:
            raise ImutoolError(f"mounting {spec!r}: axis {name} is used twice")
        used.add(name)
        m[i, _AXES[name]] = sign
    if np.linalg.det(m) < 0:
        raise ImutoolError(
            f"mounting {spec!r} is a mirror image (left-handed); a real sensor mounting is a rotation — "
            "flip the sign of one axis"
        )
    return m


def format_axis_remap(m: np.ndarray) -> str:
    """Inverse of :func:`parse_axis_remap` for a signed permutation matrix."""
    out = []
    for row in np.asarray(m):
        j = int(np.argmax(np.abs(row)))
        out.append(("-" if row[j] < 0 else "") + "xyz"[j])
    return ",".join(out)
