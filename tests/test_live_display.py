"""The bridge display of `imutool live --http` in a real headless Chromium (Debian's, driven by selenium; no
browser is downloaded): the heel shown equals the recorded estimate at the snapshot's time, a peak-hold reset
through the page (with its confirmation), status V when the replay stops, and the page reconnecting by itself
when the server comes back. ``IMUTOOL_SCREENSHOTS=DIR`` also saves a screenshot of each palette in DIR."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

import formats
from imutool.sim import run_simulate

pytest.importorskip("aiohttp", reason="the bridge display needs aiohttp (imutool[live])")
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium (test extra) drives the system Chromium")

CHROMIUM = os.environ.get("IMUTOOL_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = os.environ.get("IMUTOOL_CHROMEDRIVER") or shutil.which("chromedriver")
pytestmark = pytest.mark.skipif(
    not (CHROMIUM and DRIVER),
    reason="no system Chromium + chromedriver (Debian: apt-get install chromium chromium-driver)",
)
ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_live(csv: Path, port: int, record: Path, duration: float, log: Path, out: tuple = ()) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    args = [sys.executable, "-c", "from imutool.cli import main; main()", "live", "--replay", str(csv), "--speed",
            "2", "--motion", "ship", "--settle", "5", "--http", f"127.0.0.1:{port}", "--record", str(record),
            "--duration", str(duration), *out]  # fmt: skip
    return subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=open(log, "w"), cwd=ROOT)


@pytest.fixture(scope="module")
def ship_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("ship") / "ship.csv"
    run_simulate("ship-roll", path, seed=7, duration=240.0, rate_hz=50.0)
    return path


@pytest.fixture
def browser(tmp_path):
    from selenium.webdriver.chrome.service import Service

    os.environ["SE_OFFLINE"] = "true"  # selenium-manager never downloads anything
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              f"--user-data-dir={tmp_path / 'chromium'}", "--window-size=1280,800", "--hide-scrollbars"):  # fmt: skip
        opts.add_argument(a)
    drv = webdriver.Chrome(service=Service(DRIVER), options=opts)
    # a 10-inch 1280 x 800 screen
    drv.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride", {"width": 1280, "height": 800, "deviceScaleFactor": 1, "mobile": False}
    )
    yield drv
    drv.quit()


def wait_for(fn, timeout: float, what: str):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = fn()
        if v:
            return v
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


READ = """const e = (id) => document.getElementById(id);
return [e('heel-value').textContent, e('heel-side').textContent.trim(), e('heel').dataset.t, e('status').dataset.status,
        e('status-cause').textContent, e('peak-port').textContent, e('peak-stbd').textContent,
        e('peak-reset').textContent, window.imutoolDisplay.messages, window.imutoolDisplay.connected];"""


def read_page(drv) -> dict:
    v = drv.execute_script(READ)
    keys = ("heel", "side", "t", "status", "cause", "peak_p", "peak_s", "reset", "messages", "connected")
    out = dict(zip(keys, v, strict=True))
    out["heel_deg"] = (-1.0 if out["side"] == "P" else 1.0) * float(out["heel"]) if out["heel"] != "--.-" else None
    return out


def estimates(folder: Path):
    files = sorted(folder.glob("estimate_*.csv"))
    assert files, "no estimate file recorded"
    return formats.read(files[0])


def test_bridge_display_in_chromium(ship_csv, browser, tmp_path):
    port = free_port()
    rec = tmp_path / "rec"
    log = tmp_path / "live.log"
    hrm = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # the HRM sentences (the reset goes to the VDR)
    hrm.bind(("127.0.0.1", 0))
    hrm.settimeout(0.2)
    out = ("--out", f"udp://127.0.0.1:{hrm.getsockname()[1]}", "--sentences", "HRM")
    proc = start_live(ship_csv, port, rec, 70.0, log, out)
    try:
        url = f"http://127.0.0.1:{port}/"
        wait_for(lambda: _get(browser, url), 60, "the page to load")
        wait_for(lambda: read_page(browser)["status"] == "A", 90, "status A on the page")
        # the heel shown, and the snapshot time it belongs to
        shown = []
        for _ in range(12):
            p = read_page(browser)
            shown.append((float(p["t"]), p["heel_deg"]))
            time.sleep(0.23)
        assert len({t for t, _ in shown}) >= 8, "the page did not update"

        shots = os.environ.get("IMUTOOL_SCREENSHOTS")
        if shots:
            _screenshots(browser, Path(shots))

        # peak-hold reset through the page, with its confirmation
        before = read_page(browser)
        assert max(float(before["peak_p"]), float(before["peak_s"])) > 1.0, before
        browser.find_element("id", "reset").click()
        assert browser.find_element("id", "confirm").is_displayed()
        clicked = time.time()
        browser.find_element("id", "confirm-yes").click()
        after = wait_for(
            lambda: (p := read_page(browser))["reset"] != before["reset"] and p, 10, "the reset's UTC on the page"
        )
        t_reset = float(after["t"])
        reset_utc = datetime.strptime(after["reset"], "%Y-%m-%d %H:%M:%S UTC").replace(tzinfo=timezone.utc).timestamp()
        assert clicked - 2.0 <= reset_utc <= clicked + 5.0
        time.sleep(3.0)
        later = read_page(browser)

        # the source stops: status V with the reason
        proc.wait(timeout=120)
        stopped = wait_for(lambda: (p := read_page(browser))["status"] == "V" and p, 10, "status V after the stop")
        assert "stopped" in stopped["cause"] or "no connection" in stopped["cause"], stopped["cause"]
    finally:
        if proc.poll() is None:
            proc.kill()
    text = log.read_text()
    assert "peak-hold reset by the bridge display" in text, text[-2000:]
    hrm_lines = []
    try:
        while True:
            hrm_lines += hrm.recv(65536).decode().splitlines()
    except TimeoutError:
        hrm.close()
    stamp = datetime.strptime(after["reset"], "%Y-%m-%d %H:%M:%S UTC")
    fields = [ln.split("*")[0].split(",") for ln in hrm_lines if ln.startswith("$IIHRM")]
    assert fields and any(f[8] == stamp.strftime("%H%M%S") and f[9] == f"{stamp.day:02d}" for f in fields), fields[-3:]

    est = estimates(rec)
    t_est, roll = est.time, est["roll"]
    for t, heel in shown:
        i = int(np.argmin(np.abs(t_est - t)))
        assert abs(t_est[i] - t) < 1e-3
        assert abs(heel - roll[i]) <= 0.1, (t, heel, roll[i])
    # the peak-hold after the reset: the largest heel to each side since the reset (within a block of it), at
    # the first snapshot carrying the reset (both sides: the peaks of before cannot pass) and 3 s later
    for page in (after, later):
        t_page = float(page["t"])
        win_wide = (t_est >= t_reset - 0.5) & (t_est <= t_page)
        win_narrow = (t_est >= t_reset + 0.5) & (t_est <= t_page - 0.2)
        for shown_peak, sign in ((float(page["peak_s"]), 1.0), (float(page["peak_p"]), -1.0)):
            hi = max(0.0, float(np.max(sign * roll[win_wide])))
            lo = max(0.0, float(np.max(sign * roll[win_narrow]))) if win_narrow.any() else 0.0
            assert lo - 0.06 <= shown_peak <= hi + 0.06, (sign, shown_peak, lo, hi)

    # the server comes back: the page reconnects by itself and shows the new run
    proc2 = start_live(ship_csv, port, tmp_path / "rec2", 30.0, tmp_path / "live2.log")
    try:
        back = wait_for(
            lambda: (p := read_page(browser))["connected"] and float(p["t"] or 1e9) < 25.0 and p, 60, "reconnection"
        )
        assert back["messages"] > stopped["messages"]
    finally:
        proc2.kill()
        proc2.wait(timeout=30)


def _get(drv, url: str) -> bool:
    try:
        drv.get(url)
    except Exception:
        return False
    return drv.execute_script("return !!window.imutoolDisplay")


def _screenshots(drv, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("day", "dusk", "night"):
        drv.find_element("css selector", f"#palettes button[data-palette='{name}']").click()
        time.sleep(0.4)
        drv.save_screenshot(str(folder / f"bridge_{name}.png"))
    drv.find_element("css selector", "#palettes button[data-palette='day']").click()
