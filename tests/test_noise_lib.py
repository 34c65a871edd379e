"""imutool.noise.allan_noise: the route behind `imutool allan`, from Python, gives the CLI's files and summary."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_main

import formats
from calibration.noise_file import load_noise
from formats.errors import ImutoolError
from imutool.noise import allan_noise


def test_python_allan_equals_cli_and_recovers_the_noise(tmp_path, capsys):
    fs, n_d, hours = 50.0, 2e-3, 0.25  # gyro white noise 2e-3 rad/s/√Hz
    n = int(hours * 3600 * fs)
    rng = np.random.default_rng(3)
    rec = formats.Recording(np.arange(n) / fs)
    rec.add("gyro", rng.normal(0, n_d * np.sqrt(fs), (n, 3)))
    src = tmp_path / "static.csv"
    formats.write(rec, src)
    code, out, err = run_main(["allan", src, "-o", tmp_path / "cli.yaml", "--channels", "gyro", "--json"], capsys)
    assert code == 0, err
    stages: list[str] = []
    run = allan_noise(src, tmp_path / "lib.yaml", channels="gyro", stage=stages.append)
    assert stages == ["reading static.csv", "Allan deviation of gyro", "writing"]
    assert load_noise(tmp_path / "cli.yaml") == load_noise(tmp_path / "lib.yaml")
    lib = json.loads(json.dumps(run.summary, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
    cli = json.loads(out)
    assert lib.pop("output") == str(tmp_path / "lib.yaml") and cli.pop("output") == str(tmp_path / "cli.yaml")
    assert lib == {k: cli[k] for k in lib}
    assert run.values["gyro_noise_density"] == pytest.approx(n_d, rel=0.1)


def test_refusals(tmp_path):
    with pytest.raises(ImutoolError, match=".yaml"):
        allan_noise("x.csv", tmp_path / "noise.json")
    with pytest.raises(ImutoolError, match="unknown channel"):
        allan_noise("x.csv", tmp_path / "noise.yaml", channels="temp")
