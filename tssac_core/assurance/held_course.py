"""The law that holds a backup's lead on a ground line (issue 58; the prediction it flies:
:func:`tssac_core.assurance.lagged_backups.held_rollout`).

A lead longer than the open roll-out the fit covers flies open loop (heading-rate command 0) for ``held_after_s``, then
holds the ground line through where the vehicle is at that moment, along the course the monitor's model predicted
there. An open lead's heading error grows its path's error with the lead's length (a fraction of a degree left by the
roll-out is hundreds of metres after a minute and a half); a held one is bounded by the error where the hold begins and
the law's transient.

The law is a vector field on the line (as ArduPlane's and most autopilots' straight-line guidance): with e the signed
cross-track distance (left of the line positive) and chi_l the line's course, the desired course is

    chi_d = chi_l - chi_inf (2 / pi) atan(e / L)

(straight at the line from far off, along it on it), and the heading-rate command is k (chi_d - chi) on the ground
course chi, clipped at the limit. In still air, the only air it is predicted for, course and heading are one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LineLaw:
    """The held lead's gains (module docstring)."""

    course_gain_1_s: float = 0.4
    """k: heading rate per radian of course error (1/s), below 1 / (2 tau) of the slowest airframe's lag."""
    approach_deg: float = 20.0
    """chi_inf: the course across the line when far off it (deg, in (0, 90])."""
    cross_track_scale_m: float = 400.0
    """L: the cross-track distance at which the approach is half of chi_inf's (m)."""

    def __post_init__(self) -> None:
        if not (self.course_gain_1_s > 0.0 and 0.0 < self.approach_deg <= 90.0 and self.cross_track_scale_m > 0.0):
            raise ValueError(f"a line law needs a positive gain and scale and an approach in (0, 90] deg: {self}")


def cross_track_m(
    x: np.ndarray, y: np.ndarray, line_x: np.ndarray, line_y: np.ndarray, course_rad: np.ndarray
) -> np.ndarray:
    """The signed distance of (x, y) from the line through (line_x, line_y) along ``course_rad``, left positive."""
    return -(x - line_x) * np.sin(course_rad) + (y - line_y) * np.cos(course_rad)


def line_turn_rate(
    x: np.ndarray,
    y: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    line: tuple[np.ndarray, np.ndarray, np.ndarray],
    turn_rate_max_rad_s: np.ndarray,
    law: LineLaw,
) -> np.ndarray:
    """The heading-rate command (rad/s, counter-clockwise positive) that holds the ground ``line`` (x, y of a point on
    it, its course), for vehicles at (x, y) moving over the ground at (gx, gy), (M,)."""
    line_x, line_y, course = line
    e = cross_track_m(x, y, line_x, line_y, course)
    desired = course - math.radians(law.approach_deg) * (2.0 / math.pi) * np.arctan(e / law.cross_track_scale_m)
    error = np.mod(desired - np.arctan2(gy, gx) + np.pi, 2.0 * np.pi) - np.pi
    limit = np.asarray(turn_rate_max_rad_s, dtype=np.float64)
    return np.clip(law.course_gain_1_s * error, -limit, limit)
