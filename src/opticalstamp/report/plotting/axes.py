"""What every figure starts from: a new figure without pyplot, and the report's width."""

from __future__ import annotations

#: Width (inches) of a figure the report shows at its natural size: the page's 1,100 px
#: column less its padding, at the 110 dpi figures are saved at (io.files.figure_png).
REPORT_WIDTH_IN = 9.6


def subplots(*args, figsize=None, layout=None, **kw):
    """A new Figure and its axes, like ``pyplot.subplots`` but without pyplot: no backend
    switch, no global figure registry (a figure is freed when it is no longer used)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(*args, **kw)
