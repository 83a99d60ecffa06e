"""dynprop from Python: the few names a notebook needs (as skyfield's ``api``).

    >>> import dynprop
    >>> s = dynprop.load_scenario("goes_next_equinox", duration_s=21600)
    >>> r = dynprop.run(s)
    >>> r.summary["yaw_error_rms_deg"]
    >>> r.figure("errors")

The command line (`dynprop run` …) and these functions run the same code and write
the same files; docs/outputs.md describes every column and key.  Units are SI
inside, degrees and rpm only where the column name says so (``roll_deg``).
"""

from dynprop.scenarios import __version__

from .api import (
    ScenarioError,
    covariance,
    linearization,
    load_scenario,
    montecarlo,
    observability,
    open_run,
    run,
    simulate,
)
from .results import (
    LinearizationResult,
    MonteCarloResult,
    RunResult,
    SimulationResult,
    TextReport,
)

__all__ = [
    "LinearizationResult", "MonteCarloResult", "RunResult", "ScenarioError",
    "SimulationResult", "TextReport", "__version__", "covariance", "linearization",
    "load_scenario", "montecarlo", "observability", "open_run", "run", "simulate",
]
