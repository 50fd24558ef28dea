"""`python -m hil_sim.warmup` (run by `make setup`) runs a shipped mission's check and closed loop, saying so."""
from __future__ import annotations

import io

from hil_sim.warmup import warm
from keepout_config import config_path


def test_warmup_runs_the_check_and_the_closed_loop_of_a_mission():
    out = io.StringIO()
    warm([str(config_path("missions", "demo-pointing.yaml"))], seconds=0.5, out=out)
    line = out.getvalue()
    assert line.startswith("[1/1] demo-pointing: physics check ... closed loop ... ready (") and line.endswith(" s)\n")
