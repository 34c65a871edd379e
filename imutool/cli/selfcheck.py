"""``imutool selfcheck``: compile every kernel once and check a tiny end-to-end run (library route:
:func:`imutool.selfcheck.run_selfcheck`)."""

from __future__ import annotations

import json
import sys

import click


@click.command(
    "selfcheck",
    epilog="Example: imutool selfcheck    # after pip install, or once when building a CI image",
)
@click.option("--json", "as_json", is_flag=True, help="Print the steps and the cache folder as JSON.")
def selfcheck_cmd(as_json: bool) -> None:
    """Compile the commands' numba kernels into the per-user cache and check a tiny end-to-end run.

    Simulates a few seconds with truth, round-trips the imutool CSV (bit-exact), runs the attitude EKF (roll and
    pitch RMSE bound), the smoother, compass, heave, INS, roll statistics, a magnetometer calibration, an Allan
    deviation, ROS bag round trips and the bridge decoder. A first run compiles for minutes; later runs take
    seconds. Exit status 0 when every step passed, 1 with one line naming the failed step.
    """
    from formats.errors import ImutoolError
    from imutool.selfcheck import run_selfcheck

    def show(step) -> None:
        if not as_json:
            click.echo(f"ok  {step.name:38s} {step.seconds:6.1f} s  {step.detail}")

    try:
        result = run_selfcheck(on_step=show)
    except ImutoolError as e:
        click.echo(f"imutool selfcheck: FAILED: {' '.join(str(e).split())}", err=True)
        sys.exit(1)
    lasting = "" if result.persistent_cache else " (not writable: a temporary folder, compiled again every run)"
    if as_json:
        steps = [{"name": s.name, "seconds": round(s.seconds, 3), "detail": s.detail} for s in result.steps]
        summary = {"ok": True, "steps": steps, "cache_folder": result.cache_folder}
        summary["persistent_cache"] = result.persistent_cache
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"all {len(result.steps)} steps passed in {result.seconds:.1f} s")
    click.echo(f"compiled kernels cached in: {result.cache_folder}{lasting}")
