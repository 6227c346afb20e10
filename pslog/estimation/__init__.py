"""Estimation: continuous-time ball trajectories fitted to every detection's viewing ray.

- :mod:`~pslog.estimation.bspline`: cubic B-spline bases and derivatives (triple knots for
  velocity jumps);
- :mod:`~pslog.estimation.projection`: a camera's projection to distorted pixels with its
  analytic Jacobian;
- :mod:`~pslog.estimation.trajectory`: the robust, sparse Gauss–Newton fit with a motion
  prior, automatic bounce/kick breaks and marginal covariances (:func:`fit_trajectory`).
"""

from .projection import project_with_jacobian
from .trajectory import Fit, MotionPrior, SmoothOptions, Trajectory, fit_trajectory

__all__ = ["Fit", "MotionPrior", "SmoothOptions", "Trajectory", "fit_trajectory",
           "project_with_jacobian"]
