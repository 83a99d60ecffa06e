"""`dynprop report DIR`: one self-contained HTML page of a directory dynprop wrote, for
a reviewer (docs/report.md).  It reads the directory's files only, never reruns
anything, and draws with Plotly (its JavaScript inline, so the page opens offline).

``source``: what kind of directory it is and its files, checked before anything is
written; ``traces``: Plotly figure specifications from arrays (long series reduced
to their extremes per bin); ``cells``: the numbers shown, each tied to the file and
key it comes from; ``verdict``: the gap-end yaw against the filter, the paper and
the requirement; ``run_page``: the page of a `run` or `estimate` directory;
``run_figures``: its figures; ``pages/``: the pages of the other commands'
directories; ``render``: the Jinja2 template and the atomic write.

May import: ``config``, ``files``, the base modules, the estimator's published
constants (the paper's σ_yaw, the state indices) and the verdict rules the analyses
wrote their records by (``montecarlo.stats.nees_inside_needed``).  Nothing that
simulates or estimates: a page shows what the files hold.
"""
