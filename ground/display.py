"""The terminal display of ``keepout ground``: key channels coloured by their limits, link, events."""
from __future__ import annotations

from typing import Any, Protocol

from comms.dictionary import LimitState, TelemetryDictionary


class MonitorView(Protocol):
    """What the display reads of a monitor (ground.monitor.GroundMonitor, which draws through it)."""

    dictionary: TelemetryDictionary
    latest: dict[str, Any]
    latest_time_s: Any
    stats: Any
    events: Any

KEY_CHANNELS = (
    "mode", "safe_phase", "cycle", "pointing_error_deg", "att_error_deg", "margin_min_deg",
    "active_zone", "eps", "rate_norm_deg_s", "cov_trace", "st_valid", "st_blind_source",
    "wheel_speed_rad_s_0", "wheel_speed_rad_s_1", "wheel_speed_rad_s_2", "wheel_speed_rad_s_3",
    "torque_scale", "exec_time_ms", "slips_gnc", "exec_max_ms_gnc", "bus_crc_errors",
    "bus_alive_errors", "tc_accepted", "tc_rejected", "tm_send_errors", "fdir_trips",
)

_LIMIT_STYLE = {LimitState.GREEN: "green", LimitState.YELLOW: "bold yellow", LimitState.RED: "bold red"}
_SEVERITY_STYLE = {"FATAL": "bold white on red", "WARNING_HI": "bold red", "WARNING_LO": "yellow",
                   "COMMAND": "cyan", "ACTIVITY_HI": "bold", "ACTIVITY_LO": "", "DIAGNOSTIC": "dim"}


def limit_state(dictionary: TelemetryDictionary, name: str, value: Any) -> LimitState | None:
    """Dictionary limit state of a channel value (None when the channel has no limits or no number)."""
    channel = dictionary.channel(name)
    if channel.limits is None or isinstance(value, (str, bool)) or value != value:  # NaN: no value
        return None
    return channel.limits.check(value)


class LiveDisplay:
    """A rich Live table of a monitor, redrawn by the monitor's receive loop."""

    def __init__(self, monitor: MonitorView) -> None:
        from rich.console import Console
        from rich.live import Live

        self.monitor = monitor
        self.live = Live(console=Console(), auto_refresh=False)

    def start(self) -> None:
        self.live.start()

    def stop(self) -> None:
        self.update()
        self.live.stop()
        if not self.live.console.is_terminal:
            self.live.console.line()

    def update(self) -> None:
        self.live.update(render_tables(self.monitor), refresh=True)


def render_tables(monitor: MonitorView) -> Any:
    """A rich renderable: key channels with limit colours, link statistics and the latest events."""
    from rich.console import Group
    from rich.table import Table

    dictionary = monitor.dictionary
    channels = Table(title=f"keepout telemetry  t={monitor.latest_time_s}", expand=False)
    for column in ("channel", "value", "unit", "limit"):
        channels.add_column(column)
    for name in KEY_CHANNELS:
        if name not in monitor.latest:
            continue
        value = monitor.latest[name]
        state = limit_state(dictionary, name, value)
        text = f"{value:.5g}" if isinstance(value, float) else str(value)
        style = _LIMIT_STYLE[state] if state is not None else ""
        channels.add_row(name, text, dictionary.channel(name).unit, state.value if state else "", style=style)
    stats = monitor.stats
    link = Table(title="link", expand=False)
    for column in ("datagrams", "decoded", "decode errors", "gaps", "missing", "forged/unauthenticated"):
        link.add_column(column)
    link.add_row(str(stats.datagrams), str(stats.decoded), str(stats.decode_errors), str(len(stats.gaps)),
                 str(stats.missing), ", ".join(f"{k} {n}" for k, n in sorted(stats.rejected.items())) or "0",
                 style="bold red" if stats.missing or stats.decode_errors or stats.rejected else "")
    if stats.decode_errors:  # what the undecodable packets were, and the last one's reason
        kinds = ", ".join(f"{kind} {n}" for kind, n in sorted(stats.decode_errors_by_kind.items()))
        link.caption = f"undecoded: {kinds}; last: {stats.last_decode_error[:100]}"
    events = Table(title="latest events", expand=False)
    for column in ("time_s", "severity", "event", "message"):
        events.add_column(column)
    for event in reversed(monitor.events):
        events.add_row(f"{event.time_s:.2f}", event.severity or "", event.event or "", event.message or "",
                       style=_SEVERITY_STYLE.get(event.severity or "", ""))
    return Group(channels, link, events)
