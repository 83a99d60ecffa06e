"""The application: scenarios, the run engine, the files, the analyses and the
``dynprop`` command line; the only package that wires ``sim``, ``estimator`` and
``plots`` together.

It is split into rooms with one job each (docs/architecture.md has the map, the
flow of `dynprop run` and the import rules, which tests/test_layering.py enforces):
the base modules ``units``, ``samples``, ``records`` and ``workers``; ``config``;
``files`` and ``bridge``; ``figures``; ``run``; the analyses ``trim``,
``linearization`` and ``montecarlo``; ``studies``; and on top ``commands``,
``arguments`` and ``cli``, where every command starts.  A room imports only its own
modules and the rooms below it.
"""

__version__ = "0.1.0"   # the package's one version (pyproject.toml reads it here)
