"""imutool events: parametric roll detected with its onset (and a normal sea of the same severity not), heavy-roll
events, hourly MSC.363 statistics, the fleet table through a batch."""

from __future__ import annotations

import json

import numpy as np
import pytest

import formats
from formats import Recording
from imutool import events
from imutool.cli import main
from imutool.roll import roll_cycles
from imutool.sim import simulate


def _para(rec: Recording, **kw) -> list[dict]:
    res = events.analyse(rec, roll_channel="ref_roll", pitch_channel=kw.pop("pitch", "ref_pitch"), **kw)
    return [e for e in res["events"] if e["type"] == "parametric_roll"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_parametric_roll_detected_with_onset(seed):
    rec = simulate("parametric-roll", duration=800.0, rate_hz=10.0, seed=seed)
    t_roll, onset, rate = rec.meta["roll_period_s"], rec.meta["onset_s"], rec.meta["growth_rate_per_s"]
    eps = _para(rec)
    assert len(eps) == 1
    e = eps[0]
    assert abs(e["t_onset"] - onset) <= 1.5 * t_roll  # within 1.5 roll periods (30 s) of the true onset
    assert abs(e["period_ratio"] - 2.0) < 0.05 and abs(e["period_s"] - t_roll) < 0.5
    assert abs(e["encounter_period_s"] - rec.meta["encounter_period_s"]) < 0.3
    assert e["phase_lock"] > 0.9
    assert abs(e["growth_rate_per_s"] - rate) < 0.25 * rate
    assert abs(e["peak_deg"]) > 0.95 * rec.meta["max_roll_deg"]


def test_parametric_roll_from_heave_and_other_settings():
    rec = simulate(
        "parametric-roll",
        duration=700.0,
        rate_hz=10.0,
        seed=3,
        onset_s=200.0,
        growth_rate=0.05,
        encounter_period_s=8.0,
        max_roll_deg=35.0,
    )
    rec.remove("ref_pitch")
    res = events.analyse(rec, roll_channel="ref_roll", heave_channel="ref_heave")
    (e,) = [e for e in res["events"] if e["type"] == "parametric_roll"]
    assert res["wave_channel"] == "ref_heave"
    assert abs(e["t_onset"] - 200.0) <= 1.5 * 16.0 and abs(e["period_s"] - 16.0) < 0.5


@pytest.mark.parametrize(
    "name,opts",
    [
        ("ship-at-sea", {}),  # irregular sea, roll 19° at 12 s, pitch 8 s
        ("ship-at-sea", {"roll_period": 16.0, "pitch_period": 8.0}),  # tuned 2:1 but a linear (unlocked) response
        ("ship-roll", {"roll_period_s": 14.0, "pitch_period_s": 7.0}),  # steady 15° roll at exactly 2 × pitch period
        ("parametric-roll", {"onset_s": 1e9}),  # tuned background roll, never growing
    ],
)
def test_normal_sea_not_detected(name, opts):
    for seed in (0, 1):
        rec = simulate(name, duration=800.0, rate_hz=10.0, seed=seed, **opts)
        assert _para(rec) == [], (name, opts, seed)
    if name == "ship-at-sea":  # the same severity as the parametric case: roll near 20°
        assert np.nanmax(np.abs(rec["ref_roll"])) > 18.0


def test_detector_refuses_growth_without_tuning():
    # growing roll but at 1.4 × the encounter period: not parametric (frequency condition)
    rec = simulate("parametric-roll", duration=800.0, rate_hz=10.0, seed=0, roll_ratio=1.4)
    assert _para(rec) == []
    assert _para(rec, tuning_tol=0.5) == []  # the phase lock refuses it too (2·ω_roll ≠ ω_e)
    assert len(_para(rec, tuning_tol=0.5, min_lock=0.0)) == 1  # only these two criteria refused it


def _bursts(fs: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0, 900, 1 / fs)
    x = 3.0 * np.sin(2 * np.pi * t / 10.0)
    for t0, amp in ((100.0, 25.0), (400.0, -32.0)):
        m = (t >= t0) & (t < t0 + 60.0)
        x[m] = amp * np.sin(2 * np.pi * (t[m] - t0) / 10.0)
    return t, x


def test_heavy_roll_events():
    t, x = _bursts()
    cyc = roll_cycles(t, x)
    ev = events.heavy_roll_events(t, x, cyc, threshold_deg=20.0, merge_gap_s=30.0)
    assert len(ev) == 2
    a, b = ev
    assert a["peak_deg"] == pytest.approx(25.0, abs=0.05) and b["peak_deg"] == pytest.approx(-32.0, abs=0.05)
    assert b["side"] == "port" and a["side"] == "starboard"
    assert a["crossings"] == 12 and b["crossings"] == 12  # twice per 10 s cycle for 60 s
    assert a["period_s"] == pytest.approx(10.0, abs=0.05)
    assert 100.0 < a["t_start"] < 102.0 and 155.0 < a["t_end"] < 160.0
    # a merge gap shorter than the half-period splits into single crossings
    assert len(events.heavy_roll_events(t, x, cyc, 20.0, merge_gap_s=1.0)) == 24
    assert events.heavy_roll_events(t, x, cyc, threshold_deg=40.0) == []


def test_hourly_statistics_msc363():
    fs = 5.0
    t = np.arange(0, 3 * 3600, 1 / fs)
    amp = np.where(t < 3600, 5.0, np.where(t < 7200, 12.0, 8.0))
    x = amp * np.sin(2 * np.pi * t / 8.0) + 1e-9
    cyc = roll_cycles(t, x)
    start = events.utc_start_of(Recording(t[:1]), "2025-02-01T09:30:00Z")
    rows = events.hourly_statistics(t, x, cyc, [], 3600.0, start)
    # aligned to the UTC hour: 09:30–10:00, 10:00–11:00, 11:00–12:00, 12:00–12:30
    assert [r["utc_start"] for r in rows] == [
        "2025-02-01T09:00:00Z",
        "2025-02-01T10:00:00Z",
        "2025-02-01T11:00:00Z",
        "2025-02-01T12:00:00Z",
    ]
    assert [r["amplitude_stbd_max_deg"] for r in rows] == pytest.approx([5.0, 12.0, 12.0, 8.0], abs=0.05)
    assert rows[1]["amplitude_port_mean_deg"] == pytest.approx((5.0 + 12.0) / 2, abs=0.5)  # half an hour each
    for r in rows:
        assert r["period_stbd_mean_s"] == pytest.approx(8.0, abs=0.01)
        assert r["period_port_mean_s"] == pytest.approx(8.0, abs=0.01)
    assert rows[0]["rms_heel_deg"] == pytest.approx(5.0 / np.sqrt(2), rel=0.01)
    assert sum(r["samples"] for r in rows) == t.size


def _run(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main(args)
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


def test_batch_then_fleet_table_and_plot(tmp_path, capsys):
    root = tmp_path / "fleet"
    specs = [
        ("Aurora", "V001", "parametric-roll", {}),
        ("Aurora", "V002", "ship-at-sea", {}),
        ("Borealis", "V017", "parametric-roll", {"onset_s": 150.0}),
    ]
    for k, (ship, voyage, scen, opts) in enumerate(specs):
        rec = simulate(scen, duration=700.0, rate_hz=5.0, seed=k, **opts)
        rec.meta["utc_start"] = f"2025-0{k + 1}-10T06:00:00Z"
        (root / ship).mkdir(parents=True, exist_ok=True)
        formats.write(rec, root / ship / f"{voyage}.csv")
    code, out, err = _run(
        [
            "batch",
            "events detect",
            str(root),
            "-o",
            str(tmp_path / "ev" / "{parent}_{stem}.json"),
            "--args",
            "--roll-channel ref_roll --pitch-channel ref_pitch",
            "-j",
            "1",
            "--figure",
            "parametric_roll_episodes",
            "--figure",
            "max_heel_deg",
        ],
        capsys,
    )
    assert code == 0, err + out
    one = json.loads((tmp_path / "ev" / "Aurora_V001.json").read_text())
    assert one["ship"] == "Aurora" and one["voyage"] == "V001" and one["summary"]["parametric_roll_episodes"] == 1
    assert one["hourly"] and one["hourly"][0]["utc_start"] == "2025-01-10T06:00:00Z"
    code, out, err = _run(
        [
            "events",
            "fleet",
            str(tmp_path / "ev"),
            "-o",
            str(tmp_path / "fleet.csv"),
            "--voyages",
            str(tmp_path / "voyages.csv"),
            "--plot",
            str(tmp_path / "fleet.png"),
            "--json",
        ],
        capsys,
    )
    assert code == 0, err
    s = json.loads(out)
    assert s["ships"] == 2 and s["voyages"] == 3 and s["parametric_roll_episodes"] == 2
    import csv

    with open(tmp_path / "fleet.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    para = [r for r in rows if r["type"] == "parametric_roll"]
    assert {(r["ship"], r["voyage"], r["month"]) for r in para} == {
        ("Aurora", "V001", "2025-01"),
        ("Borealis", "V017", "2025-03"),
    }
    with open(tmp_path / "voyages.csv", newline="") as f:
        voy = {r["voyage"]: r for r in csv.DictReader(f)}
    assert abs(float(voy["V001"]["worst_roll_deg"])) > 24 and 17 < abs(float(voy["V002"]["worst_roll_deg"])) < 21
    assert (tmp_path / "fleet.png").stat().st_size > 10_000


def test_errors(tmp_path, capsys):
    rec = Recording(np.arange(100.0), {"accel": np.zeros((100, 3))})
    formats.write(rec, tmp_path / "noroll.csv")
    code, _, err = _run(["events", "detect", str(tmp_path / "noroll.csv")], capsys)
    assert code == 2 and "needs a 'roll' or 'heel' channel" in err
    code, _, err = _run(["events", "fleet", str(tmp_path / "noroll.csv"), "-o", str(tmp_path / "f.csv")], capsys)
    assert code == 2 and "not an events result" in err
    rec2 = Recording(np.arange(100.0), {"roll": np.zeros(100)})
    assert events.analyse(rec2)["notes"] == ["no pitch or heave channel: parametric roll not assessed"]
    with pytest.raises(formats.ImutoolError, match="no channel 'nope'"):
        events.analyse(rec2, pitch_channel="nope")
