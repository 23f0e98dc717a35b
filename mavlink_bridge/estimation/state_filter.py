"""Kalman filter for one UAV's horizontal state, fed by MAVLink position/velocity telemetry.

Frame and units follow the paper's eq. 5: x east, y north (metres), heading phi measured from east,
counter-clockwise (rad), speed v (m/s), turn rate omega = phi' (rad/s). Measurements are GPS-like
position (east, north) and velocity (east, north), e.g. from LOCAL_POSITION_NED (swap N/E) or
GLOBAL_POSITION_INT (after projecting to the local frame), stamped with the vehicle's clock
(time_boot_ms / 1000); the filter never uses the wall clock.

Models (:class:`FilterModel`)
-----------------------------
* ``CONSTANT_TURN_EKF`` (default): state [x, y, v, phi, omega]; eq. 5 with u and omega' as white
  noise, integrated exactly over each step (constant speed and turn rate); filterpy's
  ``ExtendedKalmanFilter`` with the analytic Jacobians of that transition and of the measurement
  h(x) = [x, y, v cos phi, v sin phi]. phi is wrapped to [-pi, pi) after every step.
* ``CONSTANT_TURN``: the same model with filterpy's ``UnscentedKalmanFilter`` and
  ``MerweScaledSigmaPoints`` (alpha 0.3, beta 2, kappa 0); phi is wrapped in the state residual and
  in the circular weighted mean of the sigma points.
* ``CONSTANT_VELOCITY``: state [x, y, v_east, v_north]; filterpy's linear ``KalmanFilter``;
  acceleration is white noise on each axis. It has no turn rate, so a turn is unmodelled
  acceleration (v * omega = 13 m/s^2 at 250 m/s and 3 deg/s): its process noise has to cover that,
  see :attr:`FilterNoise.accel_sigma_m_s2`.

Process noise is continuous white noise integrated in closed form over the step (for the
constant-turn model, linearised about the current speed and heading), so the result does not hinge
on how a gap is cut into steps: for the constant-velocity model one 2 s prediction equals twenty
0.1 s ones exactly, for the constant-turn model to well under a metre (both pinned by tests).

Measured (``python benchmarks/bench_filter.py``, seed 0, 20 noise draws, JSON in
``benchmarks/results/filter.json``). Sensor sigma 10 m / 1 m/s per axis at 10 Hz for 60 s; errors
after the first 10 s; "gap" = no measurement for 2 s from t = 40 s while the filter predicts
every 0.1 s, position error at the end of the gap (mean / worst of 20). Noise:
``FilterNoise.from_sensor(10, 1, max_accel_m_s2=10, max_turn_rate_rad_s=radians(5))`` for both
models; in brackets, the constant-velocity model with its acceleration noise raised to 5 m/s^2,
its best position error on the manoeuvring track in a sweep 2.5-40 (the JSON has the sweep).

Constant turn, 250 m/s, 3 deg/s (raw measurement position RMS 14.1 m):

==================================  ==============  =============  ==================
figure                              constant turn   constant turn  constant velocity
                                    (EKF, default)  (UKF)
==================================  ==============  =============  ==================
RMS position error (m)              1.51            1.51           1.52  [1.53]
RMS heading error (deg)             0.14            0.14           0.30  [0.21]
RMS speed error (m/s)               0.61            0.61           0.61  [0.79]
RMS turn-rate error (deg/s)         0.37            0.37           --
position error after 2 s gap (m)    4.6 / 11.1      4.6 / 11.1     28.3 / 31.5  [26.8 / 30.6]
position_sigma_m after the gap      10.8            10.8           6.3  [11.9]
update + predict_to, per call (us)  91 + 47         492 + 304      65 + 25
==================================  ==============  =============  ==================

(Times from one run on an otherwise idle machine.) Manoeuvring (200 m/s;
turns +5, -4, +2 deg/s; +/-10 m/s^2 for 5 s; the gap spans a turn reversal): both constant-turn
filters 1.57 m, 0.18 deg, gap 10.4 / 20.0 m (sigma 9.3 m); constant velocity 1.67 m, 0.37 deg,
gap 19.8 / 22.9 m (sigma 6.3 m) [1.55 m, 0.24 deg, 18.2 / 22.0 m].

Choice. With 10 Hz velocity measurements every model estimates position equally well (about 1.5 m
DRMS, ten times better than the raw fixes, and ``position_sigma_m`` agrees with it). The
constant-turn model is the default because it is as good or better at everything else: heading
error 0.14 deg against 0.21-0.30, a turn-rate estimate, and a 2 s dropout in a steady turn costs
4.6 m against 26-28 m. No retuning of the constant-velocity model fixes the last one (its error is
the unmodelled v * omega * t^2 / 2 = 26 m; more acceleration noise only widens its sigma), and at
the noise that suits its position estimate its sigma (6 m) understates that error. At 10 Hz the
model is nearly linear over a step, so the extended and the unscented filter agree to millimetres
(pinned by a test); the extended one costs a sixth as much, which counts in a control loop that the
SITL runs 50 times faster than real time. The unscented and the constant-velocity filters stay
selectable.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from numpy.typing import NDArray

from mavlink_bridge.estimation.filter_model import FilterModel

__all__ = ["FilterModel", "FilterNoise", "VehicleStateFilter"]

_log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: A measurement this much older than the last applied one is more than reordering: most likely
#: the vehicle rebooted (time_boot_ms restarted), which only :meth:`VehicleStateFilter.reset` fixes.
_CLOCK_JUMP_WARN_S = 5.0


def _wrap_angle_rad(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _finite_pair(name: str, value: tuple[float, float] | FloatArray) -> tuple[float, float]:
    if type(value) is tuple and len(value) == 2 and type(value[0]) is float and type(value[1]) is float:
        # The companion's case (two floats), without the round trip through a numpy array.
        if math.isfinite(value[0]) and math.isfinite(value[1]):
            return value
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be two finite numbers (east, north), got {value!r}")
    return float(arr[0]), float(arr[1])


def _finite_time(t_s: float) -> float:
    t = float(t_s)
    if not math.isfinite(t):
        raise ValueError(f"timestamp must be finite, got {t_s!r}")
    return t


@dataclass(frozen=True)
class FilterNoise:
    """Measurement and process noise of :class:`VehicleStateFilter` (one-sigma figures).

    The defaults are ``from_sensor(10, 1, max_accel_m_s2=10, max_turn_rate_rad_s=radians(5))``.
    """

    pos_sigma_m: float = 10.0
    """Position measurement noise, per horizontal axis (m)."""
    vel_sigma_m_s: float = 1.0
    """Velocity measurement noise, per horizontal axis (m/s)."""
    accel_sigma_m_s2: float = 2.5
    """Unmodelled acceleration (m/s^2), as continuous white noise of spectral density
    ``accel_sigma_m_s2**2 * 1 s``: the velocity uncertainty it adds in one second. Constant-turn
    model: along-track acceleration u of eq. 5 only. Constant-velocity model: acceleration on each
    axis, which must also cover the turn (lateral) acceleration v * omega."""
    turn_accel_sigma_rad_s2: float = 0.0218
    """Unmodelled turn-rate change omega' (rad/s^2), continuous white noise of spectral density
    ``turn_accel_sigma_rad_s2**2 * 1 s``. Constant-turn model only."""
    initial_turn_rate_sigma_rad_s: float = 0.0873
    """Prior uncertainty of the turn rate at :meth:`VehicleStateFilter.reset`, which starts it at
    zero (rad/s). Constant-turn model only."""

    def __post_init__(self) -> None:
        for name in (
            "pos_sigma_m",
            "vel_sigma_m_s",
            "accel_sigma_m_s2",
            "turn_accel_sigma_rad_s2",
            "initial_turn_rate_sigma_rad_s",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f"FilterNoise.{name} must be a number, got {value!r}")
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"FilterNoise.{name} must be finite and > 0, got {value!r}")
            object.__setattr__(self, name, float(value))

    @classmethod
    def from_sensor(
        cls,
        pos_sigma_m: float,
        vel_sigma_m_s: float,
        max_accel_m_s2: float = 10.0,
        max_turn_rate_rad_s: float = math.radians(5.0),
    ) -> FilterNoise:
        """Build from a scenario's sensor sigmas and the vehicle's limits (plain numbers).

        Process noise: acceleration sigma = max_accel / 4; turn-rate change sigma =
        max_turn_rate / 4 s; prior turn-rate sigma = max_turn_rate. Chosen on the benchmark of the
        module docstring: with 10 Hz velocity measurements, lower process noise smooths more and
        still follows +/-10 m/s^2 steps; a slower turn-rate noise (/8, /16) predicts constant turns
        better but lags at turn reversals.
        """
        for name, value in (("max_accel_m_s2", max_accel_m_s2), ("max_turn_rate_rad_s", max_turn_rate_rad_s)):
            v = float(value)
            if not math.isfinite(v) or v <= 0.0:
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        return cls(
            pos_sigma_m=float(pos_sigma_m),
            vel_sigma_m_s=float(vel_sigma_m_s),
            accel_sigma_m_s2=0.25 * float(max_accel_m_s2),
            turn_accel_sigma_rad_s2=float(max_turn_rate_rad_s) / 4.0,
            initial_turn_rate_sigma_rad_s=float(max_turn_rate_rad_s),
        )


def _integrator_q(spectral_density: float, dt_s: float, order: int) -> FloatArray:
    """Exact discrete covariance of a chain of `order` integrators driven by white noise.

    order 2: [position, velocity] under white acceleration; order 3 adds one more integrator.
    """
    if order == 2:
        q = np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
    else:
        q = np.array(
            [
                [dt_s**5 / 20.0, dt_s**4 / 8.0, dt_s**3 / 6.0],
                [dt_s**4 / 8.0, dt_s**3 / 3.0, dt_s**2 / 2.0],
                [dt_s**3 / 6.0, dt_s**2 / 2.0, dt_s],
            ]
        )
    return spectral_density * q


class _Backend(Protocol):
    """What VehicleStateFilter needs from a motion model (state kept inside a filterpy object)."""

    def initialise(
        self, pos_m: tuple[float, float], vel_m_s: tuple[float, float], turn_rate: tuple[float, float] | None
    ) -> None: ...
    def predict(self, dt_s: float) -> None: ...
    def update(self, pos_m: tuple[float, float], vel_m_s: tuple[float, float]) -> None: ...
    def get(self) -> tuple[FloatArray, FloatArray]: ...
    def set(self, x: FloatArray, p: FloatArray) -> None: ...
    def pos_vel(self) -> tuple[float, float, float, float]: ...
    def turn_rate_rad_s(self) -> float | None: ...
    def turn_rate_sigma_rad_s(self) -> float | None: ...
    def pos_cov(self) -> FloatArray: ...
    def speed_heading_sigma(self) -> tuple[float, float]: ...


class _ConstantVelocity:
    """State [x, y, v_east, v_north]; linear KF."""

    def __init__(self, noise: FilterNoise) -> None:
        self._noise = noise
        self._kf = KalmanFilter(dim_x=4, dim_z=4)
        self._kf.H = np.eye(4)
        self._kf.R = np.diag([noise.pos_sigma_m**2] * 2 + [noise.vel_sigma_m_s**2] * 2)

    def initialise(
        self, pos_m: tuple[float, float], vel_m_s: tuple[float, float], turn_rate: tuple[float, float] | None
    ) -> None:
        self._kf.x = np.array([pos_m[0], pos_m[1], vel_m_s[0], vel_m_s[1]], dtype=np.float64)
        self._kf.P = self._kf.R.copy()

    def predict(self, dt_s: float) -> None:
        f = np.eye(4)
        f[0, 2] = f[1, 3] = dt_s
        q_axis = _integrator_q(self._noise.accel_sigma_m_s2**2, dt_s, 2)
        q = np.zeros((4, 4))
        for axis in (0, 1):
            idx = np.array([axis, axis + 2])
            q[np.ix_(idx, idx)] = q_axis
        self._kf.predict(F=f, Q=q)

    def update(self, pos_m: tuple[float, float], vel_m_s: tuple[float, float]) -> None:
        self._kf.update(np.array([pos_m[0], pos_m[1], vel_m_s[0], vel_m_s[1]]))
        self._kf.P = 0.5 * (self._kf.P + self._kf.P.T)

    def get(self) -> tuple[FloatArray, FloatArray]:
        return self._kf.x.copy(), self._kf.P.copy()

    def set(self, x: FloatArray, p: FloatArray) -> None:
        self._kf.x = x.copy()
        self._kf.P = p.copy()

    def pos_vel(self) -> tuple[float, float, float, float]:
        x = self._kf.x
        return float(x[0]), float(x[1]), float(x[2]), float(x[3])

    def turn_rate_rad_s(self) -> float | None:
        return None

    def turn_rate_sigma_rad_s(self) -> float | None:
        return None

    def pos_cov(self) -> FloatArray:
        return np.asarray(self._kf.P[:2, :2], dtype=np.float64)

    def speed_heading_sigma(self) -> tuple[float, float]:
        # The velocity's worst-direction sigma bounds the speed's (along the track) and, over the speed, the
        # heading's (across it).
        sigma = math.sqrt(max(0.0, float(np.linalg.eigvalsh(self._kf.P[2:4, 2:4])[-1])))
        speed = math.hypot(float(self._kf.x[2]), float(self._kf.x[3]))
        return sigma, sigma / max(speed, 1.0)


# Constant-turn state layout (named, never bare indices elsewhere).
_X, _Y, _V, _PHI, _OMEGA = range(5)
_SMALL_TURN_RAD_S = 1e-6


def _ct_fx(state: FloatArray, dt: float) -> FloatArray:
    """Eq. 5 integrated exactly over dt at constant v and omega."""
    # Python floats: arithmetic on them rounds as numpy's does, at a fraction of the cost of numpy scalars, and the
    # result is one array made of them rather than a copy of the state with items set one by one.
    x, y, v, phi, omega = np.asarray(state, dtype=np.float64).tolist()
    phi_end = phi + omega * dt
    if abs(omega) > _SMALL_TURN_RAD_S:
        x_end = x + v / omega * (math.sin(phi_end) - math.sin(phi))
        y_end = y + v / omega * (math.cos(phi) - math.cos(phi_end))
    else:
        mid = phi + 0.5 * omega * dt
        x_end = x + v * dt * math.cos(mid)
        y_end = y + v * dt * math.sin(mid)
    return np.array([x_end, y_end, v, phi_end, omega])


def _ct_hx(state: FloatArray) -> FloatArray:
    v, phi = state[_V], state[_PHI]
    return np.array([state[_X], state[_Y], v * math.cos(phi), v * math.sin(phi)])


def _ct_residual_x(a: FloatArray, b: FloatArray) -> FloatArray:
    d = np.subtract(a, b)
    d[_PHI] = _wrap_angle_rad(float(d[_PHI]))
    return d


def _ct_mean_x(sigmas: FloatArray, wm: FloatArray) -> FloatArray:
    mean = np.dot(wm, sigmas)
    mean[_PHI] = math.atan2(float(np.dot(wm, np.sin(sigmas[:, _PHI]))), float(np.dot(wm, np.cos(sigmas[:, _PHI]))))
    return mean


def _ct_q(noise: FilterNoise, state: FloatArray, dt_s: float) -> FloatArray:
    """Process noise of the constant-turn models over dt_s, linearised at the state's speed and heading.

    Along track, white acceleration drives [s_along, v]; across track, white omega' drives
    [s_across / v, phi, omega] (linearised at speed v). Built from scalars in one array: a dozen
    small numpy operations on a 5 x 5 matrix cost more than the arithmetic.
    """
    v, phi = float(state[_V]), float(state[_PHI])
    ax, ay = math.cos(phi), math.sin(phi)  # along track
    cx, cy = -math.sin(phi), math.cos(phi)  # across track
    a00, a01, a11, qw = _ct_q_terms(noise.accel_sigma_m_s2, noise.turn_accel_sigma_rad_s2, dt_s)
    w_pos = v * v * qw[0][0]
    w_phi, w_omega = v * qw[0][1], v * qw[0][2]
    xx = a00 * (ax * ax) + w_pos * (cx * cx)
    xy = a00 * (ax * ay) + w_pos * (cx * cy)
    yy = a00 * (ay * ay) + w_pos * (cy * cy)
    return np.array(
        [
            [xx, xy, a01 * ax, w_phi * cx, w_omega * cx],
            [xy, yy, a01 * ay, w_phi * cy, w_omega * cy],
            [a01 * ax, a01 * ay, a11, 0.0, 0.0],
            [w_phi * cx, w_phi * cy, 0.0, qw[1][1], qw[1][2]],
            [w_omega * cx, w_omega * cy, 0.0, qw[2][1], qw[2][2]],
        ]
    )


@functools.lru_cache(maxsize=64)
def _ct_q_terms(
    accel_sigma_m_s2: float, turn_accel_sigma_rad_s2: float, dt_s: float
) -> tuple[float, float, float, tuple[tuple[float, ...], ...]]:
    """The integrator covariances :func:`_ct_q` rotates, for one step length (a lockstep companion predicts over the
    same 0.1 s every step): along track (a00, a01, a11), across track the 3 x 3 block as floats."""
    qa = _integrator_q(accel_sigma_m_s2**2, dt_s, 2)
    qw = _integrator_q(turn_accel_sigma_rad_s2**2, dt_s, 3)
    return float(qa[0, 0]), float(qa[0, 1]), float(qa[1, 1]), tuple(tuple(float(x) for x in row) for row in qw)


def _ct_jacobian(state: FloatArray, dt: float) -> FloatArray:
    """d _ct_fx / d state: the extended filter's transition matrix (eq. 5 at constant v and omega)."""
    v, phi, omega = float(state[_V]), float(state[_PHI]), float(state[_OMEGA])
    phi_end = phi + omega * dt
    if abs(omega) > _SMALL_TURN_RAD_S:
        ds, dc = math.sin(phi_end) - math.sin(phi), math.cos(phi) - math.cos(phi_end)
        xv, yv = ds / omega, dc / omega
        xphi, yphi = -v / omega * dc, v / omega * ds
        xomega = -v / omega**2 * ds + v / omega * math.cos(phi_end) * dt
        yomega = -v / omega**2 * dc + v / omega * math.sin(phi_end) * dt
    else:
        mid = phi + 0.5 * omega * dt
        c, s = math.cos(mid), math.sin(mid)
        xv, yv = dt * c, dt * s
        xphi, yphi = -v * dt * s, v * dt * c
        xomega, yomega = -0.5 * v * dt * dt * s, 0.5 * v * dt * dt * c
    return np.array(
        [
            [1.0, 0.0, xv, xphi, xomega],
            [0.0, 1.0, yv, yphi, yomega],
            [0.0, 0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0, dt],
            [0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    )


def _ct_h_jacobian(state: FloatArray) -> FloatArray:
    """d _ct_hx / d state."""
    v, phi = state[_V], state[_PHI]
    c, s = math.cos(phi), math.sin(phi)
    return np.array(
        [
            [1.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, c, -v * s, 0.0],
            [0.0, 0.0, s, v * c, 0.0],
        ]
    )


class _TurnEkf(ExtendedKalmanFilter):
    """filterpy's extended filter, with eq. 5 as its (non-linear) state transition."""

    dt_s = 0.1
    x: NDArray[np.float64]

    def predict_x(self, u: object = 0) -> None:
        self.x = _ct_fx(self.x, self.dt_s)


class _ConstantTurn:
    """State [x, y, v, phi, omega]; unscented (default) or extended KF."""

    def __init__(self, noise: FilterNoise, unscented: bool = True) -> None:
        self._noise = noise
        self._unscented = unscented
        if unscented:
            points = MerweScaledSigmaPoints(5, alpha=0.3, beta=2.0, kappa=0.0, subtract=_ct_residual_x)
            self._kf: UnscentedKalmanFilter | _TurnEkf = UnscentedKalmanFilter(
                dim_x=5,
                dim_z=4,
                dt=0.1,
                hx=_ct_hx,
                fx=_ct_fx,
                points=points,
                x_mean_fn=_ct_mean_x,
                residual_x=_ct_residual_x,
            )
        else:
            self._kf = _TurnEkf(dim_x=5, dim_z=4)
        self._kf.R = np.diag([noise.pos_sigma_m**2] * 2 + [noise.vel_sigma_m_s**2] * 2)

    def initialise(
        self, pos_m: tuple[float, float], vel_m_s: tuple[float, float], turn_rate: tuple[float, float] | None
    ) -> None:
        speed = math.hypot(*vel_m_s)
        n = self._noise
        omega, omega_sigma = (0.0, n.initial_turn_rate_sigma_rad_s) if turn_rate is None else turn_rate
        self._kf.x = np.array([pos_m[0], pos_m[1], speed, math.atan2(vel_m_s[1], vel_m_s[0]), omega])
        # Heading from a velocity of speed s with noise sigma per axis: sigma_phi ~ sigma / s,
        # meaningless (use pi) when the vehicle is barely moving.
        phi_sigma = min(math.pi, n.vel_sigma_m_s / max(speed, 1e-9))
        self._kf.P = np.diag([n.pos_sigma_m**2, n.pos_sigma_m**2, n.vel_sigma_m_s**2, phi_sigma**2, omega_sigma**2])

    def _tidy(self) -> None:
        self._kf.x[_PHI] = _wrap_angle_rad(float(self._kf.x[_PHI]))
        p = self._kf.P + self._kf.P.T
        p *= 0.5  # 0.5 * (P + P^T), halved in place: one array fewer
        self._kf.P = p

    def predict(self, dt_s: float) -> None:
        if dt_s == 0.0 and not self._unscented:
            # The extended filter's zero step is the identity (F = I, Q = 0): nothing to compute. (The
            # unscented one draws its sigma points in predict, so it always runs.)
            return
        self._kf.Q = _ct_q(self._noise, self._kf.x, dt_s)
        if self._unscented:
            self._kf.predict(dt=dt_s)
        else:
            self._kf.F = _ct_jacobian(self._kf.x, dt_s)  # at the prior mean, before predict_x moves it
            self._kf.dt_s = dt_s
            self._kf.predict()
        self._tidy()

    def update(self, pos_m: tuple[float, float], vel_m_s: tuple[float, float]) -> None:
        z = np.array([pos_m[0], pos_m[1], vel_m_s[0], vel_m_s[1]])
        if self._unscented:
            self._kf.update(z)
        else:
            self._kf.update(z, _ct_h_jacobian, _ct_hx)
        self._tidy()

    def get(self) -> tuple[FloatArray, FloatArray]:
        return self._kf.x.copy(), self._kf.P.copy()

    def set(self, x: FloatArray, p: FloatArray) -> None:
        self._kf.x = x.copy()
        self._kf.P = p.copy()

    def pos_vel(self) -> tuple[float, float, float, float]:
        x = self._kf.x
        v, phi = float(x[_V]), float(x[_PHI])
        return float(x[_X]), float(x[_Y]), v * math.cos(phi), v * math.sin(phi)

    def turn_rate_rad_s(self) -> float | None:
        return float(self._kf.x[_OMEGA])

    def turn_rate_sigma_rad_s(self) -> float | None:
        return math.sqrt(max(0.0, float(self._kf.P[_OMEGA, _OMEGA])))

    def pos_cov(self) -> FloatArray:
        return np.asarray(self._kf.P[:2, :2], dtype=np.float64)

    def speed_heading_sigma(self) -> tuple[float, float]:
        p = self._kf.P
        return math.sqrt(max(0.0, float(p[_V, _V]))), math.sqrt(max(0.0, float(p[_PHI, _PHI])))


class VehicleStateFilter:
    """Horizontal state of one vehicle from time-stamped position/velocity measurements.

    Time only moves forward: :meth:`predict_to` an earlier time does nothing, and a measurement
    stamped at or before the last applied one (a duplicate, or one overtaken by a newer message)
    is ignored. A measurement newer than the last applied one but older than the current estimate
    (the caller predicted ahead, then a late message came in) is applied at its own time, by
    re-predicting from the last posterior, and the estimate is then predicted back to the current
    time — valid because nothing but prediction happened in between.
    """

    def __init__(self, noise: FilterNoise | None = None, model: FilterModel = FilterModel.CONSTANT_TURN_EKF) -> None:
        self._noise = noise if noise is not None else FilterNoise()
        self._model = model
        self._backend: _Backend = (
            _ConstantVelocity(self._noise)
            if model is FilterModel.CONSTANT_VELOCITY
            else _ConstantTurn(self._noise, unscented=model is FilterModel.CONSTANT_TURN)
        )
        self._t_s: float | None = None
        # Posterior after the last applied measurement (or reset): time, mean, covariance.
        self._post_t_s = 0.0
        self._post_x: FloatArray = np.zeros(0)
        self._post_p: FloatArray = np.zeros((0, 0))
        self._rejected_count = 0

    # -- commands -------------------------------------------------------------------------------

    def reset(
        self,
        t_s: float,
        pos_m: tuple[float, float],
        vel_m_s: tuple[float, float],
        turn_rate: tuple[float, float] | None = None,
    ) -> None:
        """Start afresh from one measurement at time t_s (s, vehicle clock). ``turn_rate``: what is known of the turn
        rate then, (rad/s, its standard deviation); None: 0, as uncertain as
        :attr:`FilterNoise.initial_turn_rate_sigma_rad_s` (a constant-velocity filter has no turn rate)."""
        t = _finite_time(t_s)
        pos = _finite_pair("pos_m", pos_m)
        vel = _finite_pair("vel_m_s", vel_m_s)
        if turn_rate is not None and not (math.isfinite(turn_rate[0]) and turn_rate[1] > 0.0):
            raise ValueError(f"turn_rate must be finite with a positive sigma, got {turn_rate!r}")
        self._backend.initialise(pos, vel, turn_rate)
        self._t_s = t
        self._snapshot(t)
        self._rejected_count = 0
        _log.debug("filter reset at t=%.3f s, pos=%s, vel=%s", t, pos, vel)

    def predict_to(self, t_s: float) -> bool:
        """Predict forward to t_s; an earlier or equal time leaves the state unchanged (False)."""
        now = self._require_initialised()
        t = _finite_time(t_s)
        if t <= now:
            if t < now:
                _log.debug("predict_to(%.3f) ignored: estimate is already at %.3f s", t, now)
            return False
        self._backend.predict(t - now)
        self._t_s = t
        return True

    def predict(self, dt_s: float) -> bool:
        """Predict forward by dt_s >= 0 seconds (see :meth:`predict_to`)."""
        dt = _finite_time(dt_s)
        if dt < 0.0:
            raise ValueError(f"dt_s must be >= 0, got {dt_s!r}")
        return self.predict_to(self._require_initialised() + dt)

    def update(self, t_s: float, pos_m: tuple[float, float], vel_m_s: tuple[float, float]) -> bool:
        """Apply a measurement taken at t_s; False (state unchanged) if it is not newer than the last.

        Predicts through any gap first. On a filter not yet reset, the first measurement resets it.
        """
        t = _finite_time(t_s)
        pos = _finite_pair("pos_m", pos_m)
        vel = _finite_pair("vel_m_s", vel_m_s)
        if self._t_s is None:
            self.reset(t, pos, vel)
            return True
        if t <= self._post_t_s:
            self._rejected_count += 1
            if t < self._post_t_s - _CLOCK_JUMP_WARN_S:
                _log.warning(
                    "measurement at %.3f s is %.1f s older than the last applied one: vehicle clock "
                    "reset? call reset()",
                    t,
                    self._post_t_s - t,
                )
            else:
                _log.debug("stale measurement at %.3f s ignored (last applied %.3f s)", t, self._post_t_s)
            return False
        now = self._t_s
        if t < now:
            # Predicted past this measurement's time: go back to the last posterior (only
            # prediction happened since) and apply the measurement at its own time.
            self._backend.set(self._post_x, self._post_p)
            start = self._post_t_s
        else:
            start = now
        # Always predict (dt may be 0): the unscented filter draws its sigma points there.
        self._backend.predict(t - start)
        self._backend.update(pos, vel)
        self._snapshot(t)
        if now > t:
            self._backend.predict(now - t)
        self._t_s = max(now, t)
        return True

    # -- estimate -------------------------------------------------------------------------------

    @property
    def model(self) -> FilterModel:
        """Motion model in use."""
        return self._model

    @property
    def noise(self) -> FilterNoise:
        """Noise settings in use."""
        return self._noise

    @property
    def initialised(self) -> bool:
        """True once reset() (or a first update()) has given the filter a state."""
        return self._t_s is not None

    @property
    def t_s(self) -> float:
        """Time of the current estimate (s, vehicle clock)."""
        return self._require_initialised()

    @property
    def last_measurement_t_s(self) -> float:
        """Time of the last applied measurement (or reset) (s)."""
        self._require_initialised()
        return self._post_t_s

    @property
    def rejected_count(self) -> int:
        """Measurements ignored as stale or duplicated since the last reset."""
        return self._rejected_count

    @property
    def pos_m(self) -> tuple[float, float]:
        """Estimated position (east, north) (m)."""
        self._require_initialised()
        x, y, _, _ = self._backend.pos_vel()
        return x, y

    @property
    def vel_m_s(self) -> tuple[float, float]:
        """Estimated velocity (east, north) (m/s)."""
        self._require_initialised()
        _, _, ve, vn = self._backend.pos_vel()
        return ve, vn

    @property
    def speed_m_s(self) -> float:
        """Estimated ground speed v (m/s)."""
        return math.hypot(*self.vel_m_s)

    @property
    def heading_rad(self) -> float:
        """Estimated heading phi of eq. 5: from east, counter-clockwise, in [-pi, pi) (rad)."""
        ve, vn = self.vel_m_s
        return _wrap_angle_rad(math.atan2(vn, ve))

    @property
    def turn_rate_rad_s(self) -> float | None:
        """Estimated turn rate omega (rad/s, counter-clockwise positive); None for constant velocity."""
        self._require_initialised()
        return self._backend.turn_rate_rad_s()

    @property
    def turn_rate_sigma_rad_s(self) -> float | None:
        """Standard deviation of the turn rate's estimate (rad/s); None for constant velocity."""
        self._require_initialised()
        return self._backend.turn_rate_sigma_rad_s()

    @property
    def position_sigma_m(self) -> float:
        """Expected horizontal position error, sqrt(P_xx + P_yy) (m, a DRMS figure)."""
        self._require_initialised()
        return math.sqrt(max(0.0, float(np.trace(self._backend.pos_cov()))))

    @property
    def position_sigma_major_m(self) -> float:
        """Standard deviation of the position along its worst direction: sqrt of the largest eigenvalue of the
        2x2 position covariance (m; what the runtime-assurance monitor widens its margin by)."""
        self._require_initialised()
        return math.sqrt(max(0.0, float(np.linalg.eigvalsh(self._backend.pos_cov())[-1])))

    @property
    def speed_heading_sigma(self) -> tuple[float, float]:
        """Standard deviations of the speed (m/s) and the heading (rad): the constant-turn models' own variances;
        for constant velocity, bounds from the velocity covariance's largest eigenvalue (over the speed, for the
        heading). What the runtime-assurance monitor's error bound takes them from."""
        self._require_initialised()
        return self._backend.speed_heading_sigma()

    # -- internals ------------------------------------------------------------------------------

    def _snapshot(self, t_s: float) -> None:
        self._post_t_s = t_s
        self._post_x, self._post_p = self._backend.get()

    def _require_initialised(self) -> float:
        if self._t_s is None:
            raise RuntimeError("VehicleStateFilter has no state yet: call reset() or update() first")
        return self._t_s
