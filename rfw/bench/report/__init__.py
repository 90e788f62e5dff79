"""``report.md`` and ``report.html`` from a ``results.jsonl``: tables, charts, images, peers.

The two files say the same: a small document model is rendered to Markdown and to HTML.
Images (outputs, differences, charts) are PNG files beside the reports; ``report.md`` links
them relatively, ``report.html`` embeds them as data URIs, so that one file can be sent or
attached on its own. ``results.csv`` (beside ``results.jsonl``) holds the summary numbers.

The parts: :mod:`~.write` (the sections in order, the files written), :mod:`~.document`
(the document model and the numbers as cell text), :mod:`~.devices` (rows per device),
:mod:`~.tables`, :mod:`~.charts`, :mod:`~.images` (each variant's image against the
reference's), :mod:`~.power` (the runs and frames a 2% change needs), :mod:`~.peers` and
:mod:`~.method` ("How this was measured").
"""

from ..stats import change_text
from .devices import device_of
from .document import Doc, Img, ci, db, ms
from .images import diff_cell, image_camera, write_diffs
from .tables import _clocks
from .write import main_report, write_report

__all__ = ["Doc", "Img", "_clocks", "change_text", "ci", "db", "device_of", "diff_cell",
           "image_camera", "main_report", "ms", "write_diffs", "write_report"]
