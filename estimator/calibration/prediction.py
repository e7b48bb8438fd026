"""Predict the forces of a (new) bucket path with calibrated soil parameters."""

from __future__ import annotations

import csv
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..checks import check_choice
from ..cyclelog import CycleLog
from ..errors import ParameterError
from ..force_model import DEFAULT_OPTIONS, ModelOptions, SoilForces, soil_forces
from ..force_models import DEFAULT_FORCE_MODEL, check_force_model, model_options_for
from ..kinematics import DEFAULT_SLOPE_WINDOW, ContactState, contact_state
from ..machine import Bucket
from ..paths import BucketPath
from ..payload import PayloadOptions, with_payload
from ..pile import Pile
from ..soil import SoilParams
from .bands import BandModel, PredictionBand, prediction_band
from .result import Calibration, FitQuality, load_params


@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted forces along a path.

    Attributes
    ----------
    path : BucketPath
        The path.
    forces : SoilForces
        Model output per sample (F_T, F_N, F_R, flags, ...).
    state : ContactState
        Contact geometry (depth to the given surface, rho, alpha, ...).
    soil : SoilParams
        Parameters used.
    observed_tangential, observed_normal : numpy.ndarray or None
        Measured forces when a cycle log was given.
    quality : FitQuality or None
        RMSE against the measured forces (in-soil samples), when available.
    band : PredictionBand or None
        Prediction band (``predict(..., band=level)``), else None.
    outside_training : numpy.ndarray or None
        ``force_model="fee-learned"`` only: True where a sample's inputs leave the learned correction's training
        range (:mod:`~wheelloader.estimator.learned`; there the correction is held at the range's edge).
    """

    path: BucketPath
    forces: SoilForces
    state: ContactState = field(repr=False)
    soil: SoilParams
    observed_tangential: np.ndarray | None = field(default=None, repr=False)
    observed_normal: np.ndarray | None = field(default=None, repr=False)
    quality: FitQuality | None = None
    band: PredictionBand | None = None
    outside_training: np.ndarray | None = field(default=None, repr=False)

    @property
    def tangential(self) -> np.ndarray:
        """Predicted F_T [N]."""
        return self.forces.tangential

    @property
    def normal(self) -> np.ndarray:
        """Predicted F_N [N]."""
        return self.forces.normal

    @property
    def resultant(self) -> np.ndarray:
        """Predicted F_R [N]."""
        return self.forces.resultant

    def save_csv(self, csv_path: str | Path, overwrite: bool = False) -> Path:
        """Write ``t, x, z, blade_angle, depth, F_T, F_N, F_R, flags`` (+ observed columns when present)."""
        csv_path = Path(csv_path)
        if csv_path.exists() and not overwrite:
            raise FileExistsError(f"{csv_path} exists; pass overwrite=True to replace it")
        cols = {"t": self.path.t, "x": self.path.x, "z": self.path.z, "blade_angle": self.path.blade_angle,
                "depth": self.state.depth, "F_T": self.tangential, "F_N": self.normal, "F_R": self.resultant}
        if self.band is not None:
            cols["F_R_lower"], cols["F_R_upper"] = self.band.lower_r, self.band.upper_r
        if self.observed_tangential is not None:
            cols["F_T_obs"] = self.observed_tangential
            cols["F_N_obs"] = self.observed_normal
        names = list(cols)
        with open(csv_path, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow([*names, "flags"])
            for i in range(len(self.path)):
                writer.writerow([repr(float(cols[k][i])) for k in names] + [int(self.forces.flags[i])])
        return csv_path


def predict(
    params: SoilParams | Calibration | dict | str | Path,
    path_or_cycle: BucketPath | CycleLog,
    pile: Pile | None = None,
    bucket: Bucket | None = None,
    *,
    options: ModelOptions | None = None,
    slope_window: float = DEFAULT_SLOPE_WINDOW,
    initial_fill: float = 0.0,
    fill: str | None = None,
    band: float | None = None,
    band_model: BandModel | None = None,
    force_model: str | None = None,
    payload: PayloadOptions | None = None,
) -> Prediction:
    """Forces of the calibrated model along a path.

    Parameters
    ----------
    params : SoilParams, Calibration, dict, str or Path
        Soil parameters (a params.json path, a ``{"soil": ...}`` or bare dict,
        or a preset name are accepted).
    path_or_cycle : BucketPath or CycleLog
        A new path, or a logged cycle (its pile, bucket and logged fill/load
        are used unless ``pile``/``bucket`` are given; the measured forces
        give :attr:`Prediction.quality`).
    pile : Pile, optional
        Surface the path starts from; depth is measured to it (a carved
        surface from a previous cycle gives the paper's dual-cycle
        correction). Default: the cycle's pile, else ``Pile.trapezoid()``.
    bucket : Bucket, optional
        Default: the cycle's bucket, else ``Bucket()``.
    options : ModelOptions, optional
        Force-model options; default: those the calibration fitted when ``params`` is a
        :class:`Calibration` (:attr:`Calibration.model_options`), else the paper's model.
    slope_window : float
        Half-width of the local slope chord [m].
    initial_fill : float
        Soil already in the bucket [m^3] (new paths only).
    fill : str, optional
        For a cycle log: ``"log"`` uses its logged fill or load (what the paper's experiments
        do), ``"model"`` the model's own bookkeeping (carving the pile along the path), which is
        what a prediction of a path not yet dug has. Default: the calibration's
        (:attr:`Calibration.fill_source`), else ``"log"``.
    band : float, optional
        Level of a prediction band (e.g. 0.9): mean +- the spread from the calibration's
        parameter covariance and residual noise model (:mod:`~.bands`); needs ``params`` to be
        a :class:`Calibration` (or ``band_model``).
    band_model : BandModel, optional
        The band's inputs when ``params`` is not a :class:`Calibration` (e.g. read from a
        params.json: ``BandModel.from_dict(data["calibration"]["settings"]["band_model"])``).

    force_model : str, optional
        :data:`~wheelloader.estimator.force_models.FORCE_MODELS`; default: the calibration's
        (:attr:`Calibration.force_model`), else ``"fee"``. With ``"fee-payload"`` the fill follows the carving
        (``fill`` is not used) and the payload model's kept soil is carried once the tip leaves the soil.
    payload : PayloadOptions, optional
        The payload's parameters for ``"fee-payload"``; default: the calibration's, else
        :data:`~wheelloader.estimator.force_models.DEFAULT_PAYLOAD`.

    Returns
    -------
    Prediction
    """
    soil = load_params(params)
    force_model, payload, options, fill = _model_of(params, force_model, payload, options, fill)
    path, pile, bucket, fill_volume, load, observed_t, observed_n = _path_inputs(path_or_cycle, pile, bucket, fill)
    acceleration = None
    if options.carried_load:
        acceleration = np.column_stack(path.acceleration())
    velocity = np.column_stack(path.velocity()[:2]) if options.slip_friction else None
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket, slope_window=slope_window,
                          initial_fill=initial_fill, fill_volume=fill_volume, measured_load=load,
                          acceleration=acceleration, velocity=velocity)
    if payload is not None:
        state = with_payload(state, bucket.capacity, payload, initial_fill, blade_angle=path.blade_angle)
    forces = soil_forces(soil, state, bucket, options)
    outside = None
    if force_model == "fee-learned":
        from ..learned import default_learned_model, learned_forces

        lf = learned_forces(default_learned_model(), state, path, bucket, soil)
        f_t, f_n = forces.tangential + lf.tangential, forces.normal + lf.normal
        forces = dataclasses.replace(forces, tangential=f_t, normal=f_n, resultant=np.hypot(f_t, f_n))
        outside = lf.outside
    pband = None
    if band is not None:
        if band_model is None:
            if not isinstance(params, Calibration):
                raise ParameterError("a prediction band needs a Calibration (its covariance and residual noise "
                                     "model) or band_model")
            band_model = params.band_model
        pband = prediction_band(band_model, soil, state, bucket, options, forces.tangential, forces.normal, band)
    quality = None
    if observed_t is not None:
        mask = state.depth > 0.0
        if np.any(mask):
            quality = FitQuality.from_forces(observed_t[mask], observed_n[mask], forces.tangential[mask],
                                             forces.normal[mask])
    return Prediction(path, forces, state, soil, observed_t, observed_n, quality, pband, outside)


def _model_of(params, force_model, payload, options, fill):
    """``(force_model, payload, options, fill)`` of :func:`predict`: the given ones, else the calibration's."""
    if force_model is None:
        force_model = params.force_model if isinstance(params, Calibration) else DEFAULT_FORCE_MODEL
    if payload is None and isinstance(params, Calibration) and force_model == params.force_model:
        payload = params.payload
    payload = check_force_model(force_model, payload)
    if options is None:
        options = params.model_options if isinstance(params, Calibration) else DEFAULT_OPTIONS
    options = model_options_for(force_model, options)
    if fill is None:
        fill = params.fill_source if isinstance(params, Calibration) else "log"
    check_choice("fill", fill, ("log", "model"))
    if payload is not None:
        fill = "model"  # the payload's kept soil follows from the carving
    return force_model, payload, options, fill


def _path_inputs(path_or_cycle, pile, bucket, fill):
    """``(path, pile, bucket, fill_volume, load, observed_t, observed_n)`` of :func:`predict`."""
    observed_t = observed_n = None
    if isinstance(path_or_cycle, CycleLog):
        cycle = path_or_cycle
        path = cycle.path
        same_surface = pile is None
        pile = cycle.pile if pile is None else pile
        bucket = cycle.bucket if bucket is None else bucket
        logged = same_surface and fill == "log"
        fill_volume = cycle.fill_volume if logged else None
        load = cycle.measured_load if fill == "log" else None
        observed_t, observed_n = cycle.tangential, cycle.normal
    elif isinstance(path_or_cycle, BucketPath):
        path = path_or_cycle
        pile = Pile.trapezoid() if pile is None else pile
        bucket = Bucket() if bucket is None else bucket
        fill_volume = load = None
    else:
        raise ParameterError(f"path_or_cycle must be a BucketPath or a CycleLog, got {type(path_or_cycle).__name__}")
    if not isinstance(pile, Pile):
        raise ParameterError(f"pile must be a Pile, got {type(pile).__name__}")
    if not isinstance(bucket, Bucket):
        raise ParameterError(f"bucket must be a Bucket, got {type(bucket).__name__}")
    return path, pile, bucket, fill_volume, load, observed_t, observed_n
