"""Where the truth's coordinates meet the filter's, and telemetry becomes the
filters' inputs: no I/O and no physics formula of its own (those are ``sim``'s,
``eom``'s and ``estimator``'s), only the wiring between them.

- ``coordinates``: the nonlinear truth in the paper's model states (Eq. 10), its
  external torques split into the torque states' fit and the residual (Eqs. 9, 18);
- ``inputs``: telemetry columns to the paper filter's measurements, inputs and
  prior, a window padded with its neighbours' samples (one routine for every
  filter);
- ``ekf``: the same for the extended Kalman filter;
- ``covariance``: the scenario's inputs to Section 6's covariance analysis, the
  yaw weighed as a run's filter weighs it;
- ``twin``: the linear twin, the paper's model flown under the truth's torques and
  sensed with the truth's noise draws.

May import: ``sim``, ``estimator``, ``eom`` and the application's base modules
(``units``, ``samples``, ``records``, ``workers``) and ``config``.  Imported by
``figures``, ``run`` and the analysis rooms.
"""
