"""The EKF's fixed layouts: state vector slots (S_*), parameter vector slots (P_*), per-sample flag bits (F_*)."""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)

# the accelerometer low-pass starts as the running mean of its samples for this fraction of τ (its first samples
# averaged: 0.25 s at τ = 2.5 s), then runs as the Butterworth from that mean (docs/attitude.md, "The low-pass")
LP_MEAN_START = 0.1
# ... for at most LP_MEAN_MAX s (the same at τ ≤ 2.5 s): while the mean's memory grows (its lag t/2) the filter reads
# how a ship's translational acceleration changes as gyro bias; at τ 20–60 s a 2–6 s mean taught 1–2 °/s of wrong
# bias and the filter diverged (issue 35: τ 10 s on a bridge sensor, 200° of roll error; 2.8° with the cap)
LP_MEAN_MAX = 0.25  # s
# a low-pass longer than LP_TAU_START starts at that τ and lengthens by LP_TAU_GROWTH s per s it has run: its lag
# (τ × the gyro-bias error) is then learned while it is short — started at τ 40 s, a bridge sensor's 0.3 °/s of
# unknown bias put 13° into the roll for two minutes (issue 35); the same at τ ≤ 2.5 s
LP_TAU_START, LP_TAU_GROWTH = 2.5, 0.25  # s, s/s

# ---- state vector layout (float64, carried between chunks) -------------------------------------------------
S_Q, S_B, S_P = 0, 4, 7  # q (4), b (3), P (36, row-major 6×6)
S_MREF, S_MNORM = 43, 46  # unit reference field in NED (3), reference norm
S_TPREV, S_GPREV = 47, 48  # previous time, previous gyro (3)
S_REST_T, S_AREJ_T, S_CNT_A, S_INIT = 51, 52, 53, 54  # S_CNT_A: samples since the last accel update
S_DQ = 55  # accumulated rotation since the last covariance propagation (4)
S_TACC = 59  # accumulated time since the last covariance propagation
S_NGAPS, S_NAREJ, S_NMREJ, S_NREST, S_NGNAN, S_NUPD = 60, 61, 62, 63, 64, 65
S_QI, S_LPV, S_LPY, S_LPINIT = 66, 70, 73, 76  # gyro-only quaternion body→I (4), accel low-pass in I: rate, output
S_AVAR, S_APREV, S_NAVAR = 77, 78, 81  # accel white-noise variance estimate (m²/s⁴), previous raw accel, count
S_APREV2 = 82  # raw accel two samples back (3)
S_BHOLD = 85  # time left (s) during which accel updates may not move the bias
S_BIASMAX = 86  # |b_i| bound (rad/s, copied from the parameters; ≤ 0: none)
S_NIS_A, S_NIS_M, S_NINC = 87, 88, 89  # windowed mean NIS per degree of freedom (accel, mag heading); flagged count
S_WLP, S_WDOT, S_WINIT = 90, 93, 96  # lever arm: low-passed body rate (3), its derivative (3), started flag
S_SHOCK_T = 97  # continuous time (s) the accelerometer has been beyond the shock gate
S_MDIST = 98  # magnetic disturbance level (peak-held deviation measure, decays with mag_disturbance_hold)
S_AFLOOR = 99  # accel white-noise floor (m²/s⁴): the 10-s mean followed down at once, up with accel_noise_rise_time
S_GW1, S_GW2, S_GWN, S_GWT = 100, 103, 106, 107  # tilt check: world-frame force low-pass stages (3+3), count, time
S_NTILT, S_TILTMAX = 108, 109  # tilt check: flagged samples, largest tan² of the tilt checked
S_WV, S_WY = 110, 119  # lag-weighted R_I of the low-pass (3×3 each, s): rate's and output's companions (W = W_Y)
S_HLAST, S_HREJ_T, S_NHREJ = 128, 129, 130  # external heading: last update time (s), time rejected (s), count
# multi-rate (update every N samples): per sensor, samples since its last update (mag, rest; accel: S_CNT_A), the
# usable samples among them (accel: fed to the low-pass; mag: accepted; rest: still) and what the update averages:
# the accepted magnetometer directions in the world frame (unit vectors, summed) and the still gyro samples (rad/s)
S_CNT_M, S_CNT_R, S_USE_A, S_USE_M, S_USE_R = 131, 132, 133, 134, 135
S_MSUM, S_RSUM = 136, 139
# the magnetometer's reference norm and dip follow the accepted field (mag_reference_tau): the norms summed since
# the last update, and how many samples the reference stands for (1: the first sample; running mean at start-up)
S_MNSUM, S_MREF_N = 142, 143
# a new field: where the magnetometer is rejected, the candidate field its samples agree on (norm µT, sine of the dip,
# samples) and the time it has held while the body turned (s); how many times a candidate became the reference
S_MCN, S_MCZ, S_MCCNT, S_MCT, S_NMNEW = 144, 145, 146, 147, 148
S_MREF_T = 149  # the time the reference's own field has held while the body turned (s): confirmed at mag_new_first_time
# the candidate's mean horizontal field direction in the world frame: the means of the unit field's north and east
# components (only their angle is used); the time since the last magnetometer sample (s, gaps counted at gap_dt)
S_MCX, S_MCY, S_MDT = 150, 151, 152
# GNSS velocity aiding (docs/attitude.md, "Velocity aiding"): the specific force integrated in the frame I since the
# last velocity fix (3, m/s) and the time it spans (s); whether a sample in it was missing; the previous fix's
# sensor velocity, NED horizontal (2, m/s), whether there is one, and its time (s); the corrected mean force of the
# last whole interval, in I (3, m/s²), which the low-pass takes while it is valid
S_VA_SUM, S_VA_T, S_VA_BAD = 153, 156, 157
S_VA_PREV, S_VA_HAVE, S_VA_TFIX = 158, 160, 161
S_VA_IN, S_VA_OK = 162, 165
S_LPT = 166  # the time (s) the accelerometer low-pass has run since it started (or restarted after a gap)
S_VA_LAST = 167  # the GNSS velocity of the previous row as given (2, m/s; NaN: none): a fix is where it changes
S_NHINC = 169  # samples flagged heading-inconsistent (the magnetometer's NIS: roll and pitch not involved)
STATE_SIZE = 170
# the longest interval between two velocity fixes that is still used (s): longer, the low-pass takes the force;
# the shortest (an interpolated velocity changes every row: one fix per VA_MIN_SPACING s)
VA_MAX_INTERVAL, VA_MIN_SPACING = 3.0, 0.2

# ---- parameter vector layout ---------------------------------------------------------------------------------
P_GYRO_NOISE, P_BIAS_RW, P_ACC_NOISE, P_MAG_NOISE = 0, 1, 2, 3
P_ACC_GATE, P_ACC_NIS, P_MAG_NORM_GATE, P_MAG_DIP_GATE = 4, 5, 6, 7
P_GRAVITY, P_REST_GYRO, P_REST_ACC, P_REST_TIME, P_REST_NOISE = 8, 9, 10, 11, 12
P_GAP_DT, P_GAP_RATE, P_REJ_TIMEOUT, P_GYRO_SCALE = 13, 14, 15, 16
P_ACC_TAU, P_GYRO_PREV_W, P_ACC_ADAPT, P_ACC_SOFT, P_ACC_WN_GAIN = 17, 18, 19, 20, 21
P_MAG_BIAS, P_ACC_BIAS_DEV, P_BIAS_MAX, P_BIAS_HOLD = 22, 23, 24, 25
P_MAG_NORM_SOFT, P_MAG_DIP_SOFT = 26, 27
P_NIS_TAU, P_NIS_LIMIT, P_LEVER_TAU, P_SHOCK_MAX = 28, 29, 30, 31
P_ACC_VBIAS, P_ACC_HEAD, P_MAG_HOLD, P_HEAD_SCALE = 32, 33, 34, 35
P_ACC_NOISE_RISE, P_TILT_WIN, P_TILT_LIM = 36, 37, 38
P_ACC_LAG, P_HDG_NOISE, P_HDG_EVERY, P_MAG_REF_TAU = 39, 40, 41, 42
P_MAG_NEW_TIME, P_MAG_NEW_RATE, P_MAG_NEW_FIRST = 43, 44, 45
P_MAG_BIAS_GATE = 46
N_PARAMS = 47

# ---- flag bits in the per-sample output -------------------------------------------------------------------
F_ACC_REJ, F_MAG_REJ, F_REST, F_ACC_USED, F_MAG_USED, F_INCONSISTENT, F_HDG_USED = 1, 2, 4, 8, 16, 32, 64
F_MAG_NEW = 128  # the magnetometer's reference was replaced by a new field at this sample
F_HDG_INCONSISTENT = 256  # the heading's windowed NIS failed (the flags are uint16)

# external heading (gyrocompass): a fix whose innovation is beyond this many σ is a glitch and skipped, for at most
# this many seconds running; beyond, the heading that stayed away is taken outright
HEADING_GATE_SIGMA, HEADING_REJECT_MAX_S = 4.0, 5.0


# ================================================ numba kernels ================================================
# LLVM fast-math flags that keep NaN/Inf semantics (the kernels test np.isfinite): contraction to FMA,
# reassociation, reciprocal division, no signed zeros.
_FASTMATH = {"contract", "reassoc", "arcp", "nsz"}
# The loop's sections (predict.py, accel.py, rest.py, compensation.py, magnetic.py, heading_input.py, kernel.py) are
# compiled with _nrt=False: they allocate nothing and only borrow the kernel's arrays, so they need no reference
# counts (with them numba counted a reference to every array a section takes at each call, an atomic increment and
# decrement its pruning pass could not remove: the split loop ran at ~40 % of the single loop's speed). Those that run
# every sample or every update also take forceinline=True (LLVM's alwaysinline; numba's inline="always" re-types the
# body in the caller instead and brought the counts back): as calls, with their arrays passed field by field, the
# loop ran 25 % slower. numba compiles a function they call under the same two flags, so the update algebra is
# inlined into them too. The option-only sections (lever arm, GNSS, velocity aiding, heading input) stay calls.
# numba takes fastmath, error_model, _nrt and forceinline from the caller when a function does not set them, and its
# cache does not key on flags. So every section and helper the kernel reaches states all four (the values it took
# from its callers before) and is cached on its own: compiled alone, by the second process of a cold run
# (imutool/filter_warm.py), or inside the kernel, it is the same code, and the kernel links it from the cache
# as LLVM bitcode, so forceinline still inlines it.
# They are compiled only into the kernel, never called from Python: no Python entry (formats/jit/decorators.py).
INLINED = dict(
    fastmath=_FASTMATH,
    nogil=True,
    error_model="numpy",
    _nrt=False,
    forceinline=True,
    cache=True,
    no_cpython_wrapper=True,
)
CALLED = dict(INLINED, forceinline=False)  # the option-only sections: called, not inlined

# ---- constant arguments of the compiled helpers ----------------------------------------------------------------
# numba types a literal True or 3 passed to a compiled function as a type of its own and compiles that function
# once more for it (docs/architecture.md, "Compile time"): constant arguments are these numpy scalars instead
TRUE, FALSE = np.True_, np.False_
ATT, BIAS = np.int64(0), np.int64(3)  # the first row of the attitude block [δθ] and of the bias block [δb] of P
