"""The operator's alarm list: limit violations, FDIR trips and keep-out events, each to acknowledge.

Built from the run's archive in archive order, so an alarm's number is the same for every page and every
server over the same archive, live or replayed. A limited channel raises an alarm when it leaves GREEN (or
goes from YELLOW to RED) and clears it when it comes back; an FDIR trip, a keep-out event or any FATAL
event is an alarm of its own. Acknowledgements are the operator's word: kept beside the archive
(``alarm_acks.jsonl``, one line per acknowledgement) so a restarted console still knows them.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from comms.dictionary import LimitState, TelemetryDictionary

if TYPE_CHECKING:
    from comms.telemetry import DecodedTm

ACKS_FILE = "alarm_acks.jsonl"
ALARM_EVENTS = ("FDIR_TRIPPED", "KEEP_OUT_MARGIN_LOW", "KEEP_OUT_VIOLATION")
_RANK = {LimitState.GREEN: 0, LimitState.YELLOW: 1, LimitState.RED: 2}


@dataclass
class Alarm:
    alarm_id: int
    onboard_s: float
    utc: float
    severity: str  # RED / YELLOW for limits, the event's severity for events
    source: str  # the channel's display name, or the event's name
    message: str
    cleared_onboard_s: float | None = None
    acknowledged: bool = False


class AlarmBook:
    """Alarms of one archive, in archive order, and the acknowledgements given to them."""

    def __init__(self, dictionary: TelemetryDictionary, names: dict[str, str] | None = None,
                 acks_path: Path | None = None) -> None:
        self.alarms: list[Alarm] = []
        self._names = names or {}
        self._limited = {p.name: [(i, c) for i, c in enumerate(p.channels)
                                  if c.limits is not None and c.type not in ("BOOL", "ENUM")]
                         for p in dictionary.packets}
        self._state: dict[str, tuple[LimitState, Alarm | None]] = {}
        self._acks_path = acks_path
        self._acked: set[int] = set()
        if acks_path is not None and acks_path.is_file():
            for line in acks_path.read_text(encoding="utf-8").splitlines():
                try:
                    self._acked.add(int(json.loads(line)["alarm_id"]))
                except (ValueError, KeyError, TypeError):
                    continue  # a torn last line of a killed console: the other acknowledgements stand

    def observe(self, rx_time_s: float, packet: DecodedTm) -> None:
        if packet.kind == "event":
            if packet.event in ALARM_EVENTS or packet.severity == "FATAL":
                self._raise(packet.time_s, rx_time_s, packet.severity, packet.event, packet.message)
            return
        for _, channel in self._limited.get(packet.packet, ()):
            value = packet.values.get(channel.name)
            if not isinstance(value, (int, float)):
                continue
            state = channel.limits.check(value)
            before, alarm = self._state.get(channel.name, (LimitState.GREEN, None))
            if state == before:
                continue
            if alarm is not None and _RANK[state] < _RANK[before]:
                alarm.cleared_onboard_s = packet.time_s
                alarm = None
            if _RANK[state] > _RANK[before]:
                alarm = self._raise(packet.time_s, rx_time_s, state.value, self._names.get(channel.name, channel.name),
                                    _limit_message(channel, value, state))
            self._state[channel.name] = (state, alarm)

    def _raise(self, onboard_s: float, rx_time_s: float, severity: str, source: str, message: str) -> Alarm:
        alarm = Alarm(len(self.alarms), round(onboard_s, 3), rx_time_s * 1000.0, severity, source, message)
        alarm.acknowledged = alarm.alarm_id in self._acked
        self.alarms.append(alarm)
        return alarm

    def acknowledge(self, alarm_ids: list[int], operator: str = "") -> int:
        """Acknowledge these alarms (unknown ids are an error, nothing is recorded); returns how many
        were newly acknowledged."""
        unknown = [i for i in alarm_ids if not 0 <= i < len(self.alarms)]
        if unknown:
            raise KeyError(f"no alarm {unknown[0]} (alarms are numbered 0..{len(self.alarms) - 1})")
        new = [i for i in dict.fromkeys(alarm_ids) if not self.alarms[i].acknowledged]
        for i in new:
            self.alarms[i].acknowledged = True
            self._acked.add(i)
        if new and self._acks_path is not None:
            with open(self._acks_path, "a", encoding="utf-8") as out:
                for i in new:
                    out.write(json.dumps({"alarm_id": i, "source": self.alarms[i].source, "operator": operator,
                                          "acknowledged_utc_s": round(time.time(), 3)}) + "\n")
        return len(new)

    def to_json(self) -> dict[str, Any]:
        return {"alarms": [asdict(a) for a in self.alarms],
                "unacknowledged": sum(not a.acknowledged for a in self.alarms)}


def _limit_message(channel: Any, value: float, state: LimitState) -> str:
    """"1.5 deg, below 2 deg (yellow limit)": the value and the bound it crossed."""
    low, high = channel.limits.red if state == LimitState.RED else channel.limits.yellow
    unit = f" {channel.unit}" if channel.unit else ""
    side, bound = ("above", high) if high is not None and value > high else ("below", low)
    return f"{value:.4g}{unit}, {side} {bound:g}{unit} ({state.value.lower()} limit)"
