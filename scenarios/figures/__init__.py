"""Figures: the only room that imports ``plots`` (matplotlib drawings of plain
arrays).  Each module reads what a command wrote or computed and hands ``plots``
its arrays: ``run`` (a `run` or `estimate` directory, and `dynprop plot`),
``montecarlo``, ``linearization``, ``trim`` and ``tune``.  ``save_figure`` writes every PNG.

May import the base modules, ``config``, ``files`` and ``bridge``; imported by
``run`` and the analysis rooms.
"""

from __future__ import annotations

import os
from pathlib import Path


def save_figure(fig, path: Path) -> Path:
    # Write beside the target and rename, so a figure is never half written.
    tmp = path.with_name(f".{path.name}.tmp")
    # zlib level 1: a quarter of the encoding time for files ~10% larger.
    fig.savefig(tmp, dpi=120, format="png", pil_kwargs={"compress_level": 1})
    os.replace(tmp, path)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return path
