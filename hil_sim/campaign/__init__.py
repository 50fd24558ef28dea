"""Dispersed Monte Carlo campaigns of missions: spec, sampling, execution, results, reports, baselines.

Layout (each module small and single-purpose):

- ``spec``: the campaign YAML model (pydantic, ``extra="forbid"``) and its loader.
- ``seeds``: one ``numpy.random.SeedSequence`` per run index (independent of workers and order).
- ``dispersions``: draw values, apply them to the mission by key path, interpolate toward nominal.
- ``execute``: one run end to end (draw, apply, validate, run, read back, judge): ``RunRecord``.
- ``runner``: many runs on a local process pool or a Dask cluster; resumable run folders.
- ``fast``: the ``fast`` mode (flight software and world in one process over the ``virtual`` bus).
- ``results``, ``report``, ``baseline``, ``shrink``: what comes out of a campaign.

Keep this file import-light: the CLI imports the package on every ``keepout`` start.
"""
