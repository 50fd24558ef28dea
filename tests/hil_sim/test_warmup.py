"""`keepout warmup` (run by `make setup`) runs a shipped mission's check and closed loop, saying so."""
from __future__ import annotations

import io

import pytest

from cli.main import main as keepout
from hil_sim import warmup
from hil_sim.warmup import warm
from keepout_config import config_path


def test_warmup_runs_the_check_and_the_closed_loop_of_a_mission():
    out = io.StringIO()
    warm([str(config_path("missions", "demo-pointing.yaml"))], seconds=0.5, out=out)
    line = out.getvalue()
    assert line.startswith("[1/1] demo-pointing: physics check ... closed loop ... ready (") and line.endswith(" s)\n")


@pytest.mark.parametrize("prune", [False, True])
def test_keepout_warmup_warms_the_missions_named_and_prunes_only_when_asked(monkeypatch, capsys, prune: bool):
    calls = []
    monkeypatch.setattr(warmup, "warm", lambda missions: calls.append(("warm", missions)) or 1.5)
    monkeypatch.setattr(warmup, "prune", lambda: calls.append(("prune",)) or 0)
    assert keepout(["warmup", "a.yaml", "b.yaml", *(["--prune"] if prune else [])]) == 0
    assert calls == [("warm", ["a.yaml", "b.yaml"])] + ([("prune",)] if prune else [])
    assert capsys.readouterr().out.endswith("kernels ready in 1.5 s\n")
