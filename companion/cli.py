"""``companion``: run | replay | evaluate | batch | simulate | console | config-template
| install-unit | inspect.

The only place that configures logging and prints. Every expected failure
(bad file, bad configuration, unknown scenario) is one line on stderr and a
non-zero exit status; a traceback means a bug.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from companion import __version__

if TYPE_CHECKING:
    from companion.config import Config

EXIT_USAGE = 2
EXIT_FAILURE = 1

log = logging.getLogger("companion")

GRADE_HELP = (
    "IMU grade preset the configuration starts from, before --config's keys: mems (the "
    "default) or tactical (config-template --grade G prints it)"
)


def _setup_logging(level: str) -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper()),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )


def _progress(line: str) -> None:
    print(f"\r{line}", end="", file=sys.stderr, flush=True)


def _load_config(args: argparse.Namespace) -> Config:
    """``--grade`` (an IMU grade's preset, default the defaults) with ``--config``'s keys."""
    from companion.config import load_config
    from companion.presets import grade_config

    return load_config(args.config, None if args.grade is None else grade_config(args.grade))


def _cmd_run(args: argparse.Namespace) -> int:
    from companion.mavlink.link import parse_url

    # a malformed URL fails now, before the slow imports (the config checks it again)
    for url in (args.master, args.gcs):
        if url:
            parse_url(url)
    from companion.service import run_service

    config = _load_config(args)
    link = config.link
    if args.master:
        link = replace(link, master=args.master)
    if args.gcs is not None:
        link = replace(link, gcs=args.gcs)
    if args.record_dir is not None:
        link = replace(link, record_dir=args.record_dir)
    return run_service(replace(config, link=link))


def _cmd_replay(args: argparse.Namespace) -> int:
    from companion.replay import replay

    config = _load_config(args)
    raw, raw_rejected = None, None
    if args.raw is not None:
        from companion.replay import read_raw

        if not args.raw.is_file():
            raise FileNotFoundError(f"{args.raw}: no such file")
        raw, raw_rejected = read_raw(args.raw, args.raw_delay_s)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    summary = replay(
        args.input,
        args.output,
        config,
        None if args.quiet else _progress,
        raw=raw,
        raw_reader_rejections=raw_rejected,
    )
    if not args.quiet:
        print(file=sys.stderr)
    print(summary.to_text())
    print(f"output: {args.output}")
    return 0


class _Progress:
    """A one-line progress bar on a terminal (a line every tenth otherwise), on stderr."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.done = 0
        self.errors = 0
        self._tty = sys.stderr.isatty()
        self._t0 = time.perf_counter()
        self._last_tenth = -1

    def step(self, error: bool) -> None:
        self.done += 1
        self.errors += int(error)
        width = 30
        filled = width * self.done // max(self.total, 1)
        rate = self.done / max(time.perf_counter() - self._t0, 1e-9) * 60.0
        text = (
            f"[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} flights, "
            f"{self.errors} errors, {rate:.0f}/min"
        )
        if self._tty:
            sys.stderr.write("\r" + text + ("\n" if self.done == self.total else ""))
        elif 10 * self.done // max(self.total, 1) != self._last_tenth:
            self._last_tenth = 10 * self.done // max(self.total, 1)
            sys.stderr.write(text + "\n")
        sys.stderr.flush()


def _quiet_worker() -> None:
    """On a batch worker: the replays' warnings stay out of its log (the rows have them)."""
    logging.getLogger("companion").setLevel(logging.ERROR)


def _cmd_batch(args: argparse.Namespace) -> int:
    from companion.batch.run import expand, run_batch
    from companion.batch.summary import fleet_summary, summary_text

    progress = _Progress(len(expand(args.paths, exclude=args.output)))
    try:  # imported first: it sets its loggers up on import
        import distributed  # noqa: F401
    except ImportError:
        pass  # run_batch says what to install
    if args.log_level.upper() != "DEBUG":  # Dask's own comings and goings
        logging.getLogger("distributed").setLevel(logging.WARNING)
    result = run_batch(
        args.paths,
        args.output,
        workers=args.workers,
        scheduler=args.scheduler,
        config_path=args.config,
        table_format=args.format,
        plots=not args.no_plots,
        progress=None if args.quiet else progress.step,
        worker_setup=_quiet_worker,
    )
    print(summary_text(fleet_summary(result.rows)))
    print(f"table: {result.table}")
    for path in result.summary:
        print(f"summary: {path}")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    if (args.truth is None) == (args.against_input is None):
        raise ValueError("give --truth TRUTH.csv or --against-input IN.tlog (one of them)")
    if args.against_input is not None:
        return _evaluate_against_input(args)
    if args.config is not None or args.grade is not None:
        raise ValueError("--config and --grade go with --against-input, not --truth")
    from companion.evaluate import evaluate

    if args.plot is not None:  # before the work: a missing extra is one line, not a traceback
        from companion.evaluate.plot import require_matplotlib

        require_matplotlib()
    evaluation = evaluate(args.output_tlog, args.truth, args.events)
    if args.json:
        print(json.dumps(evaluation.to_dict(), indent=2, sort_keys=True))
    else:
        print(evaluation.to_text())
    if args.plot is not None:
        from companion.evaluate.plot import plot_evaluation

        plot_evaluation(evaluation, args.plot)
        print(f"plot: {args.plot}", file=sys.stderr)
    return 0


def _evaluate_against_input(args: argparse.Namespace) -> int:
    from companion.evaluate.against_input import evaluate_against_input

    if args.plot is not None or args.events is not None:
        raise ValueError("--plot and --events go with --truth, not --against-input")
    config = _load_config(args)
    result = evaluate_against_input(args.output_tlog, args.against_input, config.decoder)
    if args.json:
        print(json.dumps(result.to_dict(), indent=2, sort_keys=True))
    else:
        print(result.to_text())
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    from companion import sim

    if args.list:
        for name in sim.SCENARIO_NAMES:
            print(name)
        return 0
    if args.many is not None:
        if args.scenario is not None:
            raise ValueError("--many makes its own mix of scenarios: give no scenario name")
        from companion.sim.fleet import write_fleet

        tlogs = write_fleet(args.out, args.many, seed=args.seed, duration_s=args.duration)
        print(f"{len(tlogs)} flights under {args.out}")
        return 0
    if args.scenario is None:
        raise ValueError("give a scenario name (--list shows them)")
    if args.duration is not None and args.duration <= 0:
        raise ValueError(f"duration must be > 0 s, got {args.duration:g}")
    paths = sim.write_scenario(args.scenario, args.out, seed=args.seed, duration_s=args.duration)
    for path in paths:
        print(path)
    return 0


def _cmd_console(args: argparse.Namespace) -> int:
    from companion.console.main import run_console

    return run_console(
        args.master,
        once=args.once,
        duration_s=args.duration,
        as_json=args.json,
        station=args.station,
        web_port=args.web,
        web_url=args.web_url,
        tracker_out=args.tracker_out,
    )


def _cmd_inspect(args: argparse.Namespace) -> int:
    from companion.inspection import inspect_file, parse_reference

    reference = None if args.reference is None else parse_reference(args.reference)
    if not args.input.is_file():
        raise FileNotFoundError(f"{args.input}: no such file")
    if args.plot is not None:  # before the work: a missing extra is one line, not a traceback
        from companion.evaluate.plot import require_matplotlib

        require_matplotlib()
    summary = inspect_file(args.input, args.output, args.start_s, reference)
    print(summary.to_text())
    print(f"track: {args.output}")
    if args.plot is not None:
        from companion.inspection_plot import plot_inspection

        plot_inspection(summary, args.plot, title=f"{args.input.name}: T-D PRP and FIS-RAIM")
        print(f"plot: {args.plot}")
    return 0


def _cmd_config_template(args: argparse.Namespace) -> int:
    from companion.config import template
    from companion.presets import grade_template

    print(template() if args.grade is None else grade_template(args.grade))
    return 0


def _cmd_install_unit(args: argparse.Namespace) -> int:
    from companion import deploy

    executable = args.executable or deploy.installed_executable()
    if args.print_only:
        print(deploy.unit_text(executable), end="")
        return 0
    path = deploy.install_unit(args.dir or deploy.SYSTEMD_UNIT_DIR, executable)
    print(path)
    print(
        "then: systemctl daemon-reload && systemctl enable --now companion (docs/deploy.md)",
        file=sys.stderr,
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for tests and documentation)."""
    parser = argparse.ArgumentParser(
        prog="companion",
        description="Navigation service beside an ArduPilot/PX4 autopilot.",
    )
    parser.add_argument("--version", action="version", version=f"companion {__version__}")
    parser.add_argument(
        "--log-level", default="info", choices=["debug", "info", "warning", "error"]
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run the service on live links")
    p.add_argument("--master", help="autopilot link URL (overrides the config)")
    p.add_argument("--gcs", help="ground-station link URL (overrides the config)")
    p.add_argument("--config", type=Path, help="TOML configuration file")
    p.add_argument("--grade", help=GRADE_HELP)
    p.add_argument("--record-dir", help="flight recorder folder ('' disables)")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("replay", help="replay a .tlog, .bin or .ulg through the service")
    p.add_argument("input", type=Path, help="recorded flight (.tlog, DataFlash .bin, PX4 .ulg)")
    p.add_argument("--output", "-o", type=Path, required=True, help="what the service sends")
    p.add_argument("--config", type=Path, help="TOML configuration file")
    p.add_argument("--grade", help=GRADE_HELP)
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    p.add_argument(
        "--raw",
        type=Path,
        help="the raw receiver's .ubx beside the log (RXM-RAWX, RXM-SFRBX, NAV-PVT): its "
        "carrier-phase solution goes to the integrity monitor",
    )
    p.add_argument(
        "--raw-delay-s",
        type=float,
        default=0.0,
        help="the raw receiver's messages arrive this long after their GPS time (default 0)",
    )
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "evaluate", help="score a replay output against truth or against its own input"
    )
    p.add_argument("output_tlog", type=Path, help="the replay's output .tlog")
    p.add_argument("--truth", type=Path, help="truth CSV from the simulator")
    p.add_argument(
        "--against-input",
        type=Path,
        help="the replayed .tlog: score against the receiver's own fixes (no truth)",
    )
    p.add_argument("--config", type=Path, help="with --against-input: the replay's configuration")
    p.add_argument("--grade", help=GRADE_HELP)
    p.add_argument("--events", type=Path, help="event sidecar JSON (default: beside the truth)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--plot", type=Path, help="draw the track and errors to this PNG")
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("batch", help="replay and score many logs on a Dask cluster")
    p.add_argument("paths", nargs="+", type=Path, help="logs, or folders of them (recursive)")
    p.add_argument("--output", "-o", type=Path, required=True, help="folder of the table")
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler (tcp://HOST:8786)")
    p.add_argument("--config", type=Path, help="TOML configuration file for every replay")
    p.add_argument(
        "--format", choices=("auto", "parquet", "csv"), default="auto",
        help="table format (auto: Parquet when pyarrow is installed)",
    )  # fmt: skip
    p.add_argument("--no-plots", action="store_true", help="no fleet.png")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_batch)

    p = sub.add_parser("simulate", help="simulate a flight: .tlog, truth CSV, JSON sidecar")
    p.add_argument("scenario", nargs="?", help="scenario name (--list shows them)")
    p.add_argument("--out", type=Path, default=Path("."), help="output folder")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--duration", type=float, help="override the scenario duration, s")
    p.add_argument("--list", action="store_true", help="list the scenarios")
    p.add_argument(
        "--many", type=int, metavar="N",
        help="N varied flights (scenarios in turn, seeds from --seed) in DIR/flight_*/",
    )  # fmt: skip
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("console", help="watch the service from the ground (terminal)")
    p.add_argument("--master", required=True, help="link URL on which the service is heard")
    p.add_argument("--once", action="store_true", help="print one status screen and exit")
    p.add_argument("--json", action="store_true", help="print the status as JSON and exit")
    p.add_argument(
        "--duration", type=float, help="--once/--json: give up after this many seconds (5)"
    )
    p.add_argument(
        "--station",
        help="ground station LAT,LON,ALT (deg, deg, m MSL): track the aircraft in az/el/range",
    )
    p.add_argument(
        "--tracker-out",
        metavar="URL",
        help="with --station: send the predicted position to an antenna tracker's link "
        "(GLOBAL_POSITION_INT, e.g. udpout:192.168.1.20:14555)",
    )
    p.add_argument("--web", type=int, metavar="PORT", help="serve the console to a browser")
    p.add_argument(
        "--web-url",
        metavar="URL",
        help="--web: the address browsers reach this machine by (http://localhost:PORT)",
    )
    p.set_defaults(func=_cmd_console)

    p = sub.add_parser("config-template", help="print every configuration key with defaults")
    p.add_argument("--grade", help="print the values of this IMU grade's preset (mems, tactical)")
    p.set_defaults(func=_cmd_config_template)

    p = sub.add_parser(
        "inspect", help="carrier-phase track (T-D PRP) with FIS-RAIM from a raw .ubx file"
    )
    p.add_argument("input", type=Path, help="u-blox recording with RXM-RAWX and RXM-SFRBX")
    p.add_argument("--output", "-o", type=Path, required=True, help="track CSV")
    p.add_argument("--start-s", type=float, help="epoch 0 this long after the first epoch, s")
    p.add_argument("--reference", help="epoch 0's LAT,LON,ALT (deg, deg, m above the ellipsoid)")
    p.add_argument(
        "--plot",
        type=Path,
        help="draw the E/N/U track and FIS-RAIM's statistics with their limits to this PNG",
    )
    p.set_defaults(func=_cmd_inspect)

    p = sub.add_parser("install-unit", help="write the systemd unit (--print: to stdout)")
    p.add_argument("--print", dest="print_only", action="store_true", help="print; write nothing")
    p.add_argument("--dir", type=Path, help="folder to write it to (default /etc/systemd/system)")
    p.add_argument(
        "--exec",
        dest="executable",
        help="companion executable for ExecStart (default: this installation's)",
    )
    p.set_defaults(func=_cmd_install_unit)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    parser = build_parser()
    args = parser.parse_args(argv)
    _setup_logging(args.log_level)
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        return 130
    except Exception as exc:
        if not isinstance(exc, _expected_errors()):
            raise
        print(f"companion {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE


_EXPECTED_ERRORS = (
    ("companion.config", "ConfigError"),
    ("companion.evaluate.results", "EvaluationError"),
    ("companion.mavlink.link", "LinkError"),
    ("companion.mavlink.tlog", "TlogError"),
    ("companion.evaluate.plot", "PlotUnavailableError"),
    ("companion.batch.run", "BatchError"),
)
"""The package's exceptions a user can cause (one line, exit 1), by module."""


def _expected_errors() -> tuple[type[Exception], ...]:
    """ValueError, FileNotFoundError and those of :data:`_EXPECTED_ERRORS` whose module is
    loaded (an exception cannot come from a module never imported): nothing is imported
    here, so a bad command line fails before the package's slow imports."""
    found: list[type[Exception]] = [ValueError, FileNotFoundError]
    for module, name in _EXPECTED_ERRORS:
        if module in sys.modules:
            found.append(getattr(sys.modules[module], name))
    return tuple(found)
