"""``companion console``: the ground station's view of the service, and its decisions.

A Textual app on one MAVLink link (the GCS side of the autopilot, or the
service's own ``--gcs`` link). It draws :class:`~companion.console.model.ConsoleModel`
twice a second: link health (STALE after 3 s of silence), navigation mode and
accuracy, integrity against the approach categories' alert limits, outage timer,
heading correction, the alert history, plots of the last minutes and the track,
and with ``--station`` the tracking channel's azimuth, elevation and range
(with ``--tracker-out`` its prediction sent on to an antenna tracker, 10 times a
second: :mod:`companion.console.antenna`).

Keys: ``c`` / ``r`` / ``u`` confirm, refuse, undo the heading correction
(COMMAND_LONG MAV_CMD_USER_1 to component 191; its COMMAND_ACK is shown),
``p`` the service's parameters (listed with the parameter protocol; Enter on a
row to edit, Enter in the field to set), ``a`` acknowledge the alerts, ``q`` quit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from rich.text import Text
from textual import on
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.screen import Screen
from textual.widgets import DataTable, Footer, Header, Input, Static
from textual_plotext import PlotextPlot

from companion.console.antenna import AntennaFeed
from companion.console.model import ConsoleModel, NavMode, boot_text
from companion.console.send import Sender
from companion.mavlink.framing import FrameParser
from companion.mavlink.link import Link, LinkError, UdpLink, open_link

REFRESH_S = 0.5
STALE_CHECK_S = 0.1
"""How often a link going quiet (or coming back) is looked for: STALE shows within
``STALE_S`` and this, not a whole refresh later."""
ANTENNA_PERIOD_S = 0.1
EARTH_RADIUS_M = 6_371_000.0
"""For the track plot's metres (a picture, not navigation)."""
PARAM_QUIET_S = 0.5
"""No PARAM_VALUE for this long while some are missing: the list is over, ask for the rest."""
PARAM_READS_AT_ONCE = 20
SEVERITY_STYLES = {
    "EMERG": "bold white on red",
    "ALERT": "bold white on red",
    "CRIT": "bold red",
    "ERROR": "red",
    "WARN": "yellow",
    "NOTICE": "cyan",
    "INFO": "white",
    "DEBUG": "dim",
}
MODE_STYLES = {
    NavMode.WAITING: "dim",
    NavMode.NORMAL: "bold green",
    NavMode.DEGRADED: "bold yellow",
    NavMode.BRIDGING: "bold yellow",
    NavMode.LOST: "bold white on red",
}


def _num(value: float | None, fmt: str = ".2f", unit: str = "") -> str:
    return "—" if value is None else f"{format(value, fmt)}{unit}"


def _age_text(age_s: float | None, stale: bool) -> Text:
    if age_s is None:
        return Text("never heard", style="bold white on red")
    if stale:
        return Text(f" STALE {age_s:4.0f} s ", style="bold white on red blink")
    return Text(f"{age_s:4.1f} s", style="green")


class Panel(Static):
    """A bordered panel whose content is a Rich Text."""

    def __init__(self, title: str, **kw: Any) -> None:
        super().__init__(**kw)
        self.border_title = title


class ParamScreen(Screen[None]):
    """The service's parameters: a table, and a field to set one."""

    BINDINGS = [Binding("escape", "app.pop_screen", "back"), Binding("l", "reload", "reload")]

    def compose(self) -> ComposeResult:
        yield Header()
        yield DataTable(id="params", cursor_type="row")
        yield Input(placeholder="NAME VALUE  (Enter on a row fills it)", id="param-edit")
        yield Static("", id="param-status")
        yield Footer()

    def on_mount(self) -> None:
        table = self.query_one(DataTable)
        for name in ("index", "name", "value"):
            table.add_column(name, key=name)
        self.refresh_table()
        self.set_interval(REFRESH_S, self.refresh_table)
        self.set_interval(REFRESH_S, self.fetch_missing)

    def fetch_missing(self) -> None:
        """Ask again, by index, for what the list lost (as ground stations do), a few a time."""
        model: ConsoleModel = self.app.model  # type: ignore[attr-defined]
        if model.param_count is None or len(model.params) >= model.param_count:
            return
        newest = max((e.t_rx_s for e in model.params.values()), default=0.0)
        if self.app.clock() - newest < PARAM_QUIET_S:  # type: ignore[attr-defined]
            return  # the list is still coming
        have = {e.index for e in model.params.values()}
        missing = [i for i in range(model.param_count) if i not in have][:PARAM_READS_AT_ONCE]
        for index in missing:
            self.app.request_param(index)  # type: ignore[attr-defined]

    def action_reload(self) -> None:
        self.app.request_params()  # type: ignore[attr-defined]

    def refresh_table(self) -> None:
        model: ConsoleModel = self.app.model  # type: ignore[attr-defined]
        table = self.query_one(DataTable)
        for entry in sorted(model.params.values(), key=lambda e: e.index):
            key = entry.name
            value = f"{entry.value:g}"
            if key in table.rows:
                table.update_cell(key, "value", value)
            else:
                table.add_row(str(entry.index), entry.name, value, key=key)
        self.query_one("#param-status", Static).update(
            f"{len(model.params)} of {model.param_count or '?'} parameters"
        )

    @on(DataTable.RowSelected)
    def fill(self, event: DataTable.RowSelected) -> None:
        model: ConsoleModel = self.app.model  # type: ignore[attr-defined]
        entry = model.params.get(str(event.row_key.value))
        if entry is not None:
            field = self.query_one(Input)
            field.value = f"{entry.name} {entry.value:g}"
            field.focus()

    @on(Input.Submitted)
    def submit(self, event: Input.Submitted) -> None:
        parts = event.value.split()
        status = self.query_one("#param-status", Static)
        if len(parts) != 2:
            status.update("type NAME VALUE")
            return
        try:
            value = float(parts[1])
        except ValueError:
            status.update(f"not a number: {parts[1]}")
            return
        self.app.set_param(parts[0].upper(), value)  # type: ignore[attr-defined]
        status.update(f"PARAM_SET {parts[0].upper()} {value:g} sent")


class ConsoleApp(App[int]):
    """The console (see the module doc)."""

    TITLE = "companion console"
    CSS = """
    #top { height: 11; }
    #top Panel { width: 1fr; height: 100%; border: round $accent; padding: 0 1; }
    #top Panel.stale { border: heavy red; }
    #plots { height: 1fr; min-height: 10; }
    #plots > .plotbox { width: 1fr; border: round $accent; }
    #bottom { height: 12; }
    #alerts { width: 2fr; height: 100%; border: round $accent; }
    #side { width: 1fr; }
    #side Panel { border: round $accent; padding: 0 1; height: 1fr; }
    """
    BINDINGS = [
        Binding("c", "heading(1)", "confirm heading"),
        Binding("r", "heading(0)", "refuse heading"),
        Binding("u", "heading(2)", "undo heading"),
        Binding("a", "ack", "ack alerts"),
        Binding("p", "params", "parameters"),
        Binding("q", "quit", "quit"),
    ]

    def __init__(
        self,
        url: str,
        model: ConsoleModel | None = None,
        clock: Callable[[], float] = time.time,
        tracker_out: str | None = None,
    ) -> None:
        super().__init__()
        self.url = url
        self.clock = clock
        self.model = model or ConsoleModel()
        self.link: Link | None = None
        self.tracker_out = tracker_out
        self.antenna_link: Link | None = None
        self.antenna: AntennaFeed | None = None
        self.antenna_status = ""
        self.sender = Sender()
        self.parser = FrameParser()
        self.status = "no command sent yet"
        self._stale_shown = (True, True)
        self._alerts_shown = 0

    # ----------------------------------------------------------------- layout
    def compose(self) -> ComposeResult:
        yield Header()
        with Horizontal(id="top"):
            yield Panel("link", id="link")
            yield Panel("navigation", id="nav")
            yield Panel("integrity", id="integrity")
            yield Panel("outage · heading", id="heading")
            yield Panel("tracking", id="track")
        with Horizontal(id="plots"):
            with Vertical(classes="plotbox"):
                yield PlotextPlot(id="acc-plot")
            with Vertical(classes="plotbox"):
                yield PlotextPlot(id="track-plot")
        with Horizontal(id="bottom"):
            yield DataTable(id="alerts", cursor_type="row", zebra_stripes=True)
            with Vertical(id="side"):
                yield Panel("decisions", id="decisions")
        yield Footer()

    async def on_mount(self) -> None:
        table = self.query_one("#alerts", DataTable)
        table.border_title = "alerts"
        table.add_columns("autopilot time", "sev", "alert", "ack")
        try:
            self.link = await open_link(self.url)
            if isinstance(self.link, UdpLink):
                self.link.reply_to_any_sender = False
        except LinkError as exc:
            self.status = f"cannot open {self.url}: {exc}"
        else:
            self.run_worker(self._receive(), exclusive=True, group="rx")
        if self.tracker_out is not None and self.model.station is not None:
            try:
                self.antenna_link = await open_link(self.tracker_out)
            except LinkError as exc:
                self.antenna_status = f"antenna: cannot open {self.tracker_out}: {exc}"
            else:
                self.antenna = AntennaFeed(self.model.station)
                self.set_interval(ANTENNA_PERIOD_S, self._feed_antenna)
        self.refresh_panels()
        self.set_interval(REFRESH_S, self._refresh_tick)
        self.set_interval(STALE_CHECK_S, self._refresh_on_stale_change)

    async def on_unmount(self) -> None:
        if self.link is not None:
            await self.link.close()
        if self.antenna_link is not None:
            await self.antenna_link.close()

    async def _feed_antenna(self) -> None:
        """The prediction to the antenna tracker's link (GLOBAL_POSITION_INT)."""
        if self.antenna is None or self.antenna_link is None:
            return
        m = self.model
        now = self.clock()
        frames = self.antenna.frames(now, m.track_estimate(now), m.aircraft_system, m.aircraft_type)
        try:
            for frame in frames:
                await self.antenna_link.send(frame)
        except LinkError as exc:
            self.antenna_status = f"antenna: {exc}"
            return
        self.antenna_status = f"antenna: {self.antenna.sent} positions → {self.tracker_out}"

    async def _receive(self) -> None:
        assert self.link is not None
        while True:
            try:
                data = await self.link.recv()
            except LinkError as exc:
                self.status = f"link closed: {exc}"
                return
            now = self.clock()
            heard_service = False
            for msg in self.parser.feed(data):
                heard_service |= self.model.take(msg, now)
            if heard_service and isinstance(self.link, UdpLink):
                self.link.adopt_sender()  # commands go where the service is heard

    # ---------------------------------------------------------------- actions
    async def _send(self, frame: bytes) -> bool:
        if self.link is None:
            self.status = "no link"
            return False
        await self.link.send(frame)
        return True

    async def action_heading(self, action: int) -> None:
        target = self.model.service_system
        if target is None:
            self.status = "no service heard yet: command not sent"
            self.refresh_panels()
            return
        names = {0: "refuse", 1: "confirm", 2: "undo"}
        if await self._send(self.sender.heading_command(target, float(action))):
            self.status = f"heading {names[action]} sent to {target}/191, waiting for the ACK"
        self.refresh_panels()

    def action_ack(self) -> None:
        n = self.model.acknowledge()
        self.status = f"{n} alert(s) acknowledged"
        self.refresh_panels(force_alerts=True)

    def request_params(self) -> None:
        target = self.model.service_system
        if target is not None:
            self.run_worker(self._send(self.sender.param_request_list(target)), group="tx")

    def request_param(self, index: int) -> None:
        target = self.model.service_system
        if target is not None:
            self.run_worker(self._send(self.sender.param_request_read(target, index)), group="tx")

    def set_param(self, name: str, value: float) -> None:
        target = self.model.service_system
        if target is None:
            self.status = "no service heard yet: PARAM_SET not sent"
            return
        entry = self.model.params.get(name)
        ptype = entry.param_type if entry is not None else None
        self.run_worker(self._send(self.sender.param_set(target, name, value, ptype)), group="tx")

    def action_params(self) -> None:
        self.request_params()
        self.push_screen(ParamScreen())

    # ---------------------------------------------------------------- drawing
    def _refresh_tick(self) -> None:
        try:
            self.refresh_panels()
        except NoMatches:  # a tick while the app closes: the panels are gone
            return

    def _refresh_on_stale_change(self) -> None:
        now = self.clock()
        stale = (self.model.service_stale(now), self.model.autopilot_stale(now))
        if stale != self._stale_shown:
            self._refresh_tick()

    def refresh_panels(self, force_alerts: bool = False) -> None:
        now = self.clock()
        m = self.model
        self._stale_shown = (m.service_stale(now), m.autopilot_stale(now))
        s = m.snapshot(now)
        link, nav, integ, hdg = s["link"], s["navigation"], s["integrity"], s["heading"]
        self.query_one("#link", Panel).set_class(link["service_stale"], "stale")
        t = Text()
        t.append("service   ")
        t.append_text(_age_text(link["service_age_s"], link["service_stale"]))
        t.append("\nautopilot ")
        t.append_text(_age_text(link["autopilot_age_s"], link["autopilot_stale"]))
        t.append(f"\nmessages  {link['messages']}\nheartbeats {link['heartbeats']}")
        t.append(f"\n{self.url}", style="dim")
        self.query_one("#link", Panel).update(t)

        mode = m.mode(now)
        t = Text()
        t.append("mode  ")
        t.append(f" {mode.value.upper()} ", style=MODE_STYLES[mode])
        if link["service_stale"] and m.last_rx_s is not None:
            t.append("  (old)", style="bold red")
        t.append(f"\nfix   {nav['fix'] or '—'}")
        if nav["lat_deg"] is not None:
            t.append(f"\nlat   {nav['lat_deg']:.7f}\nlon   {nav['lon_deg']:.7f}")
            t.append(f"\nalt   {nav['alt_msl_m']:.1f} m MSL")
            t.append(f"\nspeed {nav['speed_mps']:.1f} m/s  hdg {_num(nav['heading_deg'], '.1f')}")
        t.append(
            f"\nacc   H {_num(nav['h_acc_m'])} V {_num(nav['v_acc_m'])} m 1σ",
            style="bold",
        )
        self.query_one("#nav", Panel).update(t)

        t = Text()
        cat1 = integ["limits"]["CAT_I"]
        hpl, vpl = integ["hpl_m"], integ["vpl_m"]
        over = hpl is not None and vpl is not None and (hpl > cat1["hal_m"] or vpl > cat1["val_m"])
        t.append(f"HPL {_num(hpl, '.1f')} m  VPL {_num(vpl, '.1f')} m\n", style="bold")
        t.append("category ")
        cat_style = "dim" if integ["category"] is None else "bold green"
        if integ["category"] is not None and (over or integ["category"] < 1):
            cat_style = "bold red"
        t.append(f" {integ['category_name']} ", style=cat_style)
        t.append("\nlimits (HAL/VAL m):")
        for name, lim in integ["limits"].items():
            ok = (
                hpl is not None
                and vpl is not None
                and not integ["lost"]
                and hpl <= lim["hal_m"]
                and vpl <= lim["val_m"]
            )
            t.append(
                f"\n {name.replace('_', ' '):<7} {lim['hal_m']:4.0f}/{lim['val_m']:4.1f} ",
            )
            t.append("met" if ok else "not met", style="green" if ok else "red")
        if integ["lost"]:
            t.append("\nINTEGRITY LOST", style="bold white on red")
        self.query_one("#integrity", Panel).update(t)

        t = Text()
        outg = s["outage_s"]
        t.append("outage  ")
        if outg:
            t.append(f" {outg:5.1f} s ", style="bold black on yellow")
        else:
            t.append(_num(outg, ".1f", " s"))
        t.append(f"\nheading {hdg['state']}", style="bold cyan" if hdg["state"] == "ready" else "")
        t.append(
            f"\n  {_num(hdg['correction_deg'])}° ± {_num(hdg['uncertainty95_deg'])}° (95 %)"
            f"\n  cycles {hdg['cycles'] if hdg['cycles'] is not None else '—'}"
        )
        if hdg["state"] == "ready":
            t.append("\n  c confirm · r refuse", style="bold")
        elif hdg["state"] == "applied":
            t.append("\n  u undo", style="bold")
        self.query_one("#heading", Panel).update(t)

        trk = s["track"]
        t = Text()
        if m.station is None:
            t.append("no station position\n(--station LAT,LON,ALT)", style="dim")
        elif trk is None:
            t.append("waiting for positions", style="dim")
        else:
            t.append(f"az    {trk['az_deg']:7.2f}°  {trk['az_rate_dps']:+.2f}°/s\n")
            t.append(f"el    {trk['el_deg']:7.2f}°  {trk['el_rate_dps']:+.2f}°/s\n")
            t.append(f"range {trk['range_m']:7.0f} m {trk['range_rate_mps']:+.1f} m/s\n")
            t.append(f"± {trk['pointing_sigma_deg']:.2f}° · {trk['range_sigma_m']:.1f} m (1σ)")
            if trk["predicted_s"] > 2.0:
                t.append(f"\npredicted {trk['predicted_s']:.0f} s", style="bold yellow")
        if self.antenna_status:
            t.append(f"\n{self.antenna_status}", style="dim")
        self.query_one("#track", Panel).update(t)

        t = Text()
        if s["last_ack"] is not None:
            ack = s["last_ack"]
            style = "bold green" if ack["result"] == "ACCEPTED" else "bold red"
            t.append(f"COMMAND_ACK {ack['command']}: ", style="bold")
            t.append(ack["result"], style=style)
            t.append("\n")
        t.append(self.status, style="dim")
        t.append(f"\nunacknowledged alerts: {m.unacked()}")
        self.query_one("#decisions", Panel).update(t)

        self._draw_alerts(force_alerts)
        self._draw_plots(now)

    def _draw_alerts(self, force: bool) -> None:
        table = self.query_one("#alerts", DataTable)
        alerts = list(self.model.alerts)
        if force:
            table.clear()
            self._alerts_shown = 0
        if len(alerts) < self._alerts_shown:  # the deque rolled over
            table.clear()
            self._alerts_shown = 0

        for a in alerts[self._alerts_shown :]:
            style = SEVERITY_STYLES.get(a.severity_name, "")
            table.add_row(
                boot_text(a.t_boot_s),
                Text(a.severity_name, style=style),
                Text(a.text, style=style),
                "✓" if a.acked else "",
            )
        if len(alerts) > self._alerts_shown:
            table.move_cursor(row=table.row_count - 1)
        self._alerts_shown = len(alerts)

    def _draw_plots(self, now: float) -> None:
        m = self.model
        acc = self.query_one("#acc-plot", PlotextPlot)
        plt = acc.plt
        plt.clear_data()
        plt.clear_figure()
        t_now = m.boot_time(now)
        plt.title("accuracy 1σ and protection levels, m, log scale (last 5 min)")
        series = {
            name: [(t, v) for t, v in m.history[name] if 0.0 < v < math.inf]
            for name in ("CMP_HACC", "CMP_VACC", "CMP_HPL", "CMP_VPL")
        }
        if t_now is None or not any(series.values()):
            t_now = None  # nothing to draw yet: an empty (linear) frame
        else:
            plt.yscale("log")
        for name, label, color in (
            ("CMP_HACC", "H acc", "green"),
            ("CMP_VACC", "V acc", "cyan"),
            ("CMP_HPL", "HPL", "orange"),
            ("CMP_VPL", "VPL", "magenta"),
        ):
            pts = series[name]
            if pts and t_now is not None:
                plt.plot(
                    [t - t_now for t, _ in pts],
                    [v for _, v in pts],
                    label=label,
                    color=color,
                    marker="braille",
                )
        if t_now is not None and any(m.history[n] for n in ("CMP_HPL", "CMP_VPL")):
            lim = m.snapshot(now)["integrity"]["limits"]
            plt.hline(lim["CAT_I"]["val_m"], "red")
            plt.hline(lim["CAT_III"]["val_m"], "red")
        plt.xlabel("s (red: CAT I and CAT III vertical alert limits)")
        acc.refresh()
        trk = self.query_one("#track-plot", PlotextPlot)
        plt = trk.plt
        plt.clear_data()
        plt.clear_figure()
        plt.title("track, m from the first position (x: now)")
        if m.track:
            lat0, lon0 = m.track[0]
            k_n = math.radians(1.0) * EARTH_RADIUS_M
            k_e = k_n * math.cos(math.radians(lat0))
            north = [(lat - lat0) * k_n for lat, _ in m.track]
            east = [(lon - lon0) * k_e for _, lon in m.track]
            plt.plot(east, north, color="cyan", marker="braille")
            plt.scatter([east[-1]], [north[-1]], color="red", marker="x")
            # the same span on both axes, at least 100 m: a straight line stays straight
            span = max(max(north) - min(north), max(east) - min(east), 100.0) / 2.0
            c_n, c_e = (max(north) + min(north)) / 2.0, (max(east) + min(east)) / 2.0
            plt.ylim(c_n - span, c_n + span)
            plt.xlim(c_e - span, c_e + span)
        plt.xlabel("east, m")
        trk.refresh()
