"""REP-103 (ROS: FLU body, ENU world) ↔ imutool (FRD body, NED world): the one frame conversion of the bag boundary.

* Body vectors (angular_velocity, linear_acceleration, magnetic_field): FLU → FRD is (x, -y, -z), a 180°
  rotation about x, so the same map goes back.
* Orientation: ROS q_ros rotates FLU body vectors into ENU (R_ros). imutool's q (body FRD → NED) is
  R = T_ne · R_ros · T_fb with T_ne = ENU→NED and T_fb = FRD→FLU (both their own inverse): q = q_ne ⊗ q_ros ⊗ q_fb.
* Covariances (3×3, row major) rotate as C_frd = R C_flu Rᵀ with R = diag(1, -1, -1): the xy and xz terms change
  sign. The orientation covariance is read as roll/pitch/yaw variances about the body axes (robot_localization's
  convention), so the same R applies. Also its own inverse.
"""

from __future__ import annotations

import numpy as np

from ..frames import Q_ENU_TO_NED, Q_FLU_TO_FRD, quat_conjugate, quat_multiply

# FLU ↔ FRD body vector map (x, -y, -z): multiply an (..., 3) array by it
FLIP = np.array([1.0, -1.0, -1.0])
# sign pattern of R C Rᵀ for R = diag(1, -1, -1), row-major 3×3: multiply an (..., 9) covariance by it
COV_SIGN = np.outer([1.0, -1.0, -1.0], [1.0, -1.0, -1.0]).ravel()
# row-major 3×3 element names (xx, xy, ..., zz): the columns of a *_cov channel
AXES = [a + b for a in "xyz" for b in "xyz"]
# the orientation covariance's diagonal (roll, pitch, yaw variances about the body axes) as one-sigma channels (deg)
STD_NAMES = ("roll_std", "pitch_std", "heading_std")


def ros_to_frd_quat(q_xyzw: np.ndarray) -> np.ndarray:
    """ROS orientation [x,y,z,w] (FLU body → ENU) → imutool q [w,x,y,z] (FRD body → NED)."""
    q = np.asarray(q_xyzw, float)[..., [3, 0, 1, 2]]
    return quat_multiply(quat_multiply(Q_ENU_TO_NED, q), Q_FLU_TO_FRD)


def frd_to_ros_quat(q_wxyz: np.ndarray) -> np.ndarray:
    """imutool q [w,x,y,z] (FRD → NED) → ROS orientation [x,y,z,w] (FLU → ENU)."""
    q = quat_multiply(quat_multiply(quat_conjugate(Q_ENU_TO_NED), q_wxyz), quat_conjugate(Q_FLU_TO_FRD))
    return q[..., [1, 2, 3, 0]]


# how each conversion is named in meta["bag"]["conversions"] (reading) and in write_bag's summary (writing)
READ_Q = "orientation: q_frd_ned = q(ENU→NED) ⊗ q_ros ⊗ q(FRD→FLU)"
READ_VECTOR = "{} FLU → FRD (x,-y,-z)"
WRITE_VECTOR = "{} FRD → FLU (x,-y,-z)"
WRITE_Q = "q (FRD→NED) → orientation (FLU→ENU)"
WRITE_EULER = "roll/pitch/heading → q (FRD→NED) → orientation (FLU→ENU)"
WRITE_COV = "covariances R C Rᵀ, R = diag(1,-1,-1) (std → variance on the diagonal)"
READ_TWIST = "twist linear ENU → vel_n = y, vel_e = x, vel_d = -z (m/s, NED)"
