"""``skyfix replay``: replay a recording against a server, print a table, write JSON and AEM.

Registered on the ``skyfix`` typer app as ``app.command("replay")(client.cli.replay)``; also
runs alone as ``python -m client.cli RECORDING --url ...``.

Exit status: 0 = done and every bar given was met; 1 = a ``--min-rate`` or ``--max-wrong``
bar was missed; 2 = bad usage or an unreadable recording; 3 = no frame was answered at all
(server unreachable or refusing every frame); 130 = interrupted (Ctrl-C).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from ._aem import write_aem
from ._config import DEFAULT_URL, Retry
from ._exceptions import RecordingError
from ._report import (
    WRONG_CROSS_BORESIGHT_ARCSEC,
    WRONG_ROLL_ARCSEC,
    Distribution,
    FrameReport,
    ReplayReport,
    WrongBars,
)
from .recording import read_recording
from .replay import aem_records, replay_frames

__all__ = ["replay"]

EXIT_BARS_MISSED = 1
EXIT_USAGE = 2
EXIT_NOTHING_ANSWERED = 3
EXIT_INTERRUPTED = 130


def _fmt(value: float | None, spec: str = ".1f") -> str:
    return "-" if value is None else format(value, spec)


def _dist(d: Distribution, spec: str = ".1f") -> str:
    if not d.n:
        return "-"
    return f"p50 {_fmt(d.p50, spec)} · p95 {_fmt(d.p95, spec)} · max {_fmt(d.max, spec)}  (n={d.n})"


def render_table(report: ReplayReport) -> Table:
    """The report as a rich table."""
    table = Table(title=f"skyfix replay · {report.transport.upper()} · {report.url}", show_header=False)
    table.add_column("measure", style="bold")
    table.add_column("value")
    table.add_row("frames", f"{report.frames}  (solved {report.solved}, no solution {report.no_solution}, "
                            f"failed {report.failed})")
    table.add_row("identification rate", f"{report.identification_rate:.1%}")
    wrong_style = "red" if report.wrong else "green"
    table.add_row("wrong answers", f"[{wrong_style}]{report.wrong}[/]"
                  + (f"  ids {report.wrong_ids[:10]}" if report.wrong_ids else ""))
    table.add_row("HIP checked / wrong", f"{report.hip_checked} / {report.hip_wrong}")
    table.add_row("cross-boresight error, arcsec", _dist(report.cross_boresight_arcsec))
    table.add_row("roll error |·|, arcsec", _dist(report.roll_arcsec))
    lat = report.latency_ms
    table.add_row("latency, ms", "-" if not lat.n else
                  f"p50 {_fmt(lat.p50)} · p95 {_fmt(lat.p95)} · p99 {_fmt(lat.p99)}  (n={lat.n})")
    table.add_row("throughput", f"{report.throughput_fps:.1f} frames/s over {report.wall_s:.2f} s")
    if report.transport == "ws":
        table.add_row("reconnects", str(report.reconnects))
    by_error: dict[str, list[object]] = {}
    for fail in report.failures:
        by_error.setdefault(str(fail["error"]), []).append(fail["id"])
    for error, ids in list(by_error.items())[:3]:
        shown = ", ".join(repr(i) for i in ids[:3]) + (", ..." if len(ids) > 3 else "")
        table.add_row(f"[red]failed ×{len(ids)}[/]", f"{error}  [dim](ids {shown})[/]")
    if len(by_error) > 3:
        table.add_row("[red]failed[/]", f"... {len(by_error) - 3} other errors (see --report)")
    return table


def replay(
    recording: Annotated[Path, typer.Argument(help="Recording (JSON Lines, one frame a line).")],
    url: Annotated[str, typer.Option(help="Server base URL.", envvar="SKYFIX_URL")] = DEFAULT_URL,
    ws: Annotated[bool, typer.Option("--ws", help="Stream over the WebSocket instead of REST.")] = False,
    rate: Annotated[float | None, typer.Option(help="Frames per second (default: as fast as possible).",
                                               min=0.001)] = None,
    concurrency: Annotated[int, typer.Option(help="Frames in flight at once (REST requests, or the WebSocket "
                                                  "window).", min=1, max=1024)] = 1,
    api_key: Annotated[str | None, typer.Option(help="Server API key (prefer the SKYFIX_API_KEY environment "
                                                     "variable: a command line is visible to ps).",
                                                envvar="SKYFIX_API_KEY", show_envvar=True)] = None,
    report: Annotated[Path | None, typer.Option(help="Write the full report, every frame, as JSON.")] = None,
    min_rate: Annotated[float | None, typer.Option(help="Fail (exit 1) below this identification rate, 0-1.",
                                                   min=0.0, max=1.0)] = None,
    max_wrong: Annotated[int | None, typer.Option(help="Fail (exit 1) above this many wrong answers.",
                                                  min=0)] = None,
    aem: Annotated[Path | None, typer.Option(help="Write the solved attitudes as a CCSDS AEM.")] = None,
    method: Annotated[str, typer.Option(help="Identification method, or 'auto'.")] = "auto",
    session: Annotated[str | None, typer.Option(help="With --ws: publish the frames to this stream session's "
                                                     "viewers (the web console's /ui/live).")] = None,
    wrong_arcsec: Annotated[float, typer.Option(
        help="Cross-boresight error above which a solved frame is wrong, arcsec.", min=0.0,
    )] = WRONG_CROSS_BORESIGHT_ARCSEC,
    wrong_roll_arcsec: Annotated[float, typer.Option(help="Roll error above which a solved frame is wrong, "
                                                          "arcsec.", min=0.0)] = WRONG_ROLL_ARCSEC,
    timeout: Annotated[float, typer.Option(help="Seconds to wait for each answer.", min=0.001)] = 30.0,
    retries: Annotated[int, typer.Option(help="Retries of a frame on connection errors and 502/503/504 "
                                              "(WebSocket: reconnect attempts).", min=0, max=100)] = 2,
    object_name: Annotated[str, typer.Option(help="AEM OBJECT_NAME.")] = "SKYFIX",
    object_id: Annotated[str, typer.Option(help="AEM OBJECT_ID (e.g. the COSPAR id).")] = "UNKNOWN",
    ref_frame_b: Annotated[str, typer.Option(help="AEM REF_FRAME_B: the camera/body frame.")] = "SC_BODY_1",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Replay recorded frames against a skyfix server and score them against their truth."""
    out = Console()
    err = Console(stderr=True, soft_wrap=True)  # one line per error, however long the path
    try:
        frames = list(read_recording(recording))
    except RecordingError as exc:
        err.print(f"[red]skyfix replay:[/] {exc}")
        raise typer.Exit(EXIT_USAGE) from None
    bars = WrongBars(cross_boresight_arcsec=wrong_arcsec, roll_arcsec=wrong_roll_arcsec)
    policy = Retry(attempts=retries + 1)
    columns = (TextColumn("[bold]replay"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.description}"), TimeElapsedColumn())
    with Progress(*columns, console=err, disable=quiet, transient=False) as progress:
        task = progress.add_task("", total=len(frames))
        counts = {"solved": 0, "no_solution": 0, "failed": 0}

        def on_result(frame: FrameReport) -> None:
            counts[frame.status] += 1
            progress.update(task, advance=1, description=(
                f"solved {counts['solved']} · none {counts['no_solution']} · failed {counts['failed']}"))

        try:
            result = asyncio.run(replay_frames(
                frames, url=url, recording=recording, ws=ws, rate_hz=rate, concurrency=concurrency,
                api_key=api_key, timeout=timeout, retries=policy, method=method, session=session, bars=bars,
                on_result=on_result))
        except KeyboardInterrupt:
            progress.stop()
            err.print("[yellow]skyfix replay:[/] interrupted")
            raise typer.Exit(EXIT_INTERRUPTED) from None
    missed = result.missed_bars(min_rate=min_rate, max_wrong=max_wrong)
    result.bars = {"min_rate": min_rate, "max_wrong": max_wrong, "passed": not missed, "missed": missed}
    out.print(render_table(result))
    if report is not None:
        report.write_text(result.model_dump_json(indent=2) + "\n", encoding="utf-8")
    if aem is not None:
        records = aem_records(result)
        if records:
            write_aem(aem, records, object_name=object_name, object_id=object_id, ref_frame_b=ref_frame_b,
                      comments=[f"skyfix replay of {recording.name}: {len(records)} solved frames"])
        else:
            err.print("[yellow]skyfix replay:[/] no solved frame: no AEM written")
    for reason in missed:
        err.print(f"[red]bar missed:[/] {reason}")
    if missed:
        raise typer.Exit(EXIT_BARS_MISSED)
    if result.frames and result.failed == result.frames:
        err.print("[red]skyfix replay:[/] no frame was answered")
        raise typer.Exit(EXIT_NOTHING_ANSWERED)


def main() -> None:
    """``python -m client.cli``."""
    typer.run(replay)


if __name__ == "__main__":
    main()
