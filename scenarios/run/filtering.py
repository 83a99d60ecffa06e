"""Which filter is "the paper's" in a run: the paper's own (``estimator.kalman``), or,
when the scenario switches on sensor-bias states (``estimator.bias_states``) or an
innovation gate (``estimator.outlier_gate_chi2``), the same filter with those
(``estimator.augmented``).

Every room downstream reads the paper's nine states, σ and innovations, so an
augmented run's result is handed on as a ``FilterResult`` of those nine
(``BiasedResult``), the bias states, the gate's rejections and the whole augmented
history riding along for the smoother, estimate.csv and the summary.  With neither
switched on nothing here runs but ``kalman_filter`` and ``rts_smoother``, exactly as
before (bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from dynprop.estimator.augmented.filter import (
    AugmentedResult,
    BiasModel,
    augmented_filter,
    augmented_smoother,
)
from dynprop.estimator.kalman.filter import (
    FilterResult,
    SmootherResult,
    kalman_filter,
    rts_smoother,
)
from dynprop.estimator.linear.model import N_STATES

from ..config import build
from ..config.schema import Scenario
from ..units import RAD2DEG


@dataclass(frozen=True)
class FilterDesign:
    """The scenario's bias states (None: none) and gate (None: no gating)."""

    bias: BiasModel | None = None
    gate_chi2: float | None = None

    @property
    def paper(self) -> bool:
        """The paper's filter itself: neither bias states nor gating."""
        return self.bias is None and self.gate_chi2 is None

    @property
    def names(self) -> tuple[str, ...]:
        return () if self.bias is None else tuple(self.bias.names)


def design_of(s: Scenario) -> FilterDesign:
    return FilterDesign(build.bias_model(s), s.estimator.outlier_gate_chi2)


def _block9(P_packed: np.ndarray, n: int) -> np.ndarray:
    """The paper's 9×9 block of a packed n-state covariance, packed as ``kalman``'s."""
    i, j = np.triu_indices(n)
    index = {(a, b): k for k, (a, b) in enumerate(zip(i, j, strict=True))}
    i9, j9 = np.triu_indices(N_STATES)
    return P_packed[:, [index[a, b] for a, b in zip(i9, j9, strict=True)]]


@dataclass(frozen=True)
class BiasedResult(FilterResult):
    """The paper's nine states of an augmented run (``FilterResult``'s fields: x,
    P_packed, ν, S, the nine of it), with the run's full prior after the last step
    (``x_next``, ``P_next``: augmented, for the next window) and ``augmented``, the
    whole history."""

    augmented: AugmentedResult | None = None

    @property
    def bias_names(self) -> tuple[str, ...]:
        return self.augmented.names

    @property
    def bias_x(self) -> np.ndarray:
        return self.augmented.x[:, N_STATES:]

    @property
    def bias_sigma(self) -> np.ndarray:
        return self.augmented.sigma[:, N_STATES:]

    @property
    def rejected(self) -> np.ndarray:
        return self.augmented.rejected


def _view(a: AugmentedResult) -> BiasedResult:
    n = a.x.shape[1]
    return BiasedResult(a.x[:, :N_STATES], _block9(a.P_packed, n), a.innovations,
                        a.innovation_var, a.x_next, a.P_next, a.backend, augmented=a)


def paper_filter(design: FilterDesign, meas, disc, x0, P0, u=None, extra=None, sun_head=None,
                 rows=None, covariance_rows=None) -> FilterResult:
    """The run's filter (``kalman_filter`` when ``design.paper``)."""
    if design.paper:
        return kalman_filter(meas, disc, x0, P0, u=u, rows=rows, extra=extra,
                             covariance_rows=covariance_rows)
    a = augmented_filter(meas, disc, x0, P0, u, bias=design.bias, sun_head=sun_head,
                         gate_chi2=design.gate_chi2, extra=extra, rows=rows)
    view = _view(a)
    if covariance_rows is not None:
        # The augmented history stays whole (the smoother and the biases need it); the
        # paper's block is cut to those rows, as ``kalman_filter`` cuts it.
        view = replace(view, P_packed=view.P_packed[np.asarray(covariance_rows)])
    return view


def paper_smoother(design: FilterDesign, result: FilterResult, disc, u=None, extra=None,
                   covariance: bool = True, x_after=None, P_after=None) -> SmootherResult:
    """The RTS smoother of ``paper_filter``'s result; its x is the paper's nine states
    (``x_after``, ``P_after``, ``full_x`` and ``full_P`` the augmented ones, for a
    window's smoothing)."""
    if design.paper or not isinstance(result, BiasedResult):
        return rts_smoother(result, disc, u=u, extra=extra, covariance=covariance,
                            x_after=x_after, P_after=P_after)
    s = augmented_smoother(result.augmented, disc, u, bias=design.bias, extra=extra,
                           covariance=covariance, x_after=x_after, P_after=P_after)
    n = s.x.shape[1]
    P = None if s.P_packed is None else _block9(s.P_packed, n)
    return SmoothedView(s.x[:, :N_STATES], P, s.x, s.P_packed)


@dataclass(frozen=True)
class SmoothedView(SmootherResult):
    """``SmootherResult`` of the paper's nine states, ``full_x`` the augmented state."""

    full_x: np.ndarray | None = None
    full_P: np.ndarray | None = None


def head(result: FilterResult, n: int) -> FilterResult:
    """The first ``n`` samples of a filter history (the prior after them is not kept)."""
    return stretch(result, slice(0, n))


def stretch(result: FilterResult, rows: slice) -> FilterResult:
    """Samples ``rows`` of a filter history (the prior after the whole is kept, but
    means nothing for a stretch that ends before it)."""
    if isinstance(result, BiasedResult):
        a = result.augmented
        cut = AugmentedResult(a.x[rows], a.P_packed[rows], a.innovations[rows],
                              a.innovation_var[rows], a.rejected[rows], a.x_next, a.P_next,
                              a.backend, a.names)
        return _view(cut)
    return FilterResult(result.x[rows], result.P_packed[rows], result.innovations[rows],
                        result.innovation_var[rows], result.x_next, result.P_next,
                        result.backend)


def smoothed_full_x(smoothed) -> np.ndarray:
    """The smoothed state a window's smoothing continues from (augmented if it is)."""
    full = getattr(smoothed, "full_x", None)
    return smoothed.x if full is None else full


def smoothed_full_P(smoothed) -> np.ndarray | None:
    """The smoothed covariance (packed) a window's smoothing continues from."""
    full = getattr(smoothed, "full_P", None)
    return smoothed.P_packed if full is None else full


def bias_columns(result: FilterResult, k) -> dict[str, np.ndarray]:
    """estimate.csv's bias columns at rows ``k``: each bias state and its σ, in degrees
    (none for the paper's filter)."""
    if not isinstance(result, BiasedResult):
        return {}
    out = {}
    for j, name in enumerate(result.bias_names):
        out[f"bias_{name}_deg"] = result.bias_x[k, j] * RAD2DEG
    for j, name in enumerate(result.bias_names):
        out[f"sigma_bias_{name}_deg"] = result.bias_sigma[k, j] * RAD2DEG
    return out


REJECTED_NAMES = ("roll", "yaw", "h")
HEAD_NAMES = ("dss", "cass1", "cass2")   # telemetry sun_head 0, 1, 2


def count_rejected(rejected: np.ndarray | None, sun_head) -> np.ndarray | None:
    """The gate's rejections (N, 3) counted per sensor: roll (the Earth sensor), yaw,
    h (the tachometers), then yaw by the Sun head that gave it (DSS, CASS1, CASS2);
    None without a gate."""
    if rejected is None:
        return None
    counts = rejected.sum(axis=0).astype(np.int64)
    head = np.full(len(rejected), np.nan) if sun_head is None else np.asarray(sun_head, float)
    by_head = [int(np.sum(rejected[:, 1] & (head == k))) for k in range(len(HEAD_NAMES))]
    return np.r_[counts, by_head].astype(np.int64)


def rejected_counts(result: FilterResult, sun_head) -> np.ndarray | None:
    """``count_rejected`` of a filter result (None for the paper's filter)."""
    if not isinstance(result, BiasedResult):
        return None
    return count_rejected(result.rejected, sun_head)


def final_biases(result: FilterResult) -> dict[str, float] | None:
    """The bias columns' last values (``bias_columns``), None for the paper's filter."""
    cols = bias_columns(result, slice(-1, None))
    return {name: float(v[0]) for name, v in cols.items()} or None


def filter_section(s: Scenario, design: FilterDesign, final: dict | None,
                   rejected: np.ndarray | None, truth_biases: dict | None) -> dict:
    """summary.json's ``bias_states`` and ``outliers`` (None when not in the design):
    each bias's final estimate and σ (``final``: the last row of estimate.csv's bias
    columns), with the truth's value and the error in σ when the run knows it; the
    gate, and the samples it rejected per sensor (``count_rejected``)."""
    biases = None
    if design.bias is not None and final:
        biases = {}
        for name in design.names:
            est, sig = final[f"bias_{name}_deg"], final[f"sigma_bias_{name}_deg"]
            true = None if truth_biases is None else truth_biases.get(name)
            true_deg = None if true is None else float(true) * RAD2DEG
            biases[name] = {
                "model": getattr(s.estimator.bias_states, name).model,
                "estimate_deg": est, "sigma_deg": sig, "truth_deg": true_deg,
                "error_over_sigma": None if true_deg is None else (est - true_deg) / sig}
    outliers = None
    if design.gate_chi2 is not None:
        counts = np.zeros(6, np.int64) if rejected is None else rejected
        outliers = {"gate_chi2": design.gate_chi2,
                    "rejected": {n: int(c) for n, c in zip(REJECTED_NAMES, counts[:3],
                                                            strict=True)},
                    "rejected_yaw_by_head": {n: int(c) for n, c in zip(HEAD_NAMES, counts[3:],
                                                                        strict=True)}}
    return {"bias_states": biases, "outliers": outliers}
