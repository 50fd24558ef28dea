"""keepout.gnc: the pure mathematics of constrained attitude guidance on S^n.

No I/O, no clocks, no threads, no globals: numpy in, numpy out. The one exception is packaging, not
maths: ``_numba_cache`` and ``_after_numba`` (design note 17) arm numba's kernel cache locator here,
because every package with kernels imports gnc first. The specification is the paper: S. Sawant and
A. Tayebi, "Constrained stabilization on the n-sphere" (conic and star-shaped constraints), arXiv 2509.02487.
"""

# Before any kernel of gnc, fsw or hil_sim is decorated: numba caches them through keepout's locator,
# stamped with the kernel's whole source closure (gnc/_numba_cache.py), installed when numba loads.
from gnc import _after_numba

_after_numba.arm()
