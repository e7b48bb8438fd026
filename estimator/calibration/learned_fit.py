"""Calibration of ``force_model="fee-learned"`` (:mod:`wheelloader.estimator.learned`): a fixed point of FEE fits."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

from ..cyclelog import CycleLog
from ..force_models import LEARNED_BASE
from ..learned import CALIBRATION_PASSES, corrected_log, default_learned_model
from .options import CalibrationOptions
from .result import Calibration, FitQuality
from .verdict import FitWarning

__all__ = ["calibrate_learned"]


def calibrate_learned(logs: list[CycleLog], opts: CalibrationOptions, calibrate: Callable[..., Calibration]
                      ) -> Calibration:
    """``force_model="fee-learned"``: a plain fit of its base
    :data:`~wheelloader.estimator.force_models.LEARNED_BASE` (the soil the correction was trained at: the soil a
    one-cycle calibration of the base finds, :mod:`wheelloader.estimator.learned`), then
    :data:`~wheelloader.estimator.learned.CALIBRATION_PASSES` fits of the base to the forces minus the correction
    at the current soil (a fixed point; 1 for the shipped weights). The result's forces, quality and settings are
    the whole model's; its band is the base's, shifted by the correction. ``calibrate`` is
    :func:`~.api.calibrate` (passed in: this module is imported by it)."""
    model = default_learned_model()
    base = dataclasses.replace(opts, force_model=LEARNED_BASE)
    t0 = time.perf_counter()
    cal = calibrate(logs if len(logs) > 1 else logs[0], options=base)
    nfev = cal.nfev
    for _ in range(CALIBRATION_PASSES):
        corrected = [corrected_log(model, log, cal.params, opts.payload, opts.slope_window)[0] for log in logs]
        cal = calibrate(corrected if len(corrected) > 1 else corrected[0], options=base)
        nfev += cal.nfev
    parts = [corrected_log(model, log, cal.params, opts.payload, opts.slope_window)[1] for log in logs]
    pred_t = cal.predicted_tangential + np.concatenate([p.tangential for p in parts])
    pred_n = cal.predicted_normal + np.concatenate([p.normal for p in parts])
    outside = np.concatenate([p.outside for p in parts])
    obs_t = np.concatenate([log.tangential for log in logs])
    obs_n = np.concatenate([log.normal for log in logs])
    mask = cal.in_soil
    quality = FitQuality.from_forces(obs_t[mask], obs_n[mask], pred_t[mask], pred_n[mask])
    settings = dict(cal.settings, force_model="fee-learned",
                    learned={"version": model.version, "passes": CALIBRATION_PASSES,
                             "outside_training_share": float(np.mean(outside[mask])) if np.any(mask) else 0.0})
    warns = list(cal.warnings)
    if np.any(outside[mask]):
        warns.append(FitWarning("outside_training", f"{int(np.count_nonzero(outside[mask]))} of "
                                f"{int(np.count_nonzero(mask))} in-soil samples leave the learned correction's "
                                "training range (its inputs are clipped there)"))
    return dataclasses.replace(cal, quality=quality, predicted_tangential=pred_t, predicted_normal=pred_n,
                               settings=settings, warnings=warns, nfev=nfev, time_s=time.perf_counter() - t0)
