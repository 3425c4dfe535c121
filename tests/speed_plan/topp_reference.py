"""Independent time-optimal C speed of one revolution, by TOPP-RA (the `toppra` package).

Reads JSON on stdin: {"x_mm": [X at C = k * 360 / n degrees, k = 0..n-1], "limits":
{"x_velocity_mm_s", "x_acceleration_mm_s2", "c_max_speed_rad_s", "c_max_accel_rad_s2"},
"grid_deg": step of toppra's grid}. Prints JSON: {"revolution_s": time of one revolution}.

The path is (X(C), C) against the path parameter s = C in radians. X(C) is a periodic cubic
spline (scipy) through the exact X values, so its derivatives are this script's own, not
the planner's. The path runs three revolutions from rest to rest and the middle one is
timed: from rest the C acceleration limit reaches any admissible speed within half a
revolution (600 rpm at 36 000 deg/s^2 takes 180 deg), so the middle revolution is the
periodic optimum. No jerk limit: the time is a lower bound for any plan that also limits
jerk.
"""

import json
import sys

import numpy as np
import toppra
import toppra.algorithm as algo
import toppra.constraint as constraint
from scipy.interpolate import CubicSpline

TURNS = 3


class ProfilePath(toppra.interpolator.AbstractGeometricPath):
    """(X(C), C) for C from 0 to TURNS revolutions, X periodic."""

    def __init__(self, x_mm):
        n = len(x_mm)
        c = np.linspace(0.0, 2.0 * np.pi, n + 1)
        self.x = CubicSpline(c, np.append(x_mm, x_mm[0]), bc_type="periodic")

    def __call__(self, s, order=0):
        s = np.atleast_1d(np.asarray(s, dtype=float))
        x = self.x(np.mod(s, 2.0 * np.pi), order)
        c = s if order == 0 else (np.ones_like(s) if order == 1 else np.zeros_like(s))
        return np.stack([x, c], axis=1)

    @property
    def dof(self):
        return 2

    @property
    def path_interval(self):
        return np.array([0.0, TURNS * 2.0 * np.pi])

    @property
    def waypoints(self):
        return None


def main():
    data = json.load(sys.stdin)
    lim = data["limits"]
    path = ProfilePath(np.asarray(data["x_mm"], dtype=float))
    v = np.array(
        [
            [-lim["x_velocity_mm_s"], lim["x_velocity_mm_s"]],
            [-lim["c_max_speed_rad_s"], lim["c_max_speed_rad_s"]],
        ]
    )
    a = np.array(
        [
            [-lim["x_acceleration_mm_s2"], lim["x_acceleration_mm_s2"]],
            [-lim["c_max_accel_rad_s2"], lim["c_max_accel_rad_s2"]],
        ]
    )
    per_turn = int(round(360.0 / data["grid_deg"]))
    grid = np.linspace(0.0, TURNS * 2.0 * np.pi, TURNS * per_turn + 1)
    instance = algo.TOPPRA(
        [
            constraint.JointVelocityConstraint(v),
            constraint.JointAccelerationConstraint(a),
        ],
        path,
        gridpoints=grid,
        solver_wrapper="seidel",
    )
    _, sd, _ = instance.compute_parameterization(0.0, 0.0)
    if sd is None or np.isnan(sd).any():
        raise SystemExit("toppra found no parameterisation")
    middle = slice(per_turn, 2 * per_turn + 1)
    s, w = grid[middle], sd[middle]
    revolution = float(np.sum(2.0 * np.diff(s) / (w[:-1] + w[1:])))
    json.dump({"revolution_s": revolution}, sys.stdout)


if __name__ == "__main__":
    main()
