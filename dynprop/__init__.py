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

# The names load on first use (PEP 562), not on `import dynprop`: every
# `dynprop.<package>` import, the command line's included, runs this file first,
# and the facade's tables (pandas) and statistics would cost the CLI half a
# second of start-up it never uses.
_API = ("ExportError", "ScenarioError", "batch", "covariance", "estimate", "export",
        "linearization", "load_scenario", "montecarlo", "observability", "open_run", "report",
        "run", "simulate", "trim", "tune")
_RESULTS = ("BatchResult", "ExportResult", "LinearizationResult", "MonteCarloResult",
            "RunResult", "SimulationResult", "TextReport", "TrimResult", "TuneResult")

__all__ = [  # noqa: F822 - defined by __getattr__ below
    "BatchResult", "ExportError", "ExportResult", "LinearizationResult", "MonteCarloResult",
    "RunResult", "ScenarioError", "SimulationResult", "TextReport", "TrimResult", "TuneResult",
    "__version__", "batch", "covariance", "estimate", "export", "linearization",
    "load_scenario", "montecarlo", "observability", "open_run", "report", "run", "simulate",
    "trim", "tune",
]


def __getattr__(name: str):
    if name in _API:
        from . import api
        return getattr(api, name)
    if name in _RESULTS:
        from . import results
        return getattr(results, name)
    raise AttributeError(f"module 'dynprop' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_API, *_RESULTS])
