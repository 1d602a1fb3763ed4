"""Pure, batch-first relative-orbit dynamics (imports nothing else from satenv but :mod:`satenv.errors`).

States are LVLH ``[x, y, z, vx, vy, vz]`` arrays ``(..., M, 6)`` (x radial, y along-track,
z orbit normal), inputs LVLH accelerations ``(..., M, 3)``, SI units throughout.

Models: ``"cw"`` (Clohessy-Wiltshire, exact ZOH), ``"nonlinear"`` (two-body, any
eccentricity), ``"j2"`` and ``"j2_drag"`` (exact ECI propagation of chief and deputies with
J2 and exponential-atmosphere drag, converted to LVLH with the frame rate including the
out-of-plane J2 term). Rigid-body attitude (quaternions, relative rotational dynamics, thruster
configuration, pointing frames) is in :mod:`satenv.dynamics.attitude`.
"""

from .attitude import (
    attitude_derivative,
    attitude_step,
    desired_angular_velocity,
    matrix_to_quat,
    pointing_error,
    pointing_frame,
    pointing_rate,
    quat_conjugate,
    quat_error,
    quat_kinematics,
    quat_multiply,
    quat_normalize,
    quat_to_euler_xyz,
    quat_to_matrix,
    relative_angular_acceleration,
    skew,
    thruster_matrices,
)
from .constants import J2_EARTH, MU_EARTH, OMEGA_EARTH, R_EARTH
from .control import delta_v, saturate_box, saturate_norm, unit_box_to_accel
from .cw import cw_continuous, cw_matrices, cw_step, cw_stm, prediction_matrices
from .disturbances import BoundedRandomDisturbance, sinusoid_disturbance
from .forces import FORCE_MODELS, ForceModel, acceleration, drag, j2, two_body
from .integrators import INTEGRATORS, euler_step, integrate, rk4_step
from .orbit import (
    Orbit,
    eci_to_lvlh,
    elements_to_rv,
    frame_rate,
    lvlh_rotation,
    lvlh_to_eci,
    rv_to_elements,
)
from .propagate import MODELS, RelativeModel, check_model, simulate

__all__ = [
    "attitude_derivative", "attitude_step", "desired_angular_velocity", "matrix_to_quat",
    "pointing_error", "pointing_frame", "pointing_rate", "quat_conjugate", "quat_error",
    "quat_kinematics", "quat_multiply", "quat_normalize", "quat_to_euler_xyz", "quat_to_matrix",
    "relative_angular_acceleration", "skew", "thruster_matrices",
    "FORCE_MODELS", "INTEGRATORS", "J2_EARTH", "MODELS", "MU_EARTH", "OMEGA_EARTH", "R_EARTH",
    "BoundedRandomDisturbance", "ForceModel", "Orbit", "RelativeModel", "acceleration",
    "check_model", "cw_continuous", "cw_matrices", "cw_step", "cw_stm", "delta_v", "drag",
    "eci_to_lvlh", "elements_to_rv", "euler_step", "frame_rate", "integrate", "j2",
    "lvlh_rotation", "lvlh_to_eci", "prediction_matrices", "rk4_step", "rv_to_elements",
    "saturate_box", "saturate_norm", "simulate", "sinusoid_disturbance", "two_body",
    "unit_box_to_accel",
]
