"""Execute a campaign: many runs on a local process pool or a Dask cluster, through one code path.

Both backends are used through the same two calls (``submit`` and ``as_completed``): a
``concurrent.futures.ProcessPoolExecutor`` (default, one worker per core) or a
``distributed.Client`` (``--scheduler tcp://host:8786``, or a ``LocalCluster``). Each run's record is
written by this (driver) process as soon as it arrives, as ``runs/run-000017.json`` plus
``run-000017.npz`` (trajectory), atomically; so workers need no shared filesystem, Ctrl-C keeps every
finished run, and running again into the same folder skips the finished ones. A run's inputs depend
only on (master seed, run index), never on the backend, the number of workers or the order of completion.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np
import yaml

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.execute import (STATUS_ERROR, STATUS_FAIL, Plan, RunRecord, execute_run,
                                      resolve_run_function)
from hil_sim.campaign.spec import Campaign, load_campaign, resolve_base_mission

MODE_RUN_FUNCTIONS = {
    "fast": "hil_sim.campaign.fast:run_fast",
    "sil": "hil_sim.campaign.sil_mode:run_sil",
}
RUNS_DIR = "runs"
PLAN_FILE = "plan.json"


class CampaignMismatch(RuntimeError):
    """An output folder holds runs of a different campaign (inputs changed): refuse to mix them."""


# ---------------------------------------------------------------------------------------------
# Building a plan
# ---------------------------------------------------------------------------------------------

def build_plan(campaign_path: str | Path, *, mode: str | None = None, runs: int | None = None,
               run_function: Callable[..., Any] | None = None, model_class: type | None = None,
               campaign: Campaign | None = None) -> tuple[Plan, Path]:
    """Load the campaign and its base mission, check every dispersion path, and return the plan and the
    base mission file. ``run_function``/``model_class`` default to the mode's function and
    ``hil_sim.mission.model.Mission`` (tests inject small deterministic stand-ins)."""
    campaign = campaign or load_campaign(campaign_path)
    if runs is not None:
        campaign = campaign.model_copy(update={"runs": int(runs)})
    if mode is not None:
        campaign = campaign.model_copy(update={"mode": mode})
    base_path = resolve_base_mission(campaign_path, campaign)
    if model_class is None:
        from hil_sim.mission.model import Mission, load_mission
        model_class = Mission
        base_model = load_mission(base_path)  # file:line:col errors for a bad base mission
    else:
        from hil_sim.mission.loader import load_model
        base_model = load_model(base_path, model_class)
    from hil_sim.mission.loader import load_marked
    base_raw = load_marked(base_path).data
    if model_class.__name__ == "Mission":
        # the flight software's knowledge is fixed from the values written in the file, before any
        # dispersion: a dispersed truth value never reaches the flight software
        from hil_sim.mission.model import written_once
        base_raw = written_once(base_raw)
    nominal = dsp.nominal_values(campaign.dispersions, base_model)
    fn = run_function or resolve_run_function(MODE_RUN_FUNCTIONS[campaign.mode])
    plan = Plan(campaign=campaign, base_raw=base_raw, nominal=nominal, model_class=model_class,
                run_function=fn, mode=campaign.mode)
    # Fail before any run when the dispersed values cannot even build a valid mission.
    plan.mission(plan.draw(0), 0)
    return plan, base_path


# ---------------------------------------------------------------------------------------------
# Run folders
# ---------------------------------------------------------------------------------------------

def default_out_dir(campaign: Campaign, root: str | Path = "campaigns") -> Path:
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return Path(root) / f"{campaign.name}-{stamp}"


def latest_out_dir(campaign: Campaign, root: str | Path = "campaigns") -> Path | None:
    found = sorted(Path(root).glob(f"{campaign.name}-*/{PLAN_FILE}"))
    return found[-1].parent if found else None


def run_path(out_dir: Path, index: int, suffix: str = ".json") -> Path:
    return out_dir / RUNS_DIR / f"run-{index:06d}{suffix}"


def prepare_out_dir(out_dir: Path, plan: Plan, campaign_path: Path, base_path: Path) -> None:
    """Create (or check, when resuming) the output folder; keep copies of the inputs next to the runs."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / RUNS_DIR).mkdir(exist_ok=True)
    meta_path = out_dir / PLAN_FILE
    meta = {"campaign": plan.campaign.name, "fingerprint": plan.campaign.fingerprint(),
            "mission_sha256": _sha256(base_path), "master_seed": plan.campaign.master_seed,
            "mode": plan.mode, "runs": plan.campaign.runs}
    if meta_path.exists():
        old = json.loads(meta_path.read_text())
        for key in ("fingerprint", "mission_sha256", "mode"):
            if old.get(key) != meta[key]:
                raise CampaignMismatch(f"{out_dir} holds runs of a different campaign ({key} changed: "
                                       f"{old.get(key)} -> {meta[key]}); use a new output folder")
        meta["runs"] = max(int(old.get("runs", 0)), meta["runs"])
    meta["created_utc"] = datetime.now(timezone.utc).isoformat()
    _atomic_write(meta_path, json.dumps(meta, indent=2))
    if not (out_dir / "mission.yaml").exists():
        shutil.copyfile(base_path, out_dir / "mission.yaml")
    # The campaign as run (command-line overrides applied), pointing at the mission copy beside it, so
    # `rerun` and `shrink` rebuild exactly this plan from the folder alone.
    effective = plan.campaign.model_copy(update={"base_mission": "mission.yaml"}).model_dump(mode="json")
    _atomic_write(out_dir / "campaign.yaml", f"# campaign as run, from {campaign_path}\n"
                  + yaml.safe_dump(effective, sort_keys=False))


def finished_runs(out_dir: Path) -> set[int]:
    return {int(p.stem.split("-")[1]) for p in (out_dir / RUNS_DIR).glob("run-*.json")}


def save_record(out_dir: Path, record: RunRecord) -> None:
    if record.trajectory:
        tmp = run_path(out_dir, record.run, ".tmp.npz")
        np.savez_compressed(tmp, **record.trajectory)
        os.replace(tmp, run_path(out_dir, record.run, ".npz"))
    # The JSON goes last: its presence is what marks the run finished.
    _atomic_write(run_path(out_dir, record.run), json.dumps(record.to_json(), indent=1, allow_nan=True))


def load_records(out_dir: Path) -> list[RunRecord]:
    records = []
    for path in sorted((out_dir / RUNS_DIR).glob("run-*.json")):
        records.append(RunRecord.from_json(json.loads(path.read_text())))
    return records


def load_trajectory(out_dir: Path, index: int) -> dict[str, np.ndarray]:
    path = run_path(out_dir, index, ".npz")
    if not path.exists():
        return {}
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _sha256(path: Path) -> str:
    import hashlib
    return hashlib.sha256(path.read_bytes()).hexdigest()


# ---------------------------------------------------------------------------------------------
# Backends (same two calls for both)
# ---------------------------------------------------------------------------------------------

def _init_worker() -> None:
    """A pool worker: Ctrl-C is the driver's to handle (it cancels what is pending and stops the workers
    itself), and the worker dies with its parent, the forkserver, which ends when the driver does (its pipe
    from the driver closes): a SIGKILLed `keepout campaign run` leaves no worker flying a run."""
    import signal

    from fsw.lifetime import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()


# What a fast-mode run imports, loaded once by the forkserver so each worker starts with it instead of
# importing it on its own (~1.5 s per worker, which is wall time whenever workers share a core).
# (first: the forkserver's own lifetime, see hil_sim.campaign._forkserver_lifetime)
_FORKSERVER_PRELOAD = ("hil_sim.campaign._forkserver_lifetime", "hil_sim.campaign.fast", "hil_sim.world.world",
                       "hil_sim.sil.lockstep", "hil_sim.sil.orchestrator", "hil_sim.sil.judge", "hil_sim.mission.model", "fsw.app", "fsw.bus",
                       "fsw.telecommand")


class _LocalBackend:
    def __init__(self, workers: int):
        import multiprocessing
        # forkserver: workers start clean (no threads or open sockets inherited from the driver); it
        # imports the modules above itself (none starts a thread or opens anything at import)
        from hil_sim.campaign._forkserver_lifetime import DRIVER_PID_ENV

        os.environ[DRIVER_PID_ENV] = str(os.getpid())  # the forkserver, started with this environment, dies with us
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(list(_FORKSERVER_PRELOAD))
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_init_worker)

    def submit(self, fn: Callable, *args: Any) -> Any:
        return self.pool.submit(fn, *args)

    def as_completed(self, futures: list[Any]) -> Iterable[Any]:
        from concurrent.futures import as_completed
        return as_completed(futures)

    def close(self, cancel: bool = False) -> None:
        if cancel:  # do not wait for the runs in progress: their results would be thrown away anyway
            for proc in list(getattr(self.pool, "_processes", {}).values()):
                proc.terminate()
        self.pool.shutdown(wait=True, cancel_futures=cancel)


class _DaskBackend:
    def __init__(self, scheduler: Any):
        from distributed import Client
        self.own_client = not hasattr(scheduler, "submit")
        self.client = Client(scheduler) if self.own_client else scheduler

    def submit(self, fn: Callable, *args: Any) -> Any:
        return self.client.submit(fn, *args, pure=False)

    def as_completed(self, futures: list[Any]) -> Iterable[Any]:
        from distributed import as_completed
        return as_completed(futures)

    def close(self, cancel: bool = False, futures: list[Any] = ()) -> None:
        if cancel and futures:
            self.client.cancel(list(futures))
        if self.own_client:
            self.client.close()


@dataclass
class Progress:
    total: int
    done: int = 0
    failures: int = 0
    errors: int = 0
    skipped: int = 0
    started: float = field(default_factory=time.perf_counter)


@dataclass
class Outcome:
    out_dir: Path
    records: list[RunRecord]
    interrupted: bool = False
    wall_s: float = 0.0
    executed: int = 0


def run_campaign(plan: Plan, out_dir: Path, *, workers: int | None = None, scheduler: Any = None,
                 indices: Iterable[int] | None = None,
                 on_progress: Callable[[Progress, RunRecord | None], None] | None = None) -> Outcome:
    """Execute the runs not yet finished in ``out_dir`` and return every record there.

    ``scheduler``: a Dask scheduler address or ``distributed.Client``; otherwise a local process pool
    of ``workers`` processes (default: all cores). Ctrl-C cancels pending runs and returns with
    ``interrupted=True``; finished runs are on disk.
    """
    wanted = set(range(plan.campaign.runs) if indices is None else indices)
    todo = sorted(wanted - finished_runs(out_dir))
    progress = Progress(total=len(wanted), skipped=len(wanted) - len(todo))
    progress.done = progress.skipped
    todo_set = set(todo)
    for record in load_records(out_dir):
        if record.run in wanted and record.run not in todo_set and record.status in (STATUS_FAIL, STATUS_ERROR):
            progress.failures += 1
    if on_progress:
        on_progress(progress, None)
    start = time.perf_counter()
    interrupted = False
    if todo:
        backend = _DaskBackend(scheduler) if scheduler is not None else _LocalBackend(workers or os.cpu_count() or 1)
        futures = []
        try:
            futures = [backend.submit(execute_run, plan, i) for i in todo]
            for future in backend.as_completed(futures):
                record = future.result()
                save_record(out_dir, record)
                progress.done += 1
                progress.failures += record.status in (STATUS_FAIL, STATUS_ERROR)
                progress.errors += record.status == STATUS_ERROR
                if on_progress:
                    on_progress(progress, record)
        except (KeyboardInterrupt, BrokenProcessPool):
            interrupted = True
            for f in futures:
                f.cancel()
        finally:
            if isinstance(backend, _DaskBackend):
                backend.close(cancel=interrupted, futures=futures)
            else:
                backend.close(cancel=interrupted)
    return Outcome(out_dir=out_dir, records=load_records(out_dir), interrupted=interrupted,
                   wall_s=time.perf_counter() - start, executed=progress.done - progress.skipped)


# ---------------------------------------------------------------------------------------------
# After the runs: tables, JUnit, report
# ---------------------------------------------------------------------------------------------

def finalize(plan: Plan, out_dir: Path, records: list[RunRecord] | None = None, *, report: bool = True) -> dict[str, Any]:
    """Write results.parquet/.csv, junit.xml and the report for the runs in ``out_dir``."""
    from hil_sim.campaign import results
    records = load_records(out_dir) if records is None else records
    records = [r for r in records if r.run < plan.campaign.runs]
    df = results.table(plan.campaign, records)
    parquet, csv = results.write_tables(df, out_dir)
    junit = results.junit_xml(plan.campaign, records, out_dir / "junit.xml")
    verdict = results.verdict(plan.campaign, records)
    out: dict[str, Any] = {"parquet": parquet, "csv": csv, "junit": junit, "verdict": verdict, "table": df}
    if report:
        from hil_sim.campaign.report import worst_runs, write_report
        worst = worst_runs(plan.campaign, records)
        trajectories = {r.run: load_trajectory(out_dir, r.run) for r in worst}
        starts = None
        if any(getattr(d, "kind", "") == "attitude" and d.max_angle_deg is None for d in plan.campaign.dispersions):
            starts = {}  # initial attitudes uniform on SO(3): the basin picture needs every run's start
            for r in records:
                traj = load_trajectory(out_dir, r.run)
                path = traj.get("boresight_N", traj.get("x"))
                if path is not None and path.ndim == 2 and path.shape[1] == 3 and len(path):
                    starts[r.run] = path[0]
        out["report"] = write_report(plan.campaign, df, records, verdict, trajectories, out_dir, starts)
    (out_dir / "verdict.txt").write_text(verdict.text() + "\n", encoding="utf-8")
    return out
