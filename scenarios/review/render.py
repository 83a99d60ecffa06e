"""The page itself: a Jinja2 template filled with the page's sections, plotly.js
and the figure specifications inline, written atomically.

Nothing is fetched when the page opens: plotly.js (from the plotly package) and
every figure's data sit in the file, so it opens from ``file://`` with the network
off, and can be mailed or archived as one document.  The script at the end draws
every figure, links the x axes of the time figures (zoom one, all follow), and
when all are drawn records the time since navigation start in ``data-drawn-ms`` on
<body> (the browser test reads it: the page's own opening time).
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from .cells import Table, Verdict

TEMPLATES = Path(__file__).with_name("templates")


@dataclass(frozen=True)
class Section:
    id: str
    title: str
    intro: str = ""
    verdicts: list[Verdict] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    plots: list = field(default_factory=list)           # run_figures.Plot
    pre: str | None = None                             # preformatted text (YAML, markdown)
    links: list[tuple[str, str, str]] = field(default_factory=list)   # href, name, note
    after: list[Table] = field(default_factory=list)   # tables below the plots


@dataclass(frozen=True)
class Page:
    title: str
    kind: str
    subtitle: str
    sections: list[Section]


@lru_cache(maxsize=1)
def _environment():
    import jinja2
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES),
                             autoescape=jinja2.select_autoescape(["html", "j2"]),
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["spec"] = _spec_json
    return env


def _spec_json(figure: dict) -> str:
    """A figure as JSON safe inside <script>: no "</" can close the element early."""
    import markupsafe
    text = json.dumps(figure, separators=(",", ":"), allow_nan=False, default=_none)
    return markupsafe.Markup(text.replace("</", "<\\/"))


def _none(value):
    raise TypeError(f"not JSON: {type(value).__name__}")


@lru_cache(maxsize=1)
def plotly_js() -> str:
    from plotly.offline import get_plotlyjs
    return get_plotlyjs()


def html(page: Page) -> str:
    import markupsafe
    template = _environment().get_template("report.html.j2")
    return template.render(page=page, plotly_js=markupsafe.Markup(plotly_js()))


def write(page: Page, path: Path) -> Path:
    """report.html beside the directory's files, whole or not at all: written to a
    temporary name in the same directory and renamed (a failed write leaves the
    previous page, or none)."""
    text = html(page)
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
