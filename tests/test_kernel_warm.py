"""A cold first run compiles on two cores: the filter's helpers in a second process (formats/jit/warm.py).

The slow test records what a cold ``imutool filter --smooth`` really compiles (numba's compile events, in a
subprocess with an empty cache and no warming) and checks that :mod:`imutool.filter_warm` lists every cached
function of it with the argument types it was called with: a helper added to the EKF without its entry, or a
changed argument list, names itself here. The quick tests check the process's own work: what it compiles is
loaded, not compiled again, by the next process.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from conftest import EKF_KERNEL_ASM, normalized_asm

import formats.jit.warm as kw
from formats.jit import claims
from formats.jit.warm import CSV_READER, CSV_WRITER
from imutool.attitude.kernel import ekf_kernel
from imutool.filter_warm import AFTER_THE_EKF, EKF_SECTIONS, HEADING_SECTION, SMOOTH_KERNELS
from imutool.roll_period import ROLL_KERNEL

ALL = AFTER_THE_EKF + (CSV_WRITER,) + SMOOTH_KERNELS  # the filter's, beside its sections

ROOT = Path(__file__).resolve().parents[1]


def _env(tmp_path: Path, **extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "IMUTOOL_KERNEL_TIMES")}
    env["PYTHONPATH"] = str(ROOT)  # this tree's packages in every subprocess, whatever its working folder
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba")
    env.update(extra)
    return env


def _python(args: list[str], cwd: Path, env: dict, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *args], input=stdin, env=env, cwd=cwd, capture_output=True, text=True, timeout=900
    )


def test_every_entry_is_in_signature_syntax():
    for module, name, text in (*ALL, *EKF_SECTIONS, HEADING_SECTION, CSV_READER, ROLL_KERNEL):
        types = kw.argument_types(text)
        assert ", ".join(kw.type_text(t) for t in types) == text, (module, name)
    assert kw.type_text(kw.argument_types("float64[:, :, ::1]")[0]) == "float64[:, :, ::1]"


def test_no_second_process_when_switched_off_cached_or_one_thread(monkeypatch):
    monkeypatch.setattr(kw, "_STARTED", set())  # each refusal below is for its own reason, not "started already"
    monkeypatch.setenv(kw.ENV_SWITCH, "0")
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is None
    monkeypatch.delenv(kw.ENV_SWITCH)
    monkeypatch.setenv("IMUTOOL_THREADS", "1")  # a batch worker's share of one core
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is None
    monkeypatch.delenv("IMUTOOL_THREADS")
    monkeypatch.setattr(kw, "_busy_cores", lambda: 64.0)  # every core busy: it would only slow the command
    monkeypatch.setattr(kw, "is_cached", lambda probe: False)
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is None
    monkeypatch.setattr(kw, "_busy_cores", lambda: 0.0)
    monkeypatch.setattr(kw, "is_cached", lambda probe: True)
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is None


def test_busy_cores_is_the_lower_of_the_mean_and_the_processes_running_now(monkeypatch, tmp_path):
    """The 1-minute mean lags behind a command that just ended; the running count (this process left out) does
    not. A machine busy now stays busy by both."""
    monkeypatch.setattr(kw.os, "getloadavg", lambda: (2.4, 1.0, 0.5))
    just_ended = tmp_path / "loadavg"
    just_ended.write_text("2.40 1.00 0.50 1/345 6789\n")  # only this process runs now
    assert kw._busy_cores(str(just_ended)) == 0.0
    busy = tmp_path / "busy"
    busy.write_text("2.40 1.00 0.50 4/345 6789\n")  # three others running: busy by both
    assert kw._busy_cores(str(busy)) == 2.4
    assert kw._busy_cores(str(tmp_path / "absent")) == 2.4  # no /proc: the mean


def test_the_commands_meanwhile_waits_until_the_probe_is_cached(monkeypatch):
    """Where the command meets the second process among the probe's parts it compiles no later kernel (that would
    put its time before the probe's own): the meanwhile answers None until the probe is cached, then compiles."""
    cached = {"probe": False}
    compiled = []
    monkeypatch.setattr(kw, "is_cached", lambda entry: cached["probe"] if entry == ("m", "probe", "") else False)
    monkeypatch.setattr(kw, "compile_entries", lambda entries, parent=None: compiled.extend(entries) or 1)
    work = kw._one_at_a_time([("m", "a", ""), ("m", "b", "")], after=("m", "probe", ""))
    assert work() is None and not compiled
    cached["probe"] = True
    assert work() is True and compiled == [("m", "a", "")]
    assert work() is True and work() is False
    assert kw._one_at_a_time([("m", "a", "")])() is True  # without a probe: at once


def test_once_per_process_and_never_in_a_pool_worker(monkeypatch):
    started = []

    class FakePopen:
        pid = -1

        def __init__(self, args, **kw):
            started.append(args)
            self.stdin = open(os.devnull, "wb")  # noqa: SIM115 - closed by warm_in_background

        def poll(self):
            return 0

    monkeypatch.setattr(kw.subprocess, "Popen", FakePopen)
    monkeypatch.setattr(kw, "_busy_cores", lambda: 0.0)
    monkeypatch.setattr(kw, "is_cached", lambda probe: False)
    monkeypatch.setattr(kw, "thread_budget", lambda: 2)
    monkeypatch.setattr(kw, "_STARTED", set())
    monkeypatch.delenv(kw.ENV_SWITCH, raising=False)
    monkeypatch.setattr(kw.multiprocessing, "parent_process", lambda: object())  # a batch pool's worker
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is None and started == []
    monkeypatch.setattr(kw.multiprocessing, "parent_process", lambda: None)
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is not None
    assert kw.warm_in_background(ekf_kernel, AFTER_THE_EKF) is None  # a cache that stays cold: not again
    assert len(started) == 1 and started[0][1] == "-c"  # our packages first on sys.path, not `-m` from a cwd
    claims.stop_sharing()  # the fake second process shares nothing


def test_the_second_process_stops_once_its_command_is_gone(monkeypatch):
    """A command killed by a signal runs no exit handler: its second process notices its parent changed and stops
    before the next entry."""
    asked = []
    monkeypatch.setattr(kw.importlib, "import_module", lambda name: asked.append(name) or os)
    entries = [("m1", "getpid", ""), ("m2", "getpid", "")]
    assert kw.compile_entries(entries, parent=os.getppid()) == 0 and asked == ["m1", "m2"]  # os.getpid: no compile
    asked.clear()
    assert kw.compile_entries(entries, parent=os.getppid() + 1) == 0 and asked == []


ORPHAN = textwrap.dedent(
    """
    import os
    from formats.jit.warm import warm_in_background
    from imutool.attitude.kernel import ekf_kernel
    from imutool.filter_warm import EKF_SECTIONS
    proc = warm_in_background(ekf_kernel, tuple(reversed(EKF_SECTIONS)), splits_probe=True)
    assert proc is not None
    print(proc.pid, flush=True)
    os._exit(0)  # as a command killed by a signal: no exit handler kills the second process
    """
)


def _ended(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state in ("Z", "X")  # a zombie: ended, not reaped by a container's init


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_a_killed_commands_second_process_compiles_nothing_more(tmp_path):
    """The command is gone before its second process has imported numba: that process compiles no entry."""
    env = _env(tmp_path, **{kw.ENV_SWITCH: "1"})
    r = _python(["-c", ORPHAN], ROOT, env)
    assert r.returncode == 0, r.stderr
    pid = int(r.stdout.split()[0])
    for _ in range(1200):  # up to 120 s; it ends within its start-up (~2 s)
        if _ended(pid):
            break
        time.sleep(0.1)
    assert _ended(pid)
    compiled = sorted(p.name for p in (tmp_path / "numba").rglob("*.nbi"))
    assert compiled == [], compiled  # the sections take ~15 s; a second process that went on would leave them


START = textwrap.dedent(
    """
    from formats.jit.warm import warm_in_background
    from imutool.attitude.kernel import ekf_kernel
    from imutool.filter_warm import AFTER_THE_EKF
    proc = warm_in_background(ekf_kernel, AFTER_THE_EKF[:1])
    assert proc is not None
    assert proc.wait() == 0
    """
)


def test_the_second_process_uses_the_parents_folder_for_a_tilde_cache_dir(tmp_path):
    """NUMBA_CACHE_DIR='~/nc' in a user's folder: the kernels land in ~/nc, nothing in the working folder."""
    work, home = tmp_path / "work", tmp_path / "home"
    work.mkdir()
    home.mkdir()
    env = _env(tmp_path, NUMBA_CACHE_DIR="~/nc", HOME=str(home), **{kw.ENV_SWITCH: "1"})
    r = _python(["-c", START], work, env)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert list(home.glob("nc/imutool/kernels-*/imutool/gyro_check.pair_discrepancy_kernel-*.nbi")), sorted(
        p.as_posix() for p in tmp_path.rglob("*")
    )
    assert list(work.iterdir()) == []


WAIT = textwrap.dedent(
    """
    import subprocess, sys
    from formats.jit.warm import argument_types, is_cached, wait_for, warm_in_background
    from imutool.gyro_check import pair_discrepancy_kernel as kernel
    from imutool.filter_warm import AFTER_THE_EKF
    assert not is_cached(kernel)
    proc = warm_in_background(kernel, AFTER_THE_EKF[:1])  # the second process compiles the kernel
    assert proc is not None
    print(wait_for(kernel, proc), is_cached(kernel))
    misses = sum(kernel.stats.cache_misses.values())
    kernel.compile(argument_types(AFTER_THE_EKF[0][2]))
    print(sum(kernel.stats.cache_misses.values()) - misses, sum(kernel.stats.cache_hits.values()))
    quit = subprocess.Popen([sys.executable, "-c", "pass"])  # a second process that ends without it
    from imutool.attitude.kernel import ekf_kernel
    print(wait_for(ekf_kernel, quit), wait_for(ekf_kernel, None))
    """
)


def test_a_command_waits_for_the_kernel_the_second_process_compiles(tmp_path):
    """ins: the second process compiles the main kernel; the command waits for it, says so, and loads it."""
    r = _python(["-c", WAIT], ROOT, _env(tmp_path, **{kw.ENV_SWITCH: "1"}))
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "True", "0", "1", "False", "False"], r.stdout
    assert r.stderr.count("imutool: compiling the filter's kernels") == 1, r.stderr  # announced while waiting


CHECK = textwrap.dedent(
    """
    import importlib, sys
    from formats.jit.warm import argument_types
    for line in sys.stdin.read().splitlines():
        module, name, text = line.split("\\t")
        fn = getattr(importlib.import_module(module), name)
        fn.compile(argument_types(text))
        print(name, fn.stats.cache_hits.get(argument_types(text), 0), sum(fn.stats.cache_misses.values()))
    """
)


def test_what_the_second_process_compiles_the_next_one_loads(tmp_path):
    entries = [e for e in ALL if e[1] in ("pair_discrepancy_kernel", "zero_phase_lp_kernel")]
    assert len(entries) == 2
    env = _env(tmp_path)
    lines = "\n".join("\t".join(e) for e in entries)
    warm = _python(["-m", "formats.jit.warm"], ROOT, env, stdin=lines)
    assert warm.returncode == 0 and warm.stdout == "" and warm.stderr == "", warm.stderr
    r = _python(["-c", CHECK], tmp_path, env, stdin=lines)
    assert r.returncode == 0, r.stderr
    names = [e[1] for e in entries]
    assert r.stdout.split() == [names[0], "1", "0", names[1], "1", "0"], r.stdout  # loaded, not compiled
    assert "compiling" not in r.stderr, r.stderr


RECORD = textwrap.dedent(
    """
    import sys
    from numba.core import caching, event
    from formats.jit.warm import type_text
    FLAGS = ("fastmath", "error_model", "_nrt", "forceinline")
    seen, stack = [], []
    class Recorder(event.Listener):
        def on_start(self, ev):
            stack.append(ev.data["dispatcher"].py_func.__name__)
        def on_end(self, ev):
            stack.pop()
            d = ev.data["dispatcher"]
            if d.py_func.__module__.split(".")[0] in ("imutool", "formats", "calibration") and not isinstance(
                d._cache, caching.NullCache
            ):
                types = ", ".join(type_text(a) for a in ev.data["args"])
                caller = stack[-1] if stack else "-"
                states = "yes" if all(f in d.targetoptions for f in FLAGS) else "no"
                seen.append((caller, d.py_func.__module__, d.py_func.__name__, types, states))
    event.register("numba:compile", Recorder())
    from imutool.cli import main
    sys.argv = ["imutool", *sys.argv[1:]]
    try:
        main()
    except SystemExit as e:
        assert not e.code, e.code
    for entry in seen:
        print("\\t".join(entry))
    """
)


@pytest.mark.slow
def test_the_lists_are_what_a_cold_filter_compiles(tmp_path):
    """~40 s: one cold compile of the filter's kernels, with the smoother."""
    env = _env(tmp_path, **{kw.ENV_SWITCH: "0"})
    sim = ["-c", "from imutool.cli import main; main()", "simulate", "ship-roll", "--duration", "20", "-o", "r.csv"]
    sim_env = dict(env, NUMBA_CACHE_DIR=str(tmp_path / "numba-sim"))  # the filter's own cache stays empty
    assert _python(sim, tmp_path, sim_env).returncode == 0
    r = _python(["-c", RECORD, "filter", "r.csv", "-o", "est.csv", "--smooth", "-q"], tmp_path, env)
    assert r.returncode == 0, r.stderr
    rows = [tuple(line.split("\t")) for line in r.stdout.splitlines()]
    top = {row[1:4] for row in rows if row[0] == "-"}
    own = {e for e in top if e[1] in ("parse_block", "ekf_kernel")}  # the command's own: first and probe
    assert {e[1] for e in own} == {"parse_block", "ekf_kernel"}, sorted(top)
    listed = set(ALL)
    assert top - own - listed == set(), "compiled but not listed (add to imutool/filter_warm.py)"
    assert listed - top == set(), "listed but not compiled as listed (remove or correct the types)"
    sections = [row[1:4] for row in rows if row[0] == "ekf_kernel"]
    # no GNSS nor external heading in the input: their sections are left out of the kernel (kernel.py)
    assert sections == list(EKF_SECTIONS), "the EKF's sections, in the order it calls them, with their types"
    # every cached function the kernel reaches (its sections and their helpers) states the flags numba would
    # otherwise take from its caller: compiled alone by the second process, it is the code the kernel would compile
    inside = [row for row in rows if row[0] != "-"]
    assert len(inside) > len(sections), inside
    assert [row[2] for row in inside if row[4] != "yes"] == []


HEADING_FILE = textwrap.dedent(
    """
    import sys
    import formats
    rec = formats.read(sys.argv[1])
    with open(sys.argv[2], "w") as f:
        f.write("time,heading_true\\n")
        for t, h in zip(rec.time[::20], rec["ref_heading"][::20]):
            f.write(f"{float(t)!r},{float(h)!r}\\n")
    """
)


@pytest.mark.slow
def test_the_heading_section_is_what_a_cold_filter_with_heading_compiles(tmp_path):
    """~40 s: with --heading the kernel has the external heading's section (left out of the default kernel), called
    with the types listed, between the magnetometer's and the outputs."""
    env = _env(tmp_path, **{kw.ENV_SWITCH: "0"})
    sim = ["-c", "from imutool.cli import main; main()", "simulate", "ship-roll", "--duration", "20", "-o", "r.csv"]
    sim_env = dict(env, NUMBA_CACHE_DIR=str(tmp_path / "numba-sim"))
    assert _python(sim, tmp_path, sim_env).returncode == 0
    assert _python(["-c", HEADING_FILE, "r.csv", "h.csv"], tmp_path, sim_env).returncode == 0
    r = _python(["-c", RECORD, "filter", "r.csv", "-o", "est.csv", "--heading", "h.csv", "-q"], tmp_path, env)
    assert r.returncode == 0, r.stderr
    rows = [tuple(line.split("\t")) for line in r.stdout.splitlines()]
    sections = [row[1:4] for row in rows if row[0] == "ekf_kernel"]
    assert sections == [*EKF_SECTIONS[:-2], HEADING_SECTION, *EKF_SECTIONS[-2:]]


@pytest.mark.slow
def test_the_ins_kernel_entry_is_what_a_cold_ins_compiles(tmp_path):
    """~15 s: one cold `imutool ins`; its kernel is listed (imutool/ins.py:INS_KERNEL) with the types it is called
    with, so the second process compiles the kernel the command then loads."""
    from imutool.ins import INS_KERNEL

    env = _env(tmp_path, **{kw.ENV_SWITCH: "0"})
    sim = ["-c", "from imutool.cli import main; main()", "simulate", "walk", "--duration", "20", "-o", "w.csv"]
    assert _python(sim, tmp_path, dict(env, NUMBA_CACHE_DIR=str(tmp_path / "numba-sim"))).returncode == 0
    r = _python(["-c", RECORD, "ins", "w.csv", "-o", "track.csv", "--zupt", "-q"], tmp_path, env)
    assert r.returncode == 0, r.stderr
    top = {tuple(line.split("\t"))[1:4] for line in r.stdout.splitlines() if line.startswith("-\t")}
    assert INS_KERNEL in top, sorted(top)


@pytest.mark.slow
def test_the_heave_kernel_entries_are_what_a_cold_heave_compiles(tmp_path):
    """~15 s: one cold `imutool heave`; its kernels are listed (imutool/heave.py:HEAVE_KERNELS) with their types."""
    from imutool.heave import HEAVE_KERNELS

    env = _env(tmp_path, **{kw.ENV_SWITCH: "0"})
    sim = ["-c", "from imutool.cli import main; main()", "simulate", "sea-state", "--duration", "120", "-o", "s.csv"]
    assert _python(sim, tmp_path, dict(env, NUMBA_CACHE_DIR=str(tmp_path / "numba-sim"))).returncode == 0
    r = _python(["-c", RECORD, "heave", "s.csv", "-o", "heave.csv", "-q"], tmp_path, env)
    assert r.returncode == 0, r.stderr
    top = {tuple(line.split("\t"))[1:4] for line in r.stdout.splitlines() if line.startswith("-\t")}
    assert set(HEAVE_KERNELS) <= top, sorted(top)


@pytest.mark.slow
def test_the_report_entries_are_what_a_cold_inclinometer_report_compiles(tmp_path):
    """~15 s: the README's first command, cold; the CSV reader's and the roll statistics' kernels are listed
    (formats/jit/warm.py:CSV_READER, imutool/roll_period.py:ROLL_KERNEL) with the types it calls them with."""
    from imutool.roll_period import ROLL_KERNEL

    env = _env(tmp_path, **{kw.ENV_SWITCH: "0"})
    s = ROOT / "sample_data"
    args = ["report", "inclinometer", str(s / "inclinometer_dut.nmea"), "--reference"]
    args += [str(s / "inclinometer_reference.csv"), "--static-steps", str(s / "inclinometer_steps.csv")]
    args += ["--test-info", str(s / "test_info.toml"), "-o", "evidence.pdf", "-q"]
    r = _python(["-c", RECORD, *args], tmp_path, env)
    assert r.returncode in (0, 1), r.stderr  # 1: the device FAILs the test; the kernels compiled all the same
    top = {tuple(line.split("\t"))[1:4] for line in r.stdout.splitlines() if line.startswith("-\t")}
    assert {kw.CSV_READER, ROLL_KERNEL} <= top, sorted(top)


@pytest.mark.slow
def test_the_ekf_kernel_is_the_same_machine_code_from_sections_compiled_apart(tmp_path):
    """~60 s: the second process's sections, loaded by the command as bitcode, give the kernel it compiles alone.

    One cache gets every section compiled on its own (as the second process does, from the last); a fresh process
    then compiles the EKF kernel over them. Beside it, a fresh process compiles the kernel from an empty cache."""
    split_env = _env(tmp_path, **{kw.ENV_SWITCH: "0", "NUMBA_CACHE_DIR": str(tmp_path / "split")})
    whole_env = _env(tmp_path, **{kw.ENV_SWITCH: "0", "NUMBA_CACHE_DIR": str(tmp_path / "whole")})
    lines = "\n".join("\t".join(e) for e in reversed(EKF_SECTIONS))
    whole = subprocess.Popen(
        [sys.executable, "-c", EKF_KERNEL_ASM], cwd=ROOT, env=whole_env, stdout=subprocess.PIPE, text=True
    )
    sections = _python(["-m", "formats.jit.warm"], ROOT, split_env, stdin=lines)
    assert sections.returncode == 0 and sections.stderr == "", sections.stderr
    times = dict(split_env, IMUTOOL_KERNEL_TIMES="1")  # names each function compiled here, not loaded
    split = _python(["-c", EKF_KERNEL_ASM], ROOT, times)
    assert split.returncode == 0, split.stderr
    compiled = [line.split()[2] for line in split.stderr.splitlines() if line.startswith("imutool: compiled ")]
    assert compiled and all(
        not name.startswith("imutool.attitude.") or name.endswith(".ekf_kernel") for name in compiled
    ), compiled  # every section was loaded from the cache
    whole_out, _ = whole.communicate(timeout=900)
    assert whole.returncode == 0
    one, two = normalized_asm(whole_out), normalized_asm(split.stdout)
    assert len(one) > 100_000
    assert one == two
