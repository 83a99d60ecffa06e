"""Scenarios in and out: the schema of every key (``schema``, with its sections in
``sections``, ``estimation`` and ``montecarlo``), the YAML loader with its
one-line-per-problem errors (``loader``, ``suggestions``), the scenario turned into
``sim`` and ``estimator`` parameter objects, seeds and the truth stream (``build``),
and docs/scenario-reference.md generated from the schema (``reference``).

May import: ``sim`` and ``estimator`` (their parameter types and defaults) and the
base modules (``units``).  Imported by every room above it.
"""
