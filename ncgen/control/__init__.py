"""ncgen.control: exact derivatives of one integrator step, gradients through rollouts,
iLQR and model-predictive control exported as C (see docs/control.md)."""
from ncgen.control.export import export_mpc
from ncgen.control.ilqr import ILQRResult, ilqr
from ncgen.control.mpc import MPC
from ncgen.control.step import StepDidNotConverge, StepFunction, step_function

__all__ = ["ILQRResult", "MPC", "export_mpc", "ilqr", "StepDidNotConverge", "StepFunction", "step_function"]
