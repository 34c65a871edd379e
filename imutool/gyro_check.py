"""Self-check of the gyro's scale against gravity: does the gyro turn the accelerometer's vertical as far as it turns?

A gyro set to the wrong full-scale range, or read in the wrong unit, reads every rate k times too large. The
attitude filter cannot see this from its innovations: its quasi-inertial low-pass and its own attitude turn with the
same gyro, so both are wrong together, and the accelerometer updates pull the tilt back often enough that the world
frame's mean force stays near vertical (a gyro ×2 costs 13° of inclination RMS on `simulate ship-roll` and raises
neither the innovation check nor the tilt check).

The check here uses the physics the filter relies on, without the filter's corrections:

- cut the recording into windows of ``window`` s (frame of each pair of consecutive windows A, B: the gyro,
  bias removed and scaled by a candidate s, integrated from the start of A — a quasi-inertial frame I_s);
- the mean specific force over A and over B in I_s are both −g·ẑ when s is right, whatever the motion, because a
  bounded velocity averages the acceleration out (|Δv| / window); with the wrong s, gravity turns in I_s by
  (s_true − s) times the body's rotation, and the two means part;
- J(s)² = mean over pairs of ‖m_A − m_B‖² / g² (rad², small angles) is least at the scale that makes the gyro
  agree with gravity: ŝ (a log-spaced grid 1/128–128, fine from 0.25 to 4, refined by a parabola in log s).

ŝ is the factor the gyro's rates would need: 0.5 for a gyro reading twice too fast. The check speaks when
ŝ departs from 1 by more than ``SCALE_TOLERANCE`` (19 %: one grid step; calibration, not this check, is for
smaller errors) **and** rescaling would remove at least ``MIN_DISCREPANCY_DEG`` of RMS window-to-window tilt
discrepancy, E = √(J(1)² − J(ŝ)²) — a recording that hardly turns has a flat J and no verdict.

Measured (window 2 s; ``python benchmarks/gyro_check.py``): on the 13 BROAD trials that turn, intact, ŝ 0.96–1.00
(E ≤ 4.2°, none warned); the 3 that hardly turn have a flat J (trial 10: ŝ 0.71, E 0.7°, no verdict). Gyro ×1.5,
×2, ×0.5 are warned on every rotating trial, ŝ 0.66–0.68, 0.48–0.50, 1.92–1.99 (at 400 °/s a wrong scale can alias
in the 4-s pair: BROAD 21 ×1.5 is named 14.65 — still warned). On the simulator: intact ship-roll ŝ 1.08 (its 2 m
lever arm is not given to the filter), ship-at-sea with lever arm and SOG/COG 0.84–0.97 (E ≤ 0.9°); ×1.5, ×2 and
×0.5 warned on both. A bridge sensor 36 m from the roll centre run **without** its lever arm gives ŝ 1.58, E 3.5°
and is warned: the roll-synchronous acceleration there is what the check measures (and its roll is 1.2–2° off), so
the warning names that cause too.

The same test names a reversed gyro axis: beside the scales, the seven sign patterns of the three axes are
candidates (x, y or z reversed, two of them, all three). A gyro axis whose sign disagrees with the accelerometer's
turns gravity in I by twice the body's rotation about that axis; the pattern that reverses it is the least J. The
check speaks when a sign pattern is the best candidate of all, removes at least ``MIN_DISCREPANCY_DEG`` and at
least ``AXIS_EXPLAINED`` (a fifth) of the mean-square discrepancy that the better of the gyro as it is and no
rotation at all leave (what neither explains is the windows' own velocity change: a foot in gait, whose velocity
changes by metres per second within a window, is not taken for a reversed axis). It does
not depend on the filter: the filter's own check of the vertical sees a reversed axis only through the phase of its
tilt error against the roll (on ship-roll seeds 1–8: 4.4–5.1° with the two-stage low-pass, 3.2–3.7° with the
Butterworth, limit 3°).
Axes swapped between the gyro and the accelerometer are not among the candidates.

Inputs are SI: time s, gyro and bias rad/s (body), force m/s² (body, the compensated specific force the filter fed
its low-pass; NaN where none). The sums are additive, so a streamed run adds chunk after chunk (pairs do not span
chunks: at most two windows per chunk are left out).
"""

from __future__ import annotations

import numpy as np

import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats.jit.decorators import njit
from imutool.quaternion import SERIES_ANGLE2, qmul, qturn, rotate

WINDOW_S = 2.0  # s: long against vibration and short jerks, short enough that fast hand motion does not alias
# candidate factors on the gyro's rates: 0.25 … 4 in steps of 2^¼ (wrong full-scale ranges), and coarse steps of 2
# out to 1/128 and 128 (a rate in deg/s read as rad/s is 57× off)
SCALES = 2.0 ** np.concatenate([[-7, -6, -5, -4, -3], np.arange(-8, 9) / 4.0, [3, 4, 5, 6, 7]])
# the sign patterns of the three axes other than (+, +, +): a reversed axis, two, all three
AXIS_SIGNS = np.array(
    [[-1, 1, 1], [1, -1, 1], [1, 1, -1], [-1, -1, 1], [-1, 1, -1], [1, -1, -1], [-1, -1, -1]], dtype=np.float64
)
# a reversal must remove this share of the mean-square discrepancy that the gyro as it is or no rotation leave:
# a reversed axis removes 0.26–0.33 at sea for y, 0.60–0.65 for x (waves change the velocity within a window), 0.47
# or more on BROAD's trials that turn (0.19–0.20 on trial 10, which hardly does: no axis named, the scale check
# warns), 0.84–0.96 on ship-roll and a turn; a foot in gait, intact, 0.14 with y reversed
AXIS_EXPLAINED = 0.2
# every candidate as factors on the x, y, z rates: the scales (all axes alike), then the sign patterns
CANDIDATES = np.vstack([np.outer(SCALES, np.ones(3)), AXIS_SIGNS])
ONE = int(np.argmin(np.abs(np.log2(SCALES))))  # the candidate "the gyro as it is" (scale 1)
SCALE_TOLERANCE = 1.3  # ŝ within [1/1.3, 1.3]: no verdict (ranges come in steps of 1.5–2; calibration does less)
MIN_DISCREPANCY_DEG = 1.5  # RMS window-to-window tilt discrepancy that rescaling must remove before it is said
AXIS_TIE_DEG = MIN_DISCREPANCY_DEG  # an axis more in a sign pattern must remove this much RMS …
AXIS_TIE_SHARE = 0.1  # … and this share of the mean square the pattern without it leaves (at sea: waves leave 8–9°)
# cost ∝ samples integrated × scales (≈ 1.6 µs a sample): a run is checked whole up to FULL_CHECK_SAMPLES, beyond that
# on evenly spread pairs, CHECKED_SHARE of its samples — per run, whatever the chunk size of a stream
FULL_CHECK_SAMPLES = 100_000
CHECKED_SHARE = 0.1


@njit(cache=True, nogil=True, error_model="numpy")  # (no zero-division branch: the loops vectorise)
def pair_discrepancy_kernel(t, gyro, bias, force, window, gap_dt, factors, g, max_samples, sums, counts):
    """Add, for each candidate (factors (C,3): the factors on the x, y, z rates), Σ‖m_A − m_B‖²/g² over pairs of
    consecutive windows into sums (C,) and the number of pairs into counts (C,). t (N,) s; gyro, bias (N,3) rad/s
    body; force (N,3) m/s² body (NaN rows skipped); window s; a step > gap_dt s inside a pair drops the pair; at
    most ~max_samples samples are integrated (pairs evenly spread; ≤ 0: none). Returns the number of samples
    integrated and the index where the last complete window starts (0 where fewer than two windows start: where a
    stream's next chunk takes over, :meth:`imutool.attitude.selfcheck.SelfCheck._add_scale`). The rate over a step
    is the sample at its end (the filter's default, ``gyro_integration = "rectangular"``).

    Each sample turns every candidate's quaternion before the next sample is read (the candidates side by side,
    one array per component): the candidates' steps are independent, so the step by the exponential's series and
    the force's rotation run as vector instructions over the candidates (``error_model="numpy"``: no division
    raises, so no branch stops that), the few candidates beyond the series' angle then one by one — 3× less time
    than one candidate's whole pair after another's (25 000 samples: 28 → 8 ms), with the same operations in the
    same order for each candidate (bit-identical sums: tests/test_gyro_check.py)."""
    n = t.shape[0]
    starts = np.empty(n + 1, dtype=np.int64)
    m = 0
    starts[0] = 0
    for k in range(1, n):
        if t[k] - t[starts[m]] >= window:
            m += 1
            starts[m] = k
    n_pairs = m - 1  # windows [starts[p], starts[p+1]) and [starts[p+1], starts[p+2])
    last = starts[m - 1] if m >= 1 else 0  # the last complete window's first sample
    if n_pairs <= 0 or max_samples <= 0:
        return 0, last
    used = 0
    per_pair = 2.0 * n / (m + 1.0)
    stride = max(1, int(np.ceil(n_pairs * per_pair / max_samples)))
    nc = factors.shape[0]
    # each candidate's integrated turn from the start of window A (q0…q3), and its force sums in its frame over
    # window A (a0…a2) and B (b0…b2): one array per component, the candidates side by side
    q0, q1, q2, q3 = np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc)
    n0, n1, n2, n3, angle2 = np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc)  # a step's
    fx, fy, fz = factors[:, 0].copy(), factors[:, 1].copy(), factors[:, 2].copy()
    a0, a1, a2, b0, b1, b2 = np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc), np.empty(nc)
    for p in range(0, n_pairs, stride):
        i0, i1, i2 = starts[p], starts[p + 1], starts[p + 2]
        ok = True
        for k in range(i0 + 1, i2):
            if not t[k] - t[k - 1] <= gap_dt:
                ok = False
                break
        if not ok:
            continue
        used += i2 - i0
        q0[:] = 1.0
        q1[:] = 0.0
        q2[:] = 0.0
        q3[:] = 0.0
        a0[:] = 0.0
        a1[:] = 0.0
        a2[:] = 0.0
        b0[:] = 0.0
        b1[:] = 0.0
        b2[:] = 0.0
        ca = 0
        cb = 0
        for k in range(i0, i2):
            if k > i0:
                dt = t[k] - t[k - 1]
                g0, g1, g2 = gyro[k, 0] - bias[k, 0], gyro[k, 1] - bias[k, 1], gyro[k, 2] - bias[k, 2]
                # every candidate's step by the exponential's series (one branch-free loop the compiler turns
                # into vector instructions), then the few whose angle is beyond the series' range (or not a
                # number) done again one by one as qturn does them: qturn's operations, qturn's result
                for si in range(nc):
                    w0 = fx[si] * g0 * dt
                    w1 = fy[si] * g1 * dt
                    w2 = fz[si] * g2 * dt
                    th = w0 * w0 + w1 * w1 + w2 * w2
                    h = 0.5 - th * (1.0 / 48.0) + th * th * (1.0 / 3840.0)
                    e0, e1, e2, e3 = 1.0 - th * 0.125 + th * th * (1.0 / 384.0), h * w0, h * w1, h * w2
                    c0, c1, c2, c3 = qmul(q0[si], q1[si], q2[si], q3[si], e0, e1, e2, e3)
                    nq = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2 + c3 * c3)
                    n0[si], n1[si], n2[si], n3[si] = c0 / nq, c1 / nq, c2 / nq, c3 / nq
                    angle2[si] = th
                for si in range(nc):
                    if angle2[si] < SERIES_ANGLE2:
                        q0[si], q1[si], q2[si], q3[si] = n0[si], n1[si], n2[si], n3[si]
                        continue
                    w0 = fx[si] * g0 * dt
                    w1 = fy[si] * g1 * dt
                    w2 = fz[si] * g2 * dt
                    if np.isfinite(w0) and np.isfinite(w1) and np.isfinite(w2):
                        q0[si], q1[si], q2[si], q3[si] = qturn(q0[si], q1[si], q2[si], q3[si], w0, w1, w2)
            f0, f1, f2 = force[k, 0], force[k, 1], force[k, 2]
            if not (np.isfinite(f0) and np.isfinite(f1) and np.isfinite(f2)):
                continue
            if k < i1:
                ca += 1
                for si in range(nc):
                    v0, v1, v2 = rotate(q0[si], q1[si], q2[si], q3[si], f0, f1, f2)
                    a0[si] += v0
                    a1[si] += v1
                    a2[si] += v2
            else:
                cb += 1
                for si in range(nc):
                    v0, v1, v2 = rotate(q0[si], q1[si], q2[si], q3[si], f0, f1, f2)
                    b0[si] += v0
                    b1[si] += v1
                    b2[si] += v2
        if 2 * ca < i1 - i0 or 2 * cb < i2 - i1:  # less than half of a window with a force: no pair
            continue
        for si in range(nc):
            d0 = a0[si] / ca - b0[si] / cb
            d1 = a1[si] / ca - b1[si] / cb
            d2 = a2[si] / ca - b2[si] / cb
            sums[si] += (d0 * d0 + d1 * d1 + d2 * d2) / (g * g)
            counts[si] += 1.0
    return used, last


class GyroScaleCheck:
    """Accumulates the window-pair discrepancy over one run (in memory: one :meth:`add`; streamed: one per chunk)
    and gives the verdict (:meth:`report`). window s; gap_dt s (a longer step inside a pair drops the pair: the
    filter's gap_factor × the nominal step); gravity m/s²."""

    def __init__(
        self,
        window: float = WINDOW_S,
        gap_dt: float = 0.5,
        gravity: float = 9.80665,
        samples_expected: int | None = None,
    ) -> None:
        self.window, self.gap_dt, self.gravity = float(window), float(gap_dt), float(gravity)
        self.sums = np.zeros(len(CANDIDATES))
        self.counts = np.zeros(len(CANDIDATES))
        self.seen = self.checked = 0  # samples given, samples integrated (the budget is per run)
        # the run's samples when known before its end (a stream's file): its budget is then spent in proportion to
        # the samples seen, so the pairs spread over the run as in one call, whatever the chunk size
        self.samples_expected = int(samples_expected or 0)
        self.last_window_start = 0  # in the last add's arrays: where its last complete window starts

    def add(self, time: np.ndarray, gyro: np.ndarray, bias: np.ndarray, force: np.ndarray) -> None:
        """One chunk: time (N,) s, gyro and the filter's bias (N,3) rad/s, compensated force (N,3) m/s² (body)."""
        arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (time, gyro, bias, force)]
        self.seen += len(arrays[0])
        run = max(self.seen, self.samples_expected)
        budget = int(max(FULL_CHECK_SAMPLES, CHECKED_SHARE * run) * self.seen / run) - self.checked
        used, self.last_window_start = pair_discrepancy_kernel(
            *arrays, self.window, self.gap_dt, CANDIDATES, self.gravity, budget, self.sums, self.counts
        )
        self.checked += used

    def _mean_j2(self) -> np.ndarray | None:
        """J² (rad²) of every candidate, the mean over the pairs seen; None without a pair."""
        if not len(self.counts) or int(self.counts.min()) == 0:
            return None
        return self.sums / self.counts

    def estimate(self) -> tuple[float, float, int] | None:
        """(ŝ, E rad, pairs): the gyro factor that best agrees with gravity and the RMS discrepancy it removes;
        None without a pair."""
        j2_all = self._mean_j2()
        if j2_all is None:
            return None
        j2 = j2_all[: len(SCALES)]
        i = int(np.argmin(j2))
        x = np.log2(SCALES)
        best_x, best_j2 = x[i], j2[i]
        if 0 < i < len(SCALES) - 1 and np.isclose(x[i] - x[i - 1], x[i + 1] - x[i]):  # parabola in log s
            den = j2[i - 1] - 2 * j2[i] + j2[i + 1]
            if den > 0:
                off = 0.5 * (j2[i - 1] - j2[i + 1]) / den
                best_x = x[i] + off * (x[i + 1] - x[i])
                best_j2 = max(j2[i] - 0.25 * (j2[i - 1] - j2[i + 1]) * off, 0.0)
        return float(2.0**best_x), float(np.sqrt(max(float(j2[ONE]) - best_j2, 0.0))), int(self.counts.min())

    def reversed_axes(self) -> tuple[str, float, bool] | None:
        """The sign pattern that best agrees with gravity: (axes reversed, e.g. "x" or "x, z"; the RMS discrepancy
        reversing them removes against the gyro as it is, rad; whether that pattern beats every candidate scale
        and removes AXIS_EXPLAINED of the discrepancy); None without a pair."""
        j2 = self._mean_j2()
        if j2 is None:
            return None
        n_s = len(SCALES)
        i = n_s + int(np.argmin(j2[n_s:]))
        j2_one = float(j2[ONE])
        # the fewest reversed axes that explain the data: an axis is kept in the verdict only where reversing it too
        # removes at least AXIS_TIE_DEG RMS and AXIS_TIE_SHARE of what the pattern without it leaves (an axis the
        # body hardly turns about, a ship's z, is reversed or not alike: gravity does not move about it, and the
        # filter's bias, learnt with the wrong axis, leaves 1–2° to either; a ship's y reversed with its x removes
        # 4–5°, a fifth or more)
        index = {tuple(CANDIDATES[c] < 0): c for c in range(n_s, len(CANDIDATES))}
        dropped = True
        while dropped and (CANDIDATES[i] < 0).sum() > 1:
            dropped = False
            for ax in np.flatnonzero(CANDIDATES[i] < 0):
                fewer = CANDIDATES[i] < 0
                fewer[ax] = False
                k = index[tuple(fewer)]
                gain = j2[k] - j2[i]
                if gain < np.radians(AXIS_TIE_DEG) ** 2 or gain < AXIS_TIE_SHARE * j2[k]:
                    i, dropped = k, True
                    break
        axes = ", ".join("xyz"[a] for a in range(3) if CANDIDATES[i, a] < 0)
        # the reversal must remove AXIS_EXPLAINED of what the better of the gyro as it is and no rotation at all
        # (the smallest scale) leave: what neither explains is the windows' own velocity change, not the gyro's
        trivial = min(j2_one, float(j2[0]))
        explains = j2[i] < j2[:n_s].min() and trivial - j2[i] >= AXIS_EXPLAINED * trivial
        return axes, float(np.sqrt(max(j2_one - j2[i], 0.0))), bool(explains)

    def report(self) -> tuple[dict, list[str]]:
        """Summary entry ``gyro_scale_check`` and the warning (one line) where the gyro disagrees with gravity: a
        reversed axis (the best candidate of all is a sign pattern) or a wrong scale."""
        est = self.estimate()
        if est is None:
            return {"gyro_scale_check": {"pairs": 0, "window_s": self.window}}, []
        axes, axis_disc, axis_best = self.reversed_axes()
        if axis_best and np.degrees(axis_disc) >= MIN_DISCREPANCY_DEG:
            entry = {
                "reversed_axes": axes,
                "discrepancy_deg": round(float(np.degrees(axis_disc)), 2),
                "pairs": est[2],
                "window_s": self.window,
                "flagged": True,
            }
            one = len(axes) == 1
            cols = " and ".join(f"'COLUMN=gyro_{a}:UNIT*-1'" for a in axes.split(", "))
            return {"gyro_scale_check": entry}, [
                f"gyro axis check: the gyro's {axes} {'axis looks' if one else 'axes look'} reversed against the "
                f"accelerometer's (reversing {'it' if one else 'them'} removes "
                f"{np.degrees(axis_disc):.1f}° RMS of tilt discrepancy between {self.window:g}-s windows): the "
                f"attitude is wrong while the sensor turns about {'that axis' if one else 'those axes'}; fix the "
                f"gyro's axis map (the device's configuration, or a column scale of −1: --columns {cols}) and run "
                "again"
            ]
        scale, disc, pairs = est
        at_edge = not SCALES[0] * 1.01 < scale < SCALES[-1] / 1.01  # beyond the grid: "at least"
        entry = {
            "scale": round(scale, 3),
            "discrepancy_deg": round(float(np.degrees(disc)), 2),
            "pairs": pairs,
            "window_s": self.window,
        }
        off = scale > SCALE_TOLERANCE or scale < 1.0 / SCALE_TOLERANCE
        if not (off and np.degrees(disc) >= MIN_DISCREPANCY_DEG):
            return {"gyro_scale_check": entry}, []
        entry["flagged"] = True
        how = f"{max(scale, 1 / scale):.3g}× too " + ("fast" if scale < 1 else "slow")
        how = "at least " + how if at_edge else how
        return {"gyro_scale_check": entry}, [
            f"gyro scale check: the gyro and gravity disagree on how far the sensor turns — its rates look "
            f"{how} (scaling them by {scale:.3g} removes {np.degrees(disc):.1f}° "
            f"RMS of tilt discrepancy between {self.window:g}-s windows); a gyro in the wrong range or unit, or an "
            "acceleration the filter was not told of (a lever arm not given, an uncompensated turn)"
        ]
