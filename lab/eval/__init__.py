"""Evaluation sweeps (``lab eval``): grids of independent seeded jobs run on a local process pool or a
Dask cluster (:mod:`lab.eval.executor`), one JSON per job and a results table (:mod:`lab.eval.sweep`).

A runs-layer package: it imports :mod:`lab.runs`, never the other way round."""
