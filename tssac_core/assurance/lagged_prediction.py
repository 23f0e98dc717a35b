"""The monitor's :class:`~tssac_core.assurance.monitor.Prediction` under an airframe's response (issue 58): every
path flown by the airframe's lag model (:mod:`tssac_core.assurance.lagged_backups`), in wind carried by the air mass
as well, and backups that hold for ever there: in calm air a maximum-rate turn (its samples and the disk its
instantaneous centre cannot leave), in wind the ground loiter (:mod:`tssac_core.assurance.ground_loiter`: the lead's
samples and the loiter's disk).

The backups are the constant-speed ones (the braking ones are not offered: an airframe brakes at what it achieves, a
few m/s^2, and holds a speed where it does not). The estimate's error moves a backup's path as
:func:`~tssac_core.assurance.monitor.backup_error_m` says (in calm air with each lead K steps longer: the turn's
samples; in wind as :func:`~tssac_core.assurance.ground_loiter.loiter_backup_error_m` says).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tssac_core.assurance.ground_loiter import WindLoiter, loiter_backup_clearance, loiter_backup_error_m
from tssac_core.assurance.lagged_backups import (
    AirframeLag,
    LagState,
    Rollout,
    lagged_backup_clearance,
    lagged_rollout,
    straight_rollout,
)
from tssac_core.assurance.monitor import (
    N_TURNS,
    EstimateError,
    Prediction,
    Scene,
    backup_error_m,
    choose_backup,
    lead_steps,
    point_clearance,
)


@dataclass(frozen=True)
class LaggedPrediction:
    """Paths under the airframe's lag from the lag's state; in the steady ``wind`` (None: calm air) carried by the air
    mass, with the ground loiter as the backups' end (module docstring)."""

    airframe: AirframeLag
    lag: LagState
    wind: WindLoiter | None = None

    def select(self, rows: np.ndarray) -> LaggedPrediction:
        wind = None if self.wind is None else self.wind.select(rows)
        return LaggedPrediction(self.airframe.select(rows), self.lag.select(rows), wind)

    def _ground(self, path: Rollout, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The path's positions over the ground: the air mass's own, carried by the wind."""
        if self.wind is None:
            return path.xs, path.ys
        dx, dy = self.wind.drift(path.xs.shape[1], dt_s)
        return path.xs + dx, path.ys + dy

    def _half_step_m(self, scene: Scene) -> np.ndarray:
        """The farthest a point between two samples lies from one: half a step's ground distance."""
        gust = 0.0 if self.wind is None else self.wind.max_m_s
        return (scene.lim.speed_max_m_s + gust) * scene.dt_s / 2

    def after(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, pending: np.ndarray, scene: Scene
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Prediction]:
        lim = scene.lim
        actions = np.clip(pending, -1.0, 1.0)
        turn = actions[:, :, 0] * lim.turn_rate_max_rad_s[:, None]
        accel = actions[:, :, 1] * lim.accel_max_m_s2[:, None]
        path = lagged_rollout(x, y, v, phi, self.lag, turn, accel, self.airframe, lim, scene.dt_s)
        xs, ys = self._ground(path, scene.dt_s)
        end = (xs[:, -1], ys[:, -1], path.speeds[:, -1], path.headings[:, -1])
        return (*end, LaggedPrediction(self.airframe, path.lag_after(pending.shape[1]), self.wind))

    def proposal_excess(
        self,
        x: np.ndarray,
        y: np.ndarray,
        v: np.ndarray,
        phi: np.ndarray,
        proposed: np.ndarray,
        steps: int,
        err_end: EstimateError,
        scene: Scene,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lim, dt_s = scene.lim, scene.dt_s
        raw = np.asarray(proposed, dtype=np.float64)
        finite: np.ndarray = np.all(np.isfinite(raw), axis=1)
        proposed = np.clip(np.where(finite[:, None], raw, 0.0), -1.0, 1.0)
        turn = np.repeat((proposed[:, 0] * lim.turn_rate_max_rad_s)[:, None], steps, axis=1)
        accel = np.repeat((proposed[:, 1] * lim.accel_max_m_s2)[:, None], steps, axis=1)
        path = lagged_rollout(x, y, v, phi, self.lag, turn, accel, self.airframe, lim, dt_s)
        xs, ys = self._ground(path, dt_s)
        clear = point_clearance(xs, ys, scene.hz).min(axis=1) - self._half_step_m(scene)
        clear = clear - scene.margin - err_end.position_m - self.airframe.residual_m
        clear = np.where(finite, clear, -np.inf)
        end = LaggedPrediction(self.airframe, path.lag_after(steps), self.wind)
        ends = end.backup_excess(xs[:, -1], ys[:, -1], path.speeds[:, -1], path.headings[:, -1], err_end, scene)
        return proposed, np.minimum(clear, ends.max(axis=1)), choose_backup(ends)

    def backup_excess(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, err: EstimateError, scene: Scene
    ) -> np.ndarray:
        """Every backup's excess over the margin and the error bound, (M, L * N_TURNS), the monitor's candidate order;
        the braking turns' columns -inf."""
        m, lim, dt_s = len(x), scene.lim, scene.dt_s
        leads = lead_steps(scene.cfg, dt_s)
        if self.wind is None:
            clear = lagged_backup_clearance(x, y, v, phi, self.lag, scene.hz, self.airframe, lim, dt_s, leads)
        else:
            wind = self.wind
            clear = loiter_backup_clearance(x, y, v, phi, self.lag, scene.hz, self.airframe, lim, dt_s, leads, wind)
        out = np.full((m, len(leads), N_TURNS), -np.inf)
        out[:, :, :2] = clear.reshape(m, len(leads), 2)
        return out.reshape(m, len(leads) * N_TURNS) - scene.margin[:, None] - self.backup_error(err, scene)

    def held_from_steps(self, dt_s: float) -> int | None:
        """Held leads in calm air only (in wind every lead is flown open loop into the loiter's turn-in)."""
        return None if self.wind is not None else self.airframe.held_from_steps(dt_s)

    def held_course(
        self, x: np.ndarray, y: np.ndarray, v: np.ndarray, phi: np.ndarray, backup: np.ndarray, scene: Scene
    ) -> np.ndarray:
        """The model's heading where each held lead's open part ends (NaN: a lead flown open to its end)."""
        held_from = self.held_from_steps(scene.dt_s)
        out = np.full(len(x), np.nan)
        if held_from is None:
            return out
        rows = lead_steps(scene.cfg, scene.dt_s)[np.asarray(backup) // N_TURNS] > held_from
        if rows.any():
            path = straight_rollout(
                x[rows], y[rows], v[rows], phi[rows], self.lag.select(rows), held_from,
                self.airframe.select(rows), scene.lim.select(rows), scene.dt_s,
            )  # fmt: skip
            out[rows] = path.headings[:, -1] if held_from else phi[rows]
        return out

    def backup_error(self, err: EstimateError, scene: Scene) -> np.ndarray:
        """In calm air each lead K steps longer (the turn's samples), in wind the loiter's
        (:func:`~tssac_core.assurance.ground_loiter.loiter_backup_error_m`); the braking turns, not offered, 0."""
        lim, dt_s = scene.lim, scene.dt_s
        leads = lead_steps(scene.cfg, dt_s)
        if self.wind is None:
            settle, held_from = self.airframe.settle_steps(dt_s), self.airframe.held_from_steps(dt_s)
            turned_max = None if held_from is None else held_from + settle
            error = backup_error_m(err, lim, dt_s, leads + settle, turned_max)
        else:
            error = loiter_backup_error_m(err, lim, dt_s, leads, self.wind)
        per_turn = error.reshape(len(error), len(leads), N_TURNS).copy()
        per_turn[:, :, 2:] = 0.0
        return per_turn.reshape(len(error), len(leads) * N_TURNS)
