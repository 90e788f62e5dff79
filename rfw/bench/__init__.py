"""Benchmark harness: runs in separate processes, interleaved repeats, per-pass statistics
with bootstrap CIs, image differences, peer renderers, Markdown and HTML reports.

``rfw bench`` on the command line (:mod:`rfw.bench.cli`); the parts:
:mod:`~rfw.bench.worker` (one run), :mod:`~rfw.bench.runner` (the matrix),
:mod:`~rfw.bench.stats`, :mod:`~rfw.bench.images`, :mod:`~rfw.bench.report`,
:mod:`~rfw.bench.compare`, :mod:`~rfw.bench.ray_executor` (``--executor ray``).
"""

from .stats import bootstrap_ci, bootstrap_ci_runs, summarize

__all__ = ["bootstrap_ci", "bootstrap_ci_runs", "summarize"]
