"""Gyro-free angular rate, angular acceleration and attitude from an array of accelerometers.

Method (gyro-free paper, §2): every accelerometer at position r (m, body FRD) measures, along its unit sensitive
axis d, the rigid-body specific force (eq. 6)

    d·f_P = d·f_O + d·(ω̇ × r) + d·(ω × (ω × r))
          = dᵀ f_O + (r × d)ᵀ ω̇ + Σ cⱼ mⱼ,   m = [ωx², ωy², ωz², ωxωy, ωxωz, ωyωz]

with cⱼ: for ωᵢ² → dᵢrᵢ − d·r, for ωᵢωⱼ → dᵢrⱼ + dⱼrᵢ (since ω×(ω×r) = ω(ω·r) − r|ω|²). Gravity is common to
all points of the body and stays inside f_O. Stacking all sensor axes gives a linear system A·u = y in the 12
unknowns u = [f_O (3), ω̇ (3), m (6)], solved by least squares for any layout of full rank (the paper's
four-triad layout is the square case: its closed form eq. 21 was re-derived here and agrees term by term;
eqs. 24a–c carry a spurious ΔT factor on the right-hand side and eq. 26 indexes k+1/k where 25 and 27 use
k/k−1 — both typographical, the recursion implemented is ω(k) = ω(k−1) + ω̇(k)·ΔT).

EKF (paper eqs. 22–30): state ω (3); process ω(k) = ω(k−1) + ω̇·ΔT with ω̇ from the least-squares solution;
measurement the six quadratic terms z = m̂ = h(ω) + v (eq. 29), Jacobian
H = [[2ωx,0,0],[0,2ωy,0],[0,0,2ωz],[ωy,ωx,0],[ωz,0,ωx],[0,ωz,ωy]]. Q and R come from the accelerometer noise
through the least-squares covariance σ²(AᵀA)⁻¹. h(ω) = h(−ω): the sign is carried by the integrated process
(initial sign: largest component positive unless given). Attitude: quaternion integration of ω with an optional
gravity tilt correction from f_O (valid when the translational acceleration is small).

Reduced planar mode: two parallel single-axis accelerometers at a known separation b across the roll axis give
ω̇x = (d·(f₂ − f₁))/(b-term); roll rate and roll angle follow by zero-phase band-pass integration (drift control;
the static heel is not observable from differences of accelerations).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

import formats
import formats.jit.cache  # noqa: F401  (compiled kernels cached per user, never in the package)
from formats import Recording
from formats.errors import ImutoolError
from formats.frames import quat_to_euler
from formats.jit.decorators import njit
from formats.units import convert, lookup
from imutool.loading import input_notes

RATE_RW = 1e-4  # rad/s/√s: random walk of ω in the EKF's process noise
TILT_GAIN = 0.0  # 1/s: gravity tilt correction of the attitude from the centre specific force (0 = pure integration)
UNKNOWNS = ["f_O_x", "f_O_y", "f_O_z", "wdot_x", "wdot_y", "wdot_z", "wx2", "wy2", "wz2", "wxwy", "wxwz", "wywz"]
_AXES = {
    "x": (1.0, 0.0, 0.0),
    "y": (0.0, 1.0, 0.0),
    "z": (0.0, 0.0, 1.0),
    "-x": (-1.0, 0.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "-z": (0.0, 0.0, -1.0),
}


# ------------------------------------------------------------------------------------------------------------------
# Layout
# ------------------------------------------------------------------------------------------------------------------
@dataclass
class Sensor:
    """One accelerometer: position (m, body FRD), unit sensitive axes (k,3), CSV columns (k), unit, scale."""

    name: str
    position: np.ndarray
    axes: np.ndarray
    columns: list[str]
    unit: str = "m/s^2"


@dataclass
class Layout:
    """An accelerometer array. ``rows()`` flattens it to one (position, direction, column) per measured axis."""

    sensors: list[Sensor]
    name: str = "custom"
    noise_density: float | None = None  # m/s²/√Hz (optional; else estimated from the data)
    meta: dict[str, Any] = field(default_factory=dict)

    def rows(self) -> tuple[np.ndarray, np.ndarray, list[str], list[str]]:
        pos, dirs, cols, units = [], [], [], []
        for s in self.sensors:
            for ax, col in zip(s.axes, s.columns, strict=True):
                pos.append(s.position)
                dirs.append(ax)
                cols.append(col)
                units.append(s.unit)
        return np.array(pos, float), np.array(dirs, float), cols, units

    def describe(self) -> list[dict[str, Any]]:
        return [
            {
                "name": s.name,
                "position_m": [float(v) for v in s.position],
                "axes": s.axes.tolist(),
                "columns": s.columns,
                "unit": s.unit,
            }
            for s in self.sensors
        ]


def paper_layout(r: float = 0.1, prefix: str = "a") -> Layout:
    """The paper's array: triad 1 at the centre of mass, triads 2/3/4 at distance r (m) on −x, +y, +z."""
    if r <= 0:
        raise ImutoolError(f"paper layout distance r must be > 0, got {r}")
    pts = [(0, 0, 0), (-r, 0, 0), (0, r, 0), (0, 0, r)]
    sensors = [
        Sensor(f"A{i + 1}", np.array(p, float), np.eye(3), [f"{prefix}{i + 1}_{c}" for c in "xyz"])
        for i, p in enumerate(pts)
    ]
    return Layout(sensors, name=f"paper (r = {r} m)", meta={"r_m": r})


def _parse_axis(v: Any, where: str) -> np.ndarray:
    if isinstance(v, str):
        key = v.strip().lower()
        if key not in _AXES:
            raise ImutoolError(f"{where}: axis {v!r} is not one of x, y, z, -x, -y, -z or a 3-vector")
        return np.array(_AXES[key])
    a = np.asarray(v, float)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) < 1e-9:
        raise ImutoolError(f"{where}: axis {v!r} must be a non-zero 3-vector")
    return a / np.linalg.norm(a)


def _noise_density(doc: dict[str, Any], source: str) -> float | None:
    v = doc.get("noise_density")
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
        raise ImutoolError(f"{source}: noise_density must be a positive number (m/s²/√Hz), got {v!r}")
    return float(v)


MAX_POSITION_M = 1000.0  # an accelerometer array larger than a kilometre is a unit error, not a vessel


def _position(v: Any, where: str) -> np.ndarray:
    """A sensor position [x, y, z] in metres: three finite numbers within ±MAX_POSITION_M."""
    ok = isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    pos = np.asarray(v, float) if ok else np.full(3, np.nan)
    if not np.all(np.isfinite(pos)):
        raise ImutoolError(f"{where}: position must be [x, y, z], finite numbers in metres")
    if np.max(np.abs(pos)) > MAX_POSITION_M:
        raise ImutoolError(f"{where}: position {v!r} is more than {MAX_POSITION_M:g} m from the origin: not metres?")
    return pos


def _accel_unit(v: Any, where: str) -> str:
    """A sensor's unit: a string naming an acceleration unit imutool knows (g, mg, m/s^2 ...)."""
    if not isinstance(v, str):
        raise ImutoolError(f'{where}: unit must be a string such as "m/s^2" or "g", got {v!r}')
    try:
        quantity, _ = lookup(v)
    except ImutoolError:
        raise ImutoolError(f"{where}: unknown unit {v!r} (an acceleration unit: m/s^2, g, mg ...)") from None
    if quantity != "acceleration":
        raise ImutoolError(f"{where}: unit {v!r} measures {quantity}, not acceleration")
    return v


def layout_from_dict(doc: dict[str, Any], source: str = "layout") -> Layout:
    """Build a layout from a parsed TOML document (see docs/gyrofree.md for the format)."""
    if "preset" in doc:
        if doc["preset"] != "paper":
            raise ImutoolError(f"{source}: unknown preset {doc['preset']!r} (known: paper)")
        r = doc.get("r", 0.1)
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not 0 < r <= MAX_POSITION_M:
            raise ImutoolError(f"{source}: r must be a distance in metres, 0 < r ≤ {MAX_POSITION_M:g}, got {r!r}")
        if not isinstance(doc.get("prefix", "a"), str):
            raise ImutoolError(f"{source}: prefix must be a string, got {doc['prefix']!r}")
        lay = paper_layout(float(r), doc.get("prefix", "a"))
        lay.noise_density = _noise_density(doc, source)
        return lay
    default_unit = _accel_unit(doc.get("unit", "m/s^2"), source)
    items = doc.get("sensor")
    if not isinstance(items, list) or not items or not all(isinstance(it, dict) for it in items):
        raise ImutoolError(f'{source}: needs [[sensor]] tables (or preset = "paper")')
    sensors = []
    for i, it in enumerate(items):
        where = f"{source}: sensor {i + 1} ({it.get('name', '?')})"
        if "position" not in it:
            raise ImutoolError(f"{where}: missing position = [x, y, z] (m, body FRD)")
        pos = _position(it["position"], where)
        if "direction" in it:  # single-axis
            col = it.get("column")
            if not isinstance(col, str) or not col.strip():
                raise ImutoolError(f'{where}: a single-axis sensor needs column = "NAME"')
            axes = _parse_axis(it["direction"], where)[None, :]
            cols = [col]
        else:
            spec = it.get("axes", "xyz")
            if isinstance(spec, str):
                if spec not in ("xyz",):
                    raise ImutoolError(f'{where}: axes must be "xyz" or a list of 3-vectors / axis names')
                axes = np.eye(3)
            else:
                axes = np.array([_parse_axis(a, where) for a in spec])
            cols = it.get("columns")
            if (
                not isinstance(cols, list)
                or len(cols) != len(axes)
                or not all(isinstance(c, str) and c.strip() for c in cols)
            ):
                raise ImutoolError(f"{where}: columns must list {len(axes)} CSV column names (strings)")
        unit = _accel_unit(it.get("unit", default_unit), where)
        sensors.append(Sensor(str(it.get("name", f"S{i + 1}")), pos, axes, list(cols), unit))
    return Layout(sensors, name=str(doc.get("name", source)), noise_density=_noise_density(doc, source))


def load_layout(path: str) -> Layout:
    """Read a layout TOML file (or the word 'paper' for the paper preset with r = 0.1 m)."""
    if path == "paper":
        return paper_layout()
    try:
        import tomllib  # noqa: PLC0415
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]  # noqa: PLC0415
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise ImutoolError(f"layout file not found: {path}") from None
    except IsADirectoryError:
        raise ImutoolError(f"{path}: is a folder, not a layout TOML file") from None
    except OSError as e:
        raise ImutoolError(f"{path}: cannot read the layout: {e.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ImutoolError(f"{path}: not valid TOML: {e}") from None
    return layout_from_dict(doc, path)


# ------------------------------------------------------------------------------------------------------------------
# Kinematics and observability
# ------------------------------------------------------------------------------------------------------------------
def design_matrix(pos: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """A (M,12): one row per measured axis, columns u = [f_O (3), ω̇ (3), ωx², ωy², ωz², ωxωy, ωxωz, ωyωz]."""
    p = np.asarray(pos, float)
    d = np.asarray(dirs, float)
    dr = np.sum(d * p, axis=1)
    a = np.zeros((len(p), 12))
    a[:, 0:3] = d
    a[:, 3:6] = np.cross(p, d)
    for i in range(3):
        a[:, 6 + i] = d[:, i] * p[:, i] - dr
    for j, (i, k) in enumerate(((0, 1), (0, 2), (1, 2))):
        a[:, 9 + j] = d[:, i] * p[:, k] + d[:, k] * p[:, i]
    return a


def _geometry_diagnosis(pos: np.ndarray, dirs: np.ndarray) -> list[str]:
    why = []
    pts = np.unique(np.round(pos, 9), axis=0)
    if len(pts) < 4:
        why.append(
            f"only {len(pts)} distinct sensor position(s): sensors at duplicated positions add no "
            "lever arm (at least 4 non-coplanar positions are needed for triads)"
        )
    c = pts - pts.mean(axis=0)
    sv = np.linalg.svd(c, compute_uv=False) if len(pts) > 1 else np.zeros(3)
    scale = max(float(sv[0]) if len(sv) else 0.0, 1e-12)
    rank = int(np.sum(sv > 1e-6 * scale)) if len(pts) > 1 else 0
    if len(pts) > 1 and rank <= 1:
        why.append(
            "all sensor positions are collinear: rotation about that line and the centripetal terms "
            "along it are not observable"
        )
    elif len(pts) > 2 and rank == 2:
        why.append(
            "all sensor positions are coplanar: the angular acceleration and quadratic terms that act "
            "normal to the plane are not separable"
        )
    if len(dirs) < 12:
        why.append(f"only {len(dirs)} measured axes for 12 unknowns (f_O, ω̇, six ω-products)")
    dset = np.unique(np.round(dirs, 9), axis=0)
    if len(dset) < 3:
        why.append("the sensitive axes span fewer than three directions")
    return why


def check_layout(layout: Layout, noise: float = 0.01, refuse: bool = True) -> dict[str, Any]:
    """Observability and conditioning of a layout.

    Returns rank, condition number of A (columns scaled by the array size so metres do not matter), and the
    one-sigma error of each unknown per 1 m/s² of accelerometer noise (diag √((AᵀA)⁻¹)). A rank below 12 is
    refused (ImutoolError) with the geometric reason and the unobservable combinations; so is a geometry the
    linear algebra cannot decompose at all."""
    try:
        return _check_layout(layout, noise, refuse)
    except np.linalg.LinAlgError as e:
        raise ImutoolError(f"layout {layout.name}: geometry cannot be analysed ({e}); check the positions") from None


def check_columns(layout: Layout, rec: Recording) -> None:
    """Refuse a layout naming a column the recording lacks (one line naming them and what it has)."""
    flat = set(rec.channels)
    for name in rec.channels:
        flat.update(rec.columns.get(name, []))
    missing = [c for c in layout.rows()[2] if c not in flat]
    if missing:
        raise ImutoolError(
            f"layout {layout.name}: column(s) {', '.join(missing)} not in the recording "
            f"(has {', '.join(sorted(flat)[:20])})"
        )


def _check_layout(layout: Layout, noise: float, refuse: bool) -> dict[str, Any]:
    pos, dirs, cols, _ = layout.rows()
    if len(set(cols)) < len(cols):
        dup = sorted({c for c in cols if cols.count(c) > 1})
        raise ImutoolError(f"layout {layout.name}: column(s) used twice: {', '.join(dup)}")
    a = design_matrix(pos, dirs)
    size = float(np.max(np.linalg.norm(pos - pos.mean(0), axis=1))) or 1.0
    sc = np.ones(12)
    sc[3:] = 1.0 / size  # unknowns × size are accelerations: compare like with like
    an = a * (1.0 / sc)
    sv = np.linalg.svd(an, compute_uv=False)
    rank = int(np.sum(sv > 1e-9 * sv[0])) if len(sv) else 0
    out: dict[str, Any] = {
        "layout": layout.name,
        "measured_axes": int(len(dirs)),
        "rank": rank,
        "unknowns": 12,
        "array_size_m": round(size, 4),
    }
    if rank < 12:
        _, _, vt = np.linalg.svd(an)
        null = vt[rank:]
        terms = []
        for v in null[:3]:
            big = np.argsort(-np.abs(v))[:3]
            terms.append(" + ".join(f"{v[j]:+.2f}·{UNKNOWNS[j]}" for j in big if abs(v[j]) > 0.05))
        why = _geometry_diagnosis(pos, dirs) or ["the sensitive axes/positions do not separate all 12 unknowns"]
        if len(dirs) <= 3:
            why.append("for two parallel accelerometers across the roll axis use the planar mode (--planar)")
        out["observable"] = False
        out["reasons"] = why
        out["unobservable"] = terms
        if refuse:
            raise ImutoolError(
                f"layout {layout.name} is degenerate (rank {rank} < 12): {'; '.join(why)}; "
                f"unobservable: {' | '.join(terms)}"
            )
        return out
    cov = np.linalg.inv(a.T @ a)
    sd = np.sqrt(np.diag(cov))
    out["observable"] = True
    out["condition_number"] = float(sv[0] / sv[-1])
    out["noise_gain"] = {
        "f_O (m/s² per m/s²)": [round(float(v), 4) for v in sd[0:3]],
        "wdot (rad/s² per m/s²)": [round(float(v), 3) for v in sd[3:6]],
        "omega products (rad²/s² per m/s²)": [round(float(v), 3) for v in sd[6:12]],
    }
    out["per_noise_sigma"] = {
        "accel_noise_mps2": noise,
        "wdot_sigma_rad_s2": [round(float(v * noise), 4) for v in sd[3:6]],
    }
    return out


def solve_kinematics(y: np.ndarray, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares u = [f_O, ω̇, m] for every sample of y (N, M measured axes, m/s²).

    Returns f_O (N,3) m/s², ω̇ (N,3) rad/s², m (N,6) rad²/s², and (AᵀA)⁻¹ (12,12) (multiply by σ² for the
    covariance). Raises for a degenerate layout."""
    check_layout(layout)
    pos, dirs, _, _ = layout.rows()
    a = design_matrix(pos, dirs)
    pinv = np.linalg.pinv(a)
    u = np.asarray(y, float) @ pinv.T
    return u[:, 0:3], u[:, 3:6], u[:, 6:12], np.linalg.inv(a.T @ a)


def paper_closed_form(acc: np.ndarray, r: float) -> np.ndarray:
    """The paper's eq. 21 (four triads A1..A4 (N,4,3), m/s²; r m) → m₁..m₉ (N,9). Used to check the LS solution."""
    a1, a2, a3, a4 = (acc[:, i, :] for i in range(4))
    x, y, z = 0, 1, 2
    m = np.empty((acc.shape[0], 9))
    m[:, 0] = (a1[:, y] + a3[:, z] - a1[:, z] - a4[:, y]) / (2 * r)
    m[:, 1] = (a2[:, z] + a4[:, x] - a1[:, x] - a1[:, z]) / (2 * r)
    m[:, 2] = (a1[:, x] + a1[:, y] - a2[:, y] - a3[:, x]) / (2 * r)
    m[:, 3] = (-a4[:, z] + a1[:, z] - a2[:, x] + a1[:, x] - a3[:, y] + a1[:, y]) / (2 * r)
    m[:, 4] = (a1[:, z] - a4[:, z] + a2[:, x] - a1[:, x] + a3[:, y] - a1[:, y]) / (2 * r)
    m[:, 5] = (a2[:, x] - a1[:, x] - a1[:, z] + a4[:, z] - a3[:, y] + a1[:, y]) / (2 * r)
    m[:, 6] = (a3[:, x] - a1[:, x] + a1[:, y] - a2[:, y]) / (2 * r)
    m[:, 7] = (a4[:, x] - a1[:, x] - a2[:, z] + a1[:, z]) / (2 * r)
    m[:, 8] = (a3[:, z] - a1[:, z] - a1[:, y] + a4[:, y]) / (2 * r)
    return m


# ------------------------------------------------------------------------------------------------------------------
# EKF (paper eqs. 22–30)
# ------------------------------------------------------------------------------------------------------------------
@njit(cache=True)
def _ekf_kernel(dt, wdot, quad, qa, rq, w0, p0, q_rw):  # pragma: no cover - numba
    n = wdot.shape[0]
    w = w0.copy()
    p = p0.copy()
    out = np.empty((n, 3))
    sd = np.empty((n, 3))
    hm = np.zeros((6, 3))
    for k in range(n):
        if k > 0:
            d = dt[k]
            for i in range(3):
                w[i] += 0.5 * (wdot[k, i] + wdot[k - 1, i]) * d
            p = p + qa * (d * d) + np.eye(3) * (q_rw * d)
        wx, wy, wz = w[0], w[1], w[2]
        hx = np.array([wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz])
        hm[:, :] = 0.0
        hm[0, 0] = 2 * wx
        hm[1, 1] = 2 * wy
        hm[2, 2] = 2 * wz
        hm[3, 0] = wy
        hm[3, 1] = wx
        hm[4, 0] = wz
        hm[4, 2] = wx
        hm[5, 1] = wz
        hm[5, 2] = wy
        s = hm @ p @ hm.T + rq
        kg = np.linalg.solve(s, hm @ p).T  # 3×6 = P Hᵀ S⁻¹ (S symmetric)
        innov = quad[k] - hx
        w = w + kg @ innov
        ikh = np.eye(3) - kg @ hm
        p = ikh @ p @ ikh.T + kg @ rq @ kg.T  # Joseph form: stays symmetric positive definite
        out[k] = w
        for i in range(3):
            sd[k, i] = np.sqrt(max(p[i, i], 0.0))
    return out, sd


def initial_rate(quad: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """ω from the quadratic terms (6,) up to sign: the largest component from its square, the others from the
    cross products; ``sign`` fixes the sign of the largest component."""
    sq = np.maximum(quad[:3], 0.0)
    j = int(np.argmax(sq))
    wj = np.sqrt(sq[j])
    w = np.zeros(3)
    if wj < 1e-6:
        return w
    cross = {(0, 1): quad[3], (0, 2): quad[4], (1, 2): quad[5]}
    for i in range(3):
        w[i] = wj if i == j else cross[tuple(sorted((i, j)))] / wj
    return sign * w


def estimate_noise(y: np.ndarray, fs: float) -> float:
    """Accelerometer white-noise σ (m/s² per sample) from the high-frequency residual (second differences)."""
    d2 = np.diff(np.asarray(y, float), 2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) * 1.4826
    return float(np.median(mad) / np.sqrt(6.0))


def ekf_rates(
    t: np.ndarray,
    wdot: np.ndarray,
    quad: np.ndarray,
    cov_unit: np.ndarray,
    sigma: float,
    w0: np.ndarray | None = None,
    sign: float = 1.0,
    rate_rw: float = RATE_RW,
    init_samples: int = 20,
) -> tuple[np.ndarray, np.ndarray]:
    """ω (N,3) rad/s and its one-sigma (N,3) from the EKF; Q, R from σ² (AᵀA)⁻¹ (σ m/s² per sample)."""
    t = np.asarray(t, float)
    dt = np.diff(t, prepend=t[0])
    qa = cov_unit[3:6, 3:6] * sigma**2
    rq = cov_unit[6:12, 6:12] * sigma**2 + np.eye(6) * 1e-12
    if w0 is None:
        w0 = initial_rate(np.mean(quad[: max(1, init_samples)], axis=0), sign)
    p0 = np.eye(3) * max(1e-4, float(np.sqrt(np.mean(np.diag(rq)))))
    return _ekf_kernel(
        dt,
        np.ascontiguousarray(wdot),
        np.ascontiguousarray(quad),
        qa,
        rq,
        np.asarray(w0, float),
        p0,
        float(rate_rw) ** 2,
    )


# ------------------------------------------------------------------------------------------------------------------
# Planar (two-accelerometer) roll
# ------------------------------------------------------------------------------------------------------------------
def planar_roll(
    t: np.ndarray,
    a1: np.ndarray,
    a2: np.ndarray,
    p1: np.ndarray,
    p2: np.ndarray,
    d: np.ndarray,
    cutoff: float | None = None,
    causal: bool = False,
) -> dict[str, np.ndarray | float]:
    """Roll acceleration/rate/angle from two parallel single-axis accelerometers (m/s²) at p1, p2 (m, FRD) with
    the common sensitive axis d. a2 − a1 = ((p2 − p1) × d)·ω̇ (+ quadratic terms, neglected: second order for a
    rolling section); the component along the x axis gives ω̇x. Rate and angle by band-pass integration:
    zero-phase (default) or causal, cut-off ``cutoff`` Hz (default 0.3 × the dominant frequency).
    Returns roll_accel (rad/s²), roll_rate (rad/s), roll (rad), cutoff_hz."""
    from scipy import signal  # here: scipy.signal is heavy to import and only the planar mode needs it

    from imutool.heave import bandpass_integrator, dominant_frequency, heave_delayed  # noqa: PLC0415

    lever = np.cross(np.asarray(p2, float) - np.asarray(p1, float), np.asarray(d, float))
    if abs(lever[0]) < 1e-6:
        raise ImutoolError(
            "planar mode: the two accelerometers do not sense roll (need a separation across "
            "the x axis and a sensitive axis perpendicular to it)"
        )
    t = np.asarray(t, float)
    fs = 1.0 / float(np.median(np.diff(t)))
    alpha = (np.asarray(a2, float) - np.asarray(a1, float)) / lever[0]
    if cutoff is None:
        fd = dominant_frequency(alpha, fs, 0.03, min(5.0, 0.2 * fs))
        if fd is None:
            raise ImutoolError("planar mode: recording too short to find the dominant roll frequency")
        cutoff = 0.3 * fd
    if causal:
        sos = bandpass_integrator(fs, cutoff, 3)
        roll = signal.sosfilt(sos, alpha - alpha[0])
        rate = np.gradient(roll) * fs
    else:
        roll, rate, _ = heave_delayed(alpha, fs, cutoff)
        # heave_delayed returns −A/ω² as "displacement" of an up-positive acceleration: the same double integral
    return {"roll_accel": alpha, "roll_rate": rate, "roll": roll, "cutoff_hz": float(cutoff)}


# ------------------------------------------------------------------------------------------------------------------
# Driver
# ------------------------------------------------------------------------------------------------------------------
def measurements(rec: Recording, layout: Layout) -> np.ndarray:
    """(N, M) specific force along every measured axis, m/s², in layout row order."""
    _, _, cols, units = layout.rows()
    out = np.empty((len(rec), len(cols)))
    flat: dict[str, np.ndarray] = {}
    for name, arr in rec.channels.items():
        cn = rec.columns.get(name, [name])
        if arr.ndim == 1:
            flat[cn[0] if cn else name] = arr
            flat[name] = arr
        else:
            for j, c in enumerate(cn):
                flat[c] = arr[:, j]
    for j, (c, u) in enumerate(zip(cols, units, strict=True)):
        if c not in flat:
            raise ImutoolError(f"layout column {c!r} not in the recording (has {', '.join(list(flat)[:20])}...)")
        v = np.asarray(flat[c], float)
        out[:, j] = v if u in ("m/s^2", "m/s2") else convert(v, u, "m/s^2")
    return out


def gyrofree_recording(
    rec: Recording,
    layout: Layout,
    noise: float | None = None,
    sign: float = 1.0,
    w0: np.ndarray | None = None,
    tilt_gain: float = TILT_GAIN,
    rate_rw: float = RATE_RW,
) -> tuple[Recording, dict[str, Any]]:
    """Full gyro-free solution: gyro (ω, rad/s), angular_accel (rad/s²), accel (f_O, m/s²), ω one-sigma, q and
    roll/pitch/heading (deg) from quaternion integration (tilt-corrected with gain ``tilt_gain`` 1/s, 0 = off)."""
    from imutool.heave import complementary_attitude  # noqa: PLC0415

    y = measurements(rec, layout)
    if not np.all(np.isfinite(y)):
        raise ImutoolError(
            f"{int((~np.isfinite(y)).sum())} missing accelerometer values; gyro-free needs every "
            "axis at every sample (fill or trim the gaps first)"
        )
    f0, wdot, quad, cov = solve_kinematics(y, layout)
    fs = rec.rate_hz
    sigma = (
        float(noise)
        if noise
        else (layout.noise_density * np.sqrt(fs) if layout.noise_density else estimate_noise(y, fs))
    )
    w, sd = ekf_rates(rec.time, wdot, quad, cov, max(sigma, 1e-6), w0, sign, rate_rw)
    q = complementary_attitude(rec.time, w, f0, tilt_gain)
    roll, pitch, heading = quat_to_euler(q)
    out = Recording(rec.time.copy(), meta=input_notes(rec.meta))
    out.add("gyro", w, "rad/s")
    out.add("gyro_std", sd, "rad/s")
    out.add("angular_accel", wdot, "rad/s^2", columns=["angular_accel_x", "angular_accel_y", "angular_accel_z"])
    out.add("accel", f0, "m/s^2")
    out.add("q", q)
    out.add("roll", np.degrees(roll), "deg")
    out.add("pitch", np.degrees(pitch), "deg")
    out.add("heading", np.degrees(heading), "deg")
    for name in ("ref_gyro", "ref_q", "ref_roll", "ref_pitch", "ref_heading"):
        if name in rec:
            out.add(name, rec[name], rec.units.get(name))
    summary = {
        "layout": layout.name,
        "measured_axes": int(y.shape[1]),
        "noise_sigma_mps2": round(sigma, 6),
        "initial_rate_rad_s": [round(float(v), 5) for v in w[0]],
        "attitude": f"quaternion integration of ω, tilt gain {tilt_gain} 1/s",
    }
    out.meta.update({"gyrofree_layout": layout.name, "frame": "body FRD; q body->NED"})
    return out, summary


def degenerate_examples() -> dict[str, Layout]:
    """Layouts that must be refused (used by tests and docs)."""
    eye = np.eye(3)

    def tri(name, p, i):
        return Sensor(name, np.array(p, float), eye, [f"s{i}_{c}" for c in "xyz"])

    collinear = Layout(
        [tri("A", (0, 0, 0), 1), tri("B", (0.1, 0, 0), 2), tri("C", (0.2, 0, 0), 3), tri("D", (-0.1, 0, 0), 4)],
        name="collinear",
    )
    dup = Layout(
        [tri("A", (0, 0, 0), 1), tri("B", (0.1, 0, 0), 2), tri("C", (0.1, 0, 0), 3), tri("D", (0, 0.1, 0), 4)],
        name="duplicated",
    )
    return {"collinear": collinear, "duplicated": dup}


def plot_rates(out: Recording, path: str, title: str = "gyro-free angular rate vs truth") -> None:
    """PNG/PDF of ω estimate vs ``ref_gyro`` (rad/s) and the error per axis."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from formats.atomic import atomic_path  # noqa: PLC0415

    if "ref_gyro" not in out:
        raise ImutoolError("plot needs ref_gyro (truth) in the output")
    fig, ax = plt.subplots(3, 2, figsize=(11, 7), sharex=True)
    for i, n in enumerate("xyz"):
        ax[i, 0].plot(out.time, out["ref_gyro"][:, i], "k-", lw=2, label="truth")
        ax[i, 0].plot(out.time, out["gyro"][:, i], "C0-", lw=0.8, label="EKF")
        ax[i, 0].set_ylabel(f"ω{n} rad/s")
        e = out["gyro"][:, i] - out["ref_gyro"][:, i]
        ax[i, 1].plot(out.time, e, "C3-", lw=0.7)
        ax[i, 1].fill_between(out.time, -out["gyro_std"][:, i], out["gyro_std"][:, i], color="C3", alpha=0.2)
        ax[i, 1].set_ylabel(f"error rad/s (RMS {np.sqrt(np.mean(e**2)):.4f})")
    ax[0, 0].legend()
    ax[2, 0].set_xlabel("time s")
    ax[2, 1].set_xlabel("time s (band: EKF 1σ)")
    fig.suptitle(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=str(path).rsplit(".", 1)[-1], dpi=90)
    plt.close(fig)
