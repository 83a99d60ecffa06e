"""Scenarios, the runner and the ``dynprop`` command line: the only package that
wires ``sim``, ``estimator`` and ``plots`` together."""

__version__ = "0.1.0"
