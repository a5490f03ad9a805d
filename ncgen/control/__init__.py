"""ncgen.control: exact derivatives of one integrator step, gradients through rollouts,
iLQR and model-predictive control exported as C (see docs/control.md)."""
from ncgen.control.ilqr import ILQRResult, ilqr
from ncgen.control.step import StepDidNotConverge, StepFunction, step_function

__all__ = ["ILQRResult", "ilqr", "StepDidNotConverge", "StepFunction", "step_function"]
