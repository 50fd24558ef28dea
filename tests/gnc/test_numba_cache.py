"""keepout's numba cache locator (gnc/_numba_cache.py): every kernel goes through it, a cached kernel is
loaded only for the exact sources it was compiled from (its own file and every keepout file it imports),
a cache of another CPU is never loaded, and read-only installs and wheel builds are handled."""
from __future__ import annotations

import importlib
import json
import os
import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from numba.core.registry import CPUDispatcher

import gnc
from gnc import _numba_cache as nc

ROOT = Path(__file__).resolve().parents[2]

# A kernel that calls a kernel of another module: the case numba's own cache gets wrong.
CALLEE = "from numba import njit\n\nK = {k}\n\n\n@njit(cache=True)\ndef inner(x):\n    return x + K\n"
CALLER = textwrap.dedent("""\
    from numba import njit

    from kcpkg.b import inner


    @njit(cache=True)
    def outer(x):
        return 2.0 * inner(x)
    """)
# Runs the caller in a fresh process with kcpkg treated as a keepout package; prints value, hits, misses.
PROBE = textwrap.dedent("""\
    import json, sys
    from pathlib import Path
    sys.path.insert(0, sys.argv[1])
    from gnc import _numba_cache as nc
    nc._ROOT = Path(sys.argv[1]).resolve()
    nc.PACKAGES = nc.PACKAGES + ("kcpkg",)
    from kcpkg.a import outer
    value = outer(1.0)
    print(json.dumps({"value": value, "hits": sum(outer.stats.cache_hits.values()),
                      "misses": sum(outer.stats.cache_misses.values()),
                      "locator": type(outer._cache._impl.locator).__name__}))
    """)


def _tree(root: Path, k: int) -> None:
    pkg = root / "kcpkg"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text(CALLER)
    (pkg / "b.py").write_text(CALLEE.format(k=k))


def _run(root: Path, **env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    out = subprocess.run([sys.executable, "-c", PROBE, str(root)], capture_output=True, text=True, check=True,
                         env={**clean, "PYTHONPATH": str(ROOT), **env}, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_changed_callee_recompiles_the_caller_and_another_cpu_compiles(tmp_path):
    _tree(tmp_path, 1)
    first = _run(tmp_path)
    assert first == {"value": 4.0, "hits": 0, "misses": 1, "locator": "SourceClosureLocator"}
    assert _run(tmp_path)["hits"] == 1  # cached: loaded, not compiled
    (tmp_path / "kcpkg" / "b.py").write_text(CALLEE.format(k=5))  # only the callee's file changes
    after = _run(tmp_path)
    assert after["value"] == 12.0 and after["hits"] == 0  # recompiled with the new callee
    assert _run(tmp_path)["hits"] == 1
    # a cache built on another CPU is never loaded: that machine compiles (numba keys entries on the CPU)
    other_cpu = _run(tmp_path, NUMBA_CPU_NAME="generic")
    assert other_cpu["value"] == 12.0 and other_cpu["hits"] == 0


def test_numba_s_own_locator_would_load_the_stale_kernel(tmp_path):
    """The scenario above is a real hazard: with numba's in-tree locator the caller keeps the old callee."""
    _tree(tmp_path, 1)
    stock = {"NUMBA_CACHE_LOCATOR_CLASSES": "InTreeCacheLocator"}
    assert _run(tmp_path, **stock)["value"] == 4.0
    (tmp_path / "kcpkg" / "b.py").write_text(CALLEE.format(k=5))
    stale = _run(tmp_path, **stock)
    assert stale["hits"] == 1 and stale["value"] == 4.0  # the old machine code, K = 1


def _keepout_modules():
    for pkg in nc.PACKAGES:
        yield pkg
        for info in pkgutil.walk_packages([str(ROOT / pkg)], prefix=f"{pkg}."):
            if not info.name.endswith("__main__"):
                yield info.name


def test_every_cached_kernel_of_the_packages_goes_through_the_locator():
    """Kernels added later are covered with no edit: the locator takes any function of these packages,
    and gnc, which fsw and hil_sim import first, installs it before any kernel is decorated."""
    kernels = []
    for name in _keepout_modules():
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue  # an optional extra (dask, playwright) that is not installed
        for obj in vars(module).values():
            if isinstance(obj, CPUDispatcher) and obj.__module__ == name and obj._cache.cache_path is not None:
                kernels.append(obj)
    assert len(kernels) > 40
    wrong = [k.__qualname__ for k in kernels if type(k._cache._impl.locator) is not nc.SourceClosureLocator]
    assert not wrong
    assert nc.SourceClosureLocator in gnc._numba_cache._CACHE_IMPL._locator_classes


def test_closure_follows_imports_across_modules():
    files = {p.relative_to(ROOT).as_posix() for p in nc.closure_files((ROOT / "hil_sim" / "world" / "world.py").resolve())}
    # the world step compiles the dynamics, orbit and ephemeris kernels into itself
    assert {"hil_sim/world/dynamics.py", "hil_sim/world/orbit.py", "hil_sim/world/ephemeris.py", "gnc/attitude.py"} <= files
    assert "hil_sim/sil/orchestrator.py" not in files and "fsw/app.py" not in files


def test_relative_imports_count(tmp_path, monkeypatch):
    pkg = tmp_path / "kcpkg"
    (pkg / "sub").mkdir(parents=True)
    for f in ("__init__.py", "sub/__init__.py", "sub/leaf.py", "helper.py"):
        (pkg / f).write_text("")
    (pkg / "sub" / "mod.py").write_text("from . import leaf\nfrom ..helper import x\n")
    monkeypatch.setattr(nc, "_ROOT", tmp_path.resolve())
    monkeypatch.setattr(nc, "PACKAGES", ("kcpkg",))
    files = {p.relative_to(tmp_path.resolve()).as_posix() for p in nc.closure_files((pkg / "sub" / "mod.py").resolve())}
    assert files == {"kcpkg/__init__.py", "kcpkg/sub/__init__.py", "kcpkg/sub/mod.py", "kcpkg/sub/leaf.py",
                     "kcpkg/helper.py"}


def test_read_only_install_seeds_the_user_cache(tmp_path, monkeypatch):
    from gnc.attitude import quat_multiply_nb

    shipped = Path(quat_multiply_nb.py_func.__code__.co_filename).resolve().parent / "__pycache__"
    writable = nc._writable
    monkeypatch.setattr(nc, "_writable", lambda folder: Path(folder) != shipped and writable(folder))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(nc.config, "CACHE_DIR", "")
    locator = nc.SourceClosureLocator.from_function(quat_multiply_nb.py_func, quat_multiply_nb.py_func.__code__.co_filename)
    folder = Path(locator.get_cache_path())
    assert folder.is_relative_to(tmp_path / "keepout" / "numba")
    prefix = f"attitude.quat_multiply_nb-{quat_multiply_nb.py_func.__code__.co_firstlineno}."
    seeded = {p.name for p in folder.iterdir()}
    assert seeded and seeded == {p.name for p in shipped.glob(prefix + "*.nb[ic]")}


def test_stale_files_are_the_ones_no_current_kernel_loads(tmp_path, monkeypatch):
    import pickle

    import numba

    monkeypatch.setattr(nc, "_ROOT", tmp_path.resolve())
    folder = tmp_path / "gnc" / "__pycache__"
    folder.mkdir(parents=True)
    (tmp_path / "gnc" / "laws.py").write_bytes((ROOT / "gnc" / "laws.py").read_bytes())
    current = ("keepout-source-closure", nc.STAMP_VERSION, nc.source_digest(tmp_path / "gnc" / "laws.py"))

    def index(name: str, stamp, data: str, version: str = numba.__version__) -> None:
        with open(folder / name, "wb") as f:
            pickle.dump(version, f)
            f.write(pickle.dumps((stamp, {"sig": data})))
        (folder / data).write_bytes(b"x")

    index("laws.f-1.py311.nbi", current, "laws.f-1.py311.1.nbc")
    index("laws.g-9.py311.nbi", current[:2] + ("0" * 64,), "laws.g-9.py311.1.nbc")  # older sources
    index("laws.h-20.py311.nbi", current, "laws.h-20.py311.1.nbc", version="0.1.0")  # another numba
    (folder / "laws.f-1.py311.2.nbc").write_bytes(b"orphan")
    assert {p.name for p in nc.stale_files([folder])} == {
        "laws.g-9.py311.nbi", "laws.g-9.py311.1.nbc", "laws.h-20.py311.nbi", "laws.h-20.py311.1.nbc",
        "laws.f-1.py311.2.nbc"}


@pytest.mark.parametrize("name", ["hil_sim/world/world.py", "fsw/estimation.py"])
def test_digest_is_stable_and_content_based(name):
    a = nc.source_digest(ROOT / name)
    assert a == nc.source_digest(str(ROOT / name)) and len(a) == 64


def test_the_locator_is_installed_when_numba_loads_not_before():
    """`import gnc` does not import numba (the ground monitor never needs it), yet the first kernel
    decorated after numba loads goes through the locator, whichever of the two is imported first."""
    probe = ("import sys, {first}, {second}\n"
             "import numba.core.caching as c\n"
             "from gnc._numba_cache import SourceClosureLocator\n"
             "assert c.CacheImpl._locator_classes[0] is SourceClosureLocator, c.CacheImpl._locator_classes\n")
    alone = "import sys, gnc\nassert 'numba' not in sys.modules\n"
    for code in (alone, probe.format(first="gnc", second="numba"), probe.format(first="numba", second="gnc")):
        subprocess.run([sys.executable, "-c", code], check=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
                       timeout=120)
