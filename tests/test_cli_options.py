"""Click-level usage errors: every command and sub-command × nonsense options → one line on stderr, exit 2.

Unknown option, missing argument, bad choice and wrong type are found by walking the click commands, so a new
command or option is covered without editing this file. (Numeric ranges, NaN/inf and hostile input files are
tested elsewhere.)
"""

from __future__ import annotations

import click
import pytest

from imutool.cli import cli, main


def _commands() -> list[tuple[tuple[str, ...], click.Command]]:
    ctx = click.Context(cli)
    out = []
    for name in cli.list_commands(ctx):
        cmd = cli.get_command(ctx, name)
        if isinstance(cmd, click.Group):
            for sub in cmd.list_commands(ctx):
                out.append(((name, sub), cmd.get_command(ctx, sub)))
        else:
            out.append(((name,), cmd))
    return out


COMMANDS = _commands()


def _cases() -> list:
    cases = []
    for path, cmd in COMMANDS:
        tag = " ".join(path)
        cases.append(pytest.param([*path, "--no-such-option-xyz"], "--no-such-option-xyz", id=f"{tag}: unknown"))
        if any(isinstance(p, click.Argument) and p.required for p in cmd.params):
            cases.append(pytest.param([*path], None, id=f"{tag}: missing argument"))
        choice = next(
            (
                p
                for p in cmd.params
                if isinstance(p, click.Option) and isinstance(p.type, click.Choice) and not p.is_flag
            ),
            None,
        )
        if choice is not None:
            opt = max(choice.opts, key=len)
            cases.append(pytest.param([*path, opt, "nonsense-choice"], opt, id=f"{tag}: bad choice {opt}"))
        for kind, bad in ((click.types.IntParamType, "twelve"), (click.types.FloatParamType, "1.2.3")):
            num = next(
                (
                    p
                    for p in cmd.params
                    if isinstance(p, click.Option) and isinstance(p.type, kind) and not p.is_flag and p.nargs == 1
                ),
                None,
            )
            if num is not None:
                opt = max(num.opts, key=len)
                cases.append(pytest.param([*path, opt, bad], opt, id=f"{tag}: bad type {opt}"))
    return cases


def test_every_command_is_walked():
    names = {" ".join(p) for p, _ in COMMANDS}
    for must in (
        "info",
        "filter",
        "simulate",
        "convert",
        "calibrate mag",
        "calibrate accel",
        "report inclinometer",
        "capture serial",
        "allan",
        "zvi",
        "ins",
        "heave",
    ):
        assert must in names, f"{must} not listed by the CLI"


@pytest.mark.parametrize(("argv", "named"), _cases())
def test_usage_error_is_one_line_exit_2(argv, named, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as ex:
        main(list(argv))
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert ex.value.code == 2, (ex.value.code, err)
    assert len(lines) == 1, err
    assert "Traceback" not in err and "internal error" not in err, err
    cmd_path = "imutool " + " ".join(a for a in argv if not a.startswith("-") and a in {*argv[:2]})
    assert lines[0].startswith(cmd_path.strip() + ": error: "), lines[0]
    if named is not None:
        assert named in lines[0], lines[0]
    assert out == "", out
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_unknown_simulate_setting_lists_valid_names(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as ex:
        main(["simulate", "sea-state", "-o", "sea.csv", "--set", "hss=2"])
    err = capsys.readouterr().err
    assert ex.value.code == 2
    assert err.count("\n") == 1 and "'hss'" in err and "hs, tp" in err, err
    assert not (tmp_path / "sea.csv").exists()


def test_bare_group_prints_help():
    with pytest.raises(SystemExit) as ex:
        main(["calibrate"])
    assert ex.value.code == 0


def test_filter_defaults_are_the_librarys():
    """`imutool filter` keeps its option defaults literal (so `--help` loads no numba): they must be the route's."""
    import inspect

    from imutool.cli.filter import filter_cmd
    from imutool.compass import CompassParams
    from imutool.filtering import run_filter

    cli_default = {p.name: p.default for p in filter_cmd.params}
    lib = {k: v.default for k, v in inspect.signature(run_filter).parameters.items()}
    comp = CompassParams()
    pairs = {
        "method": lib["method"],
        "cutoff": lib["cutoff_hz"],
        "order": lib["order"],
        "chunk_rows": lib["chunk_rows"],
        "stream_mb": lib["stream_mb"],
        "compass_model": comp.model,
        "comp_q": comp.q,
        "comp_r": comp.r,
        "variation": comp.variation_deg,
    }
    assert {k: cli_default[k] for k in pairs} == pairs
