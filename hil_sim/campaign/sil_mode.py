"""The ``sil`` execution mode: each run is a full three-process SIL run (``hil_sim.sil.orchestrator.run_sil``).

The dispersed mission is written to a YAML file and run like ``keepout sil run``: simulator in this
worker process, the flight software (``python -m fsw``) and the ground monitor as their own processes,
lockstep over ``udp_multicast`` with a multicast group and port drawn at random for each run
(`comms.bus.transport.random_udp_endpoint`), so runs executing side by side never share a bus. (SocketCAN's vcan0 is one shared bus: a campaign of
several concurrent runs cannot use it, so a mission's ``socketcan`` bus is replaced here.)

The run is judged by the same ``fast.judge`` on the run folder's ``truth.npz`` and the FDIR trips and
slips of its ``summary.json``; the dispersed values are read back from the run folder's
``mission.yaml``, the configuration the three processes were started from.
"""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any, Sequence

import yaml

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.execute import RunResult


def _requirement(summary: dict[str, Any], name: str) -> Any:
    for r in summary.get("requirements", []):
        if r.get("name") == name:
            return r.get("value")
    return None


class SilRunError(RuntimeError):
    """The SIL run did not run to its end (not started, crashed, interrupted, telemetry lost): the
    campaign records it as an error, never as a requirement failure."""


def run_sil(mission: Any, seed: int, mode: str = "sil", paths: Sequence[str] = ()) -> RunResult:
    from hil_sim.sil import orchestrator as sil
    from hil_sim.sil import judge as summary_mod
    from hil_sim.campaign.fast import judge
    from hil_sim.mission.model import load_mission

    data = mission.model_dump(mode="json")
    if not str(data.get("bus", "auto")).startswith("udp_multicast"):
        data["bus"] = "udp_multicast"  # a random group and port per run: concurrent runs never share a bus
    data["tmtc_ports"] = "auto"  # free UDP ports per run for telemetry and telecommands
    with tempfile.TemporaryDirectory(prefix="keepout-campaign-sil-") as tmp:
        mission_path = Path(tmp) / f"{mission.name}.yaml"
        mission_path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        try:
            result = sil.run_sil(sil.RunOptions(mission=mission_path, out_root=Path(tmp) / "runs", progress=False))
        except (sil.MissionRejected, sil.RunNotStarted) as exc:
            raise SilRunError(f"the SIL run could not start: {exc}") from None
        run_dir = Path(result.run_dir)
        report = result.summary or summary_mod._read_json(run_dir / "summary.json")
        status = report.get("status", "completed")
        aborted = summary_mod._read_json(run_dir / sil.SIM_STATS_FILE).get("aborted")
        if status != sil.STATUS_COMPLETED or aborted:
            raise SilRunError(f"the SIL run did not run to its end: {aborted or status}")
        truth = summary_mod.load_truth(run_dir)
        used_mission = load_mission(run_dir / "mission.yaml")
        trips = [str(m) for m in report.get("fdir_trips", [])]
        slips = _requirement(report, "cycle slips")
        metrics, trajectory = judge(used_mission, truth, trips, float("nan") if slips is None else float(slips),
                                    gains_set=summary_mod.acknowledged_rate_limits_of_run(run_dir))
        used = {p: dsp.read_path(used_mission, dsp.parse_path(p)) for p in paths}
        sim_time = float(truth["t_s"][-1]) if len(truth["t_s"]) else 0.0
        return RunResult(metrics=metrics, used=used, trajectory=trajectory, sim_time_s=sim_time,
                         events=[f"FDIR_TRIPPED {m}" for m in trips])
