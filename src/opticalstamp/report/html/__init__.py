"""The HTML page of `opticalstamp report`: tables and sections from the report's numbers,
a module per section (:mod:`.optics`, :mod:`.quality`, :mod:`.light`, :mod:`.scans`,
:mod:`.restoration`, :mod:`.studies`) put together by :func:`~.page.page`; a section
that was not measurable shows "not measurable: reason" (:func:`~.common.unmeasured`)."""

from __future__ import annotations

from .common import table
from .light import signal_html
from .page import page
from .scans import scans_html
from .studies import rodlens_html

__all__ = ["page", "rodlens_html", "scans_html", "signal_html", "table"]
#: kept under its former name for callers that import it from here
_scans_html = scans_html
