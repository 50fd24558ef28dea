"""Install keepout's numba cache locator (gnc/_numba_cache.py) as soon as numba's caching module loads.

``import gnc`` arms this (fsw and hil_sim import gnc first): every kernel is decorated after numba is
imported, so none escapes the locator, and a process that never imports numba (the ground monitor,
``keepout --version``) does not pay numba's import (~0.5 s of CPU) for it.
"""
from __future__ import annotations

import importlib.abc
import importlib.util
import sys

_TARGET = "numba.core.caching"


def _install() -> None:
    # the module installs the locator at the end of its own import (when it is being imported right now,
    # this returns the half-run module, which installs it when it gets there)
    import gnc._numba_cache  # noqa: F401


class _AfterNumbaCaching(importlib.abc.MetaPathFinder):
    """One-shot finder: lets the normal finders load numba.core.caching, then installs the locator."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname != _TARGET:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run = spec.loader.exec_module

        def exec_module(module) -> None:
            run(module)
            _install()

        spec.loader.exec_module = exec_module  # this file's own loader instance
        return spec


def arm() -> None:
    """Install now if numba's caching module is loaded, else right after it loads (idempotent)."""
    if _TARGET in sys.modules:
        _install()
    elif not any(isinstance(f, _AfterNumbaCaching) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaCaching())
