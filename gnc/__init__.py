"""keepout.gnc: the pure mathematics of constrained attitude guidance on S^n.

No I/O, no clocks, no threads, no globals: numpy in, numpy out. The paper in
``shared/paper`` (constrained stabilization on the n-sphere) is the specification.
"""
