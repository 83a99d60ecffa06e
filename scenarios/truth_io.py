"""Write truth histories as CSV (column names of DESIGN.md section 6)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RAD2DEG = 180.0 / np.pi
RADPS2RPM = 60.0 / (2.0 * np.pi)


def truth_columns(result) -> dict[str, np.ndarray]:
    """Named output columns, degrees and rpm only here at the I/O boundary.

    ``w{x,y,z}_radps`` is ω_BN, the inertial angular velocity in body axes (what a
    gyro would read); ``wrel{x,y,z}_radps`` is ω_BR, relative to the orbit frame.
    Torque columns are ``<source>_{x,y,z}_Nm`` in body axes; ``wheel<i>_cmd_Nm`` is
    the control's motor torque and ``torquer_{x,y,z}_Am2`` the torquer dipole.
    """
    cols = {
        "t_s": result.t_s,
        "yaw_deg": result.yaw_rad * RAD2DEG,
        "roll_deg": result.roll_rad * RAD2DEG,
        "pitch_deg": result.pitch_rad * RAD2DEG,
        "wx_radps": result.w_bn_radps[:, 0],
        "wy_radps": result.w_bn_radps[:, 1],
        "wz_radps": result.w_bn_radps[:, 2],
        "wrelx_radps": result.w_br_radps[:, 0],
        "wrely_radps": result.w_br_radps[:, 1],
        "wrelz_radps": result.w_br_radps[:, 2],
    }
    for i in range(result.wheel_speeds_radps.shape[1]):
        cols[f"wheel{i + 1}_rpm"] = result.wheel_speeds_radps[:, i] * RADPS2RPM
    cols["h_Nms"] = result.h_Nms
    cols["H_Nms"] = result.H_Nms
    cols["eclipse"] = result.eclipse.astype(float)
    cols["shadow"] = result.shadow
    for i in range(result.wheel_command_Nm.shape[1]):
        cols[f"wheel{i + 1}_cmd_Nm"] = result.wheel_command_Nm[:, i]
    for k, axis in enumerate("xyz"):
        cols[f"torquer_{axis}_Am2"] = result.torquer_dipole_Am2[:, k]
    for name, torque in result.torques.items():
        for k, axis in enumerate("xyz"):
            cols[f"{name}_{axis}_Nm"] = torque[:, k]
    return cols


def write_truth_csv(path: Path | str, result) -> None:
    cols = truth_columns(result)
    data = np.column_stack(list(cols.values()))
    # repr-exact floats (%.17g) so that a file round-trips bit for bit.
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt="%.17g")
