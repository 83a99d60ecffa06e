"""One check shared by the figure tests: a figure's one legend covers no panel and
no caption."""

from __future__ import annotations


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def legend_clear_of_axes_and_caption(fig) -> None:
    """One figure legend; no legend inside a panel; the legend's box meets neither any
    panel nor the caption text at the foot of the figure."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    assert all(ax.get_legend() is None for ax in fig.axes)
    (legend,) = fig.legends
    box = legend.get_window_extent(r)
    for ax in fig.axes:
        assert not _overlap(box, ax.get_window_extent(r)), ax.get_ylabel()
    for t in fig.texts:
        assert not _overlap(box, t.get_window_extent(r)), t.get_text()
