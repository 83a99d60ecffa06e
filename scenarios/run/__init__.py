"""The run engine: a scenario flown and filtered.

- ``simulate``: truth and telemetry as whole arrays; ``whole``: the paper's filter,
  smoother and linear twin on them (``estimate``, Monte Carlo cases, the analyses);
- the streamed `dynprop run`, in ``stream/`` (its ``__init__`` and ``windows``'
  module doc): ``stream.plan`` cuts the run into windows, ``stream.producer`` flies
  the truth, senses it and runs the twin and its filter in a process of its own,
  ``stream.stages`` filter and smooth each window (the EKF beside them: ``ekf``),
  ``tally``, ``daily`` and ``filter_tally`` accumulate the figures and
  ``stream.directory`` writes the run directory;
- ``estimate``: `dynprop estimate` on a telemetry file; ``statistics``: the
  summary's figures of a run held whole.

May import: ``sim``, ``estimator``, the base modules, ``config``, ``files``,
``bridge`` and ``figures``.  It knows no analysis: a run steered by one (the trim
loop) gets a steering object from the command layer (``commands``).
"""
