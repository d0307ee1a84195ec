"""fbia.figures: what every figure of fbia shares, matplotlib with the Agg back end and
legends only where something has a label.  The study's figures (``fbia.studies.plots``), the
iterators' and the OCT segmentation's use them; it imports nothing of fbia, so every layer
that draws can (it left ``fbia.imaging``, issue 48: the iterators drew through the imaging
package without reading an image)."""

from __future__ import annotations

from typing import Any

__all__ = ["legend", "pyplot"]


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg back end (files, no screen), imported on first use."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def legend(ax: Any, **kwargs: Any) -> None:
    """``legend(ax, **kwargs)`` when something on ``ax`` has a label: matplotlib warns "No
    artists with labels found to put in legend" for an empty plot (e.g. when every run
    failed), and a study prints nothing it has no use for."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kwargs)
