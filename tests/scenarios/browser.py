"""A page opened as its reader would: headless Chromium through selenium, with the
network off, for the tests of `dynprop report`'s pages (test_report_browser.py).

``Browser().open(html, screenshot)`` loads ``file://html``, waits until the page's
own script has drawn every figure (it sets ``data-drawn-ms`` on <body>, the time
since navigation start), and returns what a reader would meet: the console's
messages, that time, each figure's drawn DOM, every request the page made and a
full-page screenshot.

The network is off three ways: DevTools' offline emulation, every host name
resolving to nothing and a proxy on a closed port; a page that asks for anything
beyond file:, data: or blob: shows it in ``requests`` (what it tried, from the
DevTools network log) and ``resources`` (what it loaded, from Resource Timing).

Chromium and chromedriver come from Debian's ``chromium`` and ``chromium-driver``
(.ci/run installs them), selenium from the dev extra; without one of them the tests
skip, naming the package, unless DYNPROP_BROWSER_REQUIRED is set (CI), where they fail.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

CHROMIUM = ("/usr/bin/chromium", "chromium", "chromium-browser")
CHROMEDRIVER = ("/usr/bin/chromedriver", "chromedriver")
LOCAL_SCHEMES = ("file:", "data:", "blob:")
WIDTH, HEIGHT = 1400, 1000
MAX_SHOT_PX = 16000

# Each figure's drawn DOM.  A trace's group carries its calcdata (d3's __data__),
# whose first point holds the full trace: its index, mode and points tell what
# should have been drawn.
_PLOTS_JS = r"""
var layers = [".scatterlayer", ".barlayer", ".boxlayer", ".violinlayer",
              ".heatmaplayer", ".contourlayer", ".ohlclayer", ".polarlayer", ".pielayer"];
return Array.from(document.querySelectorAll("div.plot")).map(function (div) {
  var svg = div.querySelector("svg.main-svg");
  var box = svg ? svg.getBoundingClientRect() : null;
  var perLayer = {};
  layers.forEach(function (l) {
    var n = div.querySelectorAll(l + " g.trace, " + l + " g.hm, " + l + " g.contour").length;
    if (n) { perLayer[l.slice(1)] = n; }
  });
  var lines = [];
  div.querySelectorAll(".scatterlayer g.trace").forEach(function (g) {
    var cd = g.__data__ || [], tr = (cd[0] || {}).trace || {};
    var finite = cd.filter(function (p) { return isFinite(p.x) && isFinite(p.y); }).length;
    var path = g.querySelector("path.js-line");
    var d = path ? (path.getAttribute("d") || "") : "";
    lines.push({index: tr.index, name: tr.name || "", mode: tr.mode || "",
                finite: finite, d: d.length,
                points: g.querySelectorAll("path.point").length});
  });
  return {id: div.id, traces: parseInt(div.dataset.traces, 10), drawn: div.dataset.drawn || "",
          svg: !!svg, width: box ? box.width : 0, height: box ? box.height : 0,
          full_data: div._fullData ? div._fullData.length : -1,
          layers: perLayer, scatter: lines,
          buttons: Array.from(div.querySelectorAll(".modebar-btn"))
                     .map(function (b) { return b.getAttribute("data-title"); })};
});
"""


@dataclass
class Plot:
    id: str
    traces: int                   # data-traces: the traces in the figure's spec
    drawn: str                    # data-drawn ("1" once Plotly.newPlot resolved)
    svg: bool                     # the main svg exists
    width: float
    height: float
    full_data: int                # traces Plotly itself holds (div._fullData)
    layers: dict                  # trace groups drawn, per layer (scatterlayer: 12, ...)
    scatter: list                 # per scatter trace: index, name, mode, finite, d, points
    buttons: list                 # the mode bar's buttons, by title ("Zoom", "Share chart...")

    @property
    def drawn_traces(self) -> int:
        return sum(self.layers.values())

    def faults(self) -> list[str]:
        """What is missing from this figure, as sentences; none when it is whole."""
        out = []
        if self.drawn != "1":
            out.append("not drawn (no data-drawn)")
        if not (self.svg and self.width > 0 and self.height > 0):
            out.append(f"no main svg of nonzero size ({self.width}x{self.height})")
        if self.drawn_traces != self.traces:
            out.append(f"{self.drawn_traces} traces drawn {self.layers}, "
                       f"its spec has {self.traces}")
        for t in self.scatter:
            if "lines" in t["mode"] and t["finite"] >= 2 and t["d"] == 0:
                out.append(f"trace {t['index']} {t['name']!r}: {t['finite']} points, "
                           "an empty line path")
            if t["mode"] == "lines" and t["finite"] == 0:
                out.append(f"trace {t['index']} {t['name']!r}: a line without one finite point")
            if t["mode"] == "markers" and t["finite"] > 0 and t["points"] == 0:
                out.append(f"trace {t['index']} {t['name']!r}: {t['finite']} points, "
                           "no marker drawn")
        return out


@dataclass
class Opened:
    path: Path                    # the page's file
    url: str
    drawn_ms: float | None        # body[data-drawn-ms]; None: not drawn within the timeout
    load_s: float                 # wall time from get() to drawn (or to giving up)
    shot_s: float = 0.0           # wall time of the screenshot
    console: list = field(default_factory=list)     # driver.get_log("browser") entries
    plots: list = field(default_factory=list)       # Plot
    resources: list = field(default_factory=list)   # Resource Timing names
    requests: list = field(default_factory=list)    # URLs the page asked for (DevTools)
    screenshot: Path | None = None
    size: tuple[int, int] = (0, 0)                  # the page's scroll width and height
    specs: int = 0                                  # script.plot-spec elements in the page

    def remote(self) -> list[str]:
        """Everything the page asked for or loaded beyond file:, data: and blob:."""
        return sorted({u for u in self.resources + self.requests
                       if not u.startswith(LOCAL_SCHEMES)})


def _find(candidates, package: str, kind: str) -> str:
    for c in candidates:
        path = c if os.path.isabs(c) else shutil.which(c)
        if path and os.access(path, os.X_OK):
            return path
    _missing(f"{kind} not found ({', '.join(candidates)}): install Debian's {package!r} "
             f"(apt-get install {package})")


def _missing(message: str):
    if os.environ.get("DYNPROP_BROWSER_REQUIRED"):
        pytest.fail(message + " -- DYNPROP_BROWSER_REQUIRED is set", pytrace=False)
    pytest.skip(message)


class Browser:
    """One headless Chromium for a module's pages; ``open`` each, ``quit`` at the end."""

    def __init__(self):
        try:
            from selenium import webdriver
            from selenium.webdriver.chrome.service import Service
        except ImportError:
            _missing("selenium is not installed: pip install selenium (in the dev extra)")
        binary = _find(CHROMIUM, "chromium", "Chromium")
        driver = _find(CHROMEDRIVER, "chromium-driver", "chromedriver")
        options = webdriver.ChromeOptions()
        options.binary_location = binary
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu",
                    "--disable-dev-shm-usage", f"--window-size={WIDTH},{HEIGHT}",
                    "--host-resolver-rules=MAP * ~NOTFOUND", "--proxy-server=127.0.0.1:9",
                    "--no-first-run", "--no-default-browser-check",
                    "--disable-background-networking", "--disable-component-update",
                    "--disable-sync", "--disable-extensions", "--hide-scrollbars"):
            options.add_argument(arg)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
        self.driver = webdriver.Chrome(service=Service(driver), options=options)
        self.driver.execute_cdp_cmd("Network.enable", {})
        self.driver.execute_cdp_cmd("Network.emulateNetworkConditions", {
            "offline": True, "latency": 0, "downloadThroughput": 0, "uploadThroughput": 0})

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.quit()

    def quit(self):
        self.driver.quit()

    def open(self, html: Path, screenshot: Path | None = None,
             timeout_s: float = 60.0) -> Opened:
        d = self.driver
        d.set_window_size(WIDTH, HEIGHT)
        d.get("about:blank")
        d.get_log("browser")                     # drop what earlier pages left
        d.get_log("performance")
        url = Path(html).resolve().as_uri()
        console, drawn = [], None
        start = time.perf_counter()
        d.get(url)
        while time.perf_counter() - start < timeout_s:
            drawn = d.execute_script("return document.body && document.body.dataset.drawnMs")
            console += d.get_log("browser")
            # The page's script reports a failed figure on the console and never
            # sets data-drawn-ms: no need to wait for the timeout.
            if drawn or any(e.get("level") == "SEVERE" for e in console):
                break
            time.sleep(0.05)
        load_s = time.perf_counter() - start
        out = Opened(path=Path(html), url=url, load_s=load_s,
                     drawn_ms=float(drawn) if drawn else None)
        out.plots = [Plot(**p) for p in d.execute_script(_PLOTS_JS)]
        out.resources = d.execute_script(
            "return performance.getEntriesByType('resource').map(function (e) "
            "{ return e.name; })")
        out.requests = [m["params"]["request"]["url"]
                        for m in (json.loads(e["message"])["message"]
                                  for e in d.get_log("performance"))
                        if m.get("method") == "Network.requestWillBeSent"]
        out.specs = d.execute_script(
            "return document.querySelectorAll('script.plot-spec').length")
        out.size = tuple(d.execute_script(
            "return [document.documentElement.scrollWidth, "
            "document.documentElement.scrollHeight]"))
        if screenshot is not None:
            start = time.perf_counter()
            out.screenshot = self._shot(Path(screenshot), *out.size)
            out.shot_s = time.perf_counter() - start
        out.console = console + d.get_log("browser")
        return out

    def _shot(self, path: Path, width: int, height: int) -> Path:
        """The whole page (at most MAX_SHOT_PX tall) as PNG, the window kept at its
        width so that no figure is redrawn for it."""
        self.driver.execute_script("window.scrollTo(0, 0)")
        shot = self.driver.execute_cdp_cmd("Page.captureScreenshot", {
            "format": "png", "captureBeyondViewport": True,
            "clip": {"x": 0, "y": 0, "width": max(width, WIDTH),
                     "height": min(height, MAX_SHOT_PX), "scale": 1}})
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(shot["data"]))
        return path
