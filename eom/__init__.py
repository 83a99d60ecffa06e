"""Equations of motion shared by ``sim`` (the truth integrates them) and
``estimator`` (the extended Kalman filter propagates them), which may not import
each other: the gyrostat's Euler equation, quaternion and 3-1-2 Euler kinematics,
and the torque laws, as CasADi expressions.  No parameters, no state: formulas."""
