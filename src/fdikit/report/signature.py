"""A signature matrix or D-matrix as a report section (a heat map), for monitor runs and campaigns."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .html import Report, heatmap_figure

__all__ = ["add_signature"]


def add_signature(rep: Report, signature: Mapping[str, Any]) -> None:
    """A signature matrix or D-matrix as a heat map (``matrix``, ``rows``, ``columns``, ``title``)."""
    m = np.asarray(signature["matrix"], float)
    title = signature.get("title", "signature matrix")
    rep.section(title.capitalize() if title[:1].islower() else title, signature.get("intro"))
    rep.figure(
        heatmap_figure(
            m,
            signature["columns"],
            signature["rows"],
            title=title,
            colorbar=signature.get("colorbar", "value (–)"),
            text=signature.get("text"),
            x_title=signature.get("x_title", "test / residual"),
            y_title=signature.get("y_title", "fault"),
            zmin=signature.get("zmin"),
            zmax=signature.get("zmax"),
        )
    )
