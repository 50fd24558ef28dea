"""Where keepout's compiled numba kernels are cached, and when a cached kernel is still the right one.

Every ``@njit(cache=True)`` kernel in the code packages (gnc, comms, fsw, hil_sim, ground) goes through
`SourceClosureLocator`, put first in numba's locator list as soon as numba's caching module loads
(`gnc._after_numba`, armed by ``import gnc``; fsw and hil_sim import gnc first, so no kernel is decorated
before it). Kernels added later are covered with no edit: the locator takes any function whose file
lies in those packages.

Why not numba's own locator: it stamps a cache with the content of the kernel's *own* file only. A kernel
that calls a kernel of another module (the world step calls dynamics, orbit and ephemeris kernels) has
the callee compiled into it, so after an edit of the callee's file numba would load the old machine code.
Here the stamp is the SHA-256 of every keepout source file the kernel's module imports, directly or
through other keepout modules (a static over-approximation: any import line counts, also inside
functions; this machinery itself is left out, it compiles into no kernel). Change any of them and the
kernel compiles again. numba's own index keys add the numba version, the Python version, the kernel's
bytecode, its argument types and the CPU (name and features), so a cache built on another CPU is never
loaded: that machine compiles, as with no cache.

Where: ``NUMBA_CACHE_DIR`` if set (as numba), else ``__pycache__`` beside the source when writable (an
editable checkout, a venv; a wheel built by ``make wheel`` ships these files), else the user cache folder
(``$XDG_CACHE_HOME/keepout/numba``), seeded from the shipped files of that kernel.
"""
from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import tempfile
from pathlib import Path

from numba.core import caching, config

# numba >= 0.61 names it CacheImpl, earlier _CacheImpl: the class whose _locator_classes numba walks
_CACHE_IMPL = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")

PACKAGES = ("gnc", "comms", "fsw", "hil_sim", "ground")  # the code packages whose imports make up a kernel's closure
STAMP_VERSION = 1  # bump when the stamp's meaning changes: every cached kernel is then compiled again
# the cache machinery: imported by every package's __init__, compiled into no kernel (STAMP_VERSION covers it)
_NOT_SOURCES = frozenset({"gnc._numba_cache", "gnc._after_numba"})

_ROOT = Path(__file__).resolve().parent.parent  # the folder holding the packages (checkout or site-packages)
# `import a.b as c, d` and `from .x import (y, z)`, also indented (imports inside functions count)
_IMPORT_RE = re.compile(r"^[ \t]*import[ \t]+([\w., \t]+)", re.M)
_FROM_RE = re.compile(r"^[ \t]*from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]+)", re.M)


def user_cache_dir() -> Path:
    """keepout's per-user cache folder (``$XDG_CACHE_HOME/keepout`` or ``~/.cache/keepout``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "keepout"


def _module_of(path: Path) -> str | None:
    """Dotted module name of a source file inside one of PACKAGES, else None."""
    try:
        rel = path.resolve().relative_to(_ROOT)
    except ValueError:
        return None
    if rel.suffix != ".py" or not rel.parts or rel.parts[0] not in PACKAGES:
        return None
    parts = list(rel.with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _file_of(module: str) -> Path | None:
    base = _ROOT.joinpath(*module.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@functools.lru_cache(maxsize=None)
def _direct_imports(path: Path) -> tuple[str, ...]:
    """keepout modules a source file imports (each with the packages above it, which the import runs)."""
    text = path.read_text(encoding="utf-8")
    here = _module_of(path) or ""
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    names: set[str] = set()
    for match in _IMPORT_RE.finditer(text):
        names.update(part.split()[0] for part in match[1].split(",") if part.strip())
    for match in _FROM_RE.finditer(text):
        source, targets = match[1], match[2].strip("() \t\n")
        if source.startswith("."):
            up = len(source) - len(source.lstrip("."))
            base = package.split(".")[: max(0, len(package.split(".")) - (up - 1))] if package else []
            source = ".".join(base + ([source.lstrip(".")] if source.lstrip(".") else []))
        names.add(source)
        # `from pkg import mod` imports a module when there is one of that name
        names.update(f"{source}.{t.split()[0]}" for t in targets.replace("\n", " ").split(",") if t.strip())
    found: set[str] = set()
    for name in names:
        parts = name.split(".")
        if parts[0] not in PACKAGES:
            continue
        for k in range(1, len(parts) + 1):
            module = ".".join(parts[:k])
            if module not in _NOT_SOURCES and _file_of(module) is not None:
                found.add(module)
    return tuple(sorted(found))


@functools.lru_cache(maxsize=None)
def closure_files(path: Path) -> tuple[Path, ...]:
    """``path`` and every keepout source file it imports, directly or through keepout modules."""
    seen: dict[Path, None] = {path: None}
    todo = [path]
    while todo:
        for module in _direct_imports(todo.pop()):
            file = _file_of(module)
            if file is not None and file not in seen:
                seen[file] = None
                todo.append(file)
    return tuple(sorted(seen))


@functools.lru_cache(maxsize=None)
def _file_digest(path: Path) -> bytes:
    return hashlib.sha256(path.read_bytes()).digest()


def source_digest(path: str | os.PathLike) -> str:
    """SHA-256 over the names and contents of ``path``'s keepout import closure (see the module doc).

    Computed once per process and file: a kernel's source is fixed for the life of the process that
    loaded it, and so is what was compiled into it."""
    path = Path(path).resolve()
    h = hashlib.sha256()
    for file in closure_files(path):
        name = file.relative_to(_ROOT).as_posix() if file.is_relative_to(_ROOT) else file.name
        h.update(name.encode() + b"\0" + _file_digest(file))
    return h.hexdigest()


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


class SourceClosureLocator(caching._CacheLocator):
    """numba cache locator for keepout kernels: stamped with `source_digest` of the kernel's file."""

    def __init__(self, py_func, py_file: str, cache_path: Path):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = str(cache_path)

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self):
        return ("keepout-source-closure", STAMP_VERSION, source_digest(self._py_file))

    def get_disambiguator(self) -> str:
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        path = Path(py_file)
        if _module_of(path) is None:
            return None  # not a keepout kernel (tests, notebooks): numba's own locators
        shipped = path.resolve().parent / "__pycache__"
        sub = cls.get_suitable_cache_subpath(py_file)
        if config.CACHE_DIR:
            folder = Path(config.CACHE_DIR) / sub
        elif _writable(shipped):
            folder = shipped
        else:
            folder = user_cache_dir() / "numba" / sub
            _seed(shipped, folder, f"{path.stem}.{py_func.__qualname__}-{py_func.__code__.co_firstlineno}.")
        return cls(py_func, py_file, folder) if _writable(folder) else None


def _seed(shipped: Path, folder: Path, prefix: str) -> None:
    """Copy a read-only install's shipped cache files of one kernel into the user cache, once. Sound:
    the stamp inside them is the source closure's digest, checked on load like any other entry."""
    if not shipped.is_dir() or not _writable(folder):
        return
    for src in shipped.glob(prefix.replace("<", "").replace(">", "") + "*.nb[ic]"):
        dst = folder / src.name
        if not dst.exists():
            try:
                shutil.copyfile(src, dst)
            except OSError:
                return


def install() -> None:
    """Put `SourceClosureLocator` first in numba's locator list (idempotent)."""
    if SourceClosureLocator not in _CACHE_IMPL._locator_classes:
        _CACHE_IMPL._locator_classes.insert(0, SourceClosureLocator)


def stale_files(folders: list[Path] | None = None) -> list[Path]:
    """Cache files in the packages' ``__pycache__`` folders that no current kernel can load: index files
    whose stamp is not the current digest of their module (or for another numba), and data files no
    current index names. `keepout warmup --prune` deletes them before a wheel is built."""
    import pickle

    import numba

    if folders is None:
        folders = [p for pkg in PACKAGES for p in (_ROOT / pkg).rglob("__pycache__") if p.is_dir()]
    stale: list[Path] = []
    for folder in folders:
        live: set[str] = set()
        for index in folder.glob("*.nbi"):
            source = index.parent.parent / (index.name.split(".", 1)[0] + ".py")
            try:
                with open(index, "rb") as f:
                    version = pickle.load(f)
                    stamp, overloads = pickle.loads(f.read())
            except Exception:  # noqa: BLE001 - unreadable index: numba ignores it too
                stale.append(index)
                continue
            current = ("keepout-source-closure", STAMP_VERSION, source_digest(source)) if source.is_file() else None
            if version != numba.__version__ or stamp != current:
                stale.append(index)
            else:
                live.update(overloads.values())
        stale.extend(p for p in folder.glob("*.nbc") if p.name not in live)
    return sorted(stale)


install()  # importing this module is enough (gnc._after_numba imports it when numba loads)
