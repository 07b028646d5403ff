"""``auto`` for the noise options of ``diagnose``: the noise estimated from the data.

Each system's diagnosis under ``auto`` (:func:`montecarlo.discrepancy.noise_estimation.
diagnose_estimated`): the tests of an estimated noise (F, Pope's tau), the estimate and its
interval from the final model; ground's two noise values, when both are ``auto``, by variance
components.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from montecarlo.cli.common import nonnegative, positive
from montecarlo.units import ARCSEC

if TYPE_CHECKING:
    from montecarlo.discrepancy.engine import Diagnosis
    from montecarlo.discrepancy.noise_estimation import NoiseEstimate
    from montecarlo.discrepancy.problem import Problem
    from montecarlo.geometry.camera import Camera
    from montecarlo.io.ground_csv import GroundData
    from montecarlo.lsq import LeastSquaresFit

AUTO = "auto"


def positive_or_auto(text: str) -> float | str:
    """A positive number, or ``auto`` (estimate it from the data)."""
    return AUTO if text.strip().lower() == AUTO else positive(text)


def nonnegative_or_auto(text: str) -> float | str:
    """A number >= 0, or ``auto`` (estimate it from the data)."""
    return AUTO if text.strip().lower() == AUTO else nonnegative(text)


AUTO_HELP = ("; or 'auto': estimated from the data (the final model's; the tests then F and "
             "Pope's tau)")


def report_entry(used: Mapping[str, float], estimates: list[NoiseEstimate]) -> dict[str, Any]:
    """The diagnosis JSON's ``noise_estimate``: the estimates and the values the tests used."""
    return {"estimates": [e.to_json() for e in estimates], "used": dict(used),
            "tests": "F (effects; global: against every effect at once), Pope's tau "
                     "(observations)"}


def _scale(option: str) -> Callable[[Mapping[str, float], LeastSquaresFit],
                                    list[NoiseEstimate]]:
    from montecarlo.discrepancy.noise_estimation import scale_estimate

    return lambda used, fit: [scale_estimate(option, used[option], fit)]


def diagnose_scaled(build: Callable[[float], Problem], option: str, alpha: float,
                    start: float = 1.0,
                    initial: Callable[[Problem], LeastSquaresFit] | None = None
                    ) -> tuple[Diagnosis, dict[str, float], list[NoiseEstimate]]:
    """A system whose one noise value scales every whitened residual (camera, collimation,
    stabilisation without gyro walk): ``build(sigma)`` in the option's unit."""
    from montecarlo.discrepancy.noise_estimation import diagnose_estimated

    return diagnose_estimated(lambda s: build(s[option]), {option: start}, _scale(option),
                              alpha, initial)


def diagnose_collimation_auto(build: Callable[[float], Problem], alpha: float
                              ) -> tuple[Diagnosis, dict[str, float], list[NoiseEstimate]]:
    """``--angle-sigma-arcsec auto``: ``build(sigma [rad])``."""
    return diagnose_scaled(lambda s: build(s * ARCSEC), "angle_sigma_arcsec", alpha)


def diagnose_stabilization_auto(build: Callable[[float], Problem], gyro_noise: float,
                                start: float, alpha: float
                                ) -> tuple[Diagnosis, dict[str, float], list[NoiseEstimate]]:
    """``--image-noise-px auto``: a pure scale without gyro walk, else the chi-square pivot
    with the walk known."""
    from montecarlo.discrepancy.noise_estimation import diagnose_estimated, pivot_component

    option = "image_noise_px"
    if gyro_noise == 0.0:
        return diagnose_scaled(build, option, alpha, start)

    def problem(s: Mapping[str, float]) -> Problem:
        return build(s[option])

    return diagnose_estimated(problem, {option: start}, lambda used, fit: [
        pivot_component(option, problem, used, fit)], alpha)


def diagnose_ground_auto(data: GroundData, camera: Camera, pixel: float | str,
                         survey: float | str, refraction: float, alpha: float
                         ) -> tuple[Diagnosis, dict[str, float], list[NoiseEstimate]]:
    """``--pixel-sigma-px`` and/or ``--survey-sigma-m auto``: one unknown by the chi-square
    pivot, both by REML variance components."""
    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.discrepancy.noise_estimation import (
        diagnose_estimated,
        pivot_component,
        reml_components,
    )

    options = ["pixel_sigma_px", "survey_sigma_m"]
    free = [pixel == AUTO, survey == AUTO]
    start = {"pixel_sigma_px": 1.0 if pixel == AUTO else float(pixel),
             "survey_sigma_m": 0.01 if survey == AUTO else float(survey)}

    def build(s: Mapping[str, float]) -> Problem:
        return ge.ground_problem(data, camera, s["pixel_sigma_px"], s["survey_sigma_m"],
                                 refraction)

    def estimate(used: Mapping[str, float], fit: LeastSquaresFit) -> list[NoiseEstimate]:
        if all(free):
            Q = ge.whitened_noise_components(data, camera, used["pixel_sigma_px"],
                                             used["survey_sigma_m"], refraction)
            return reml_components(options, Q, used, free, fit)
        option = options[free.index(True)]
        return [pivot_component(option, build, used, fit)]

    return diagnose_estimated(build, start, estimate, alpha)


def diagnose_collimation(build: Callable[[float], Problem], angle_sigma: float | str,
                         alpha: float) -> tuple[Diagnosis, float, dict[str, Any]]:
    """``diagnose collimation`` at ``--angle-sigma-arcsec`` S or ``auto``: the diagnosis,
    the sigma [rad] its tests used and the report's noise keys; ``build(sigma [rad])``."""
    from montecarlo.discrepancy.engine import diagnose

    if angle_sigma == AUTO:
        d, used, found = diagnose_collimation_auto(build, alpha)
        return d, used["angle_sigma_arcsec"] * ARCSEC, {
            "noise_estimate": report_entry(used, found)}
    sigma = float(angle_sigma) * ARCSEC
    return diagnose(build(sigma), alpha), sigma, {
        "stated_noise": {"angle sigma arcsec": angle_sigma}}


def diagnose_ground(data: GroundData, camera: Camera, pixel: float | str,
                    survey: float | str, refraction: float, alpha: float
                    ) -> tuple[Diagnosis, float, float, dict[str, Any]]:
    """``diagnose ground`` with stated or ``auto`` noise: the diagnosis, the pixel [px] and
    survey [m] sigma its tests used, and the report's noise keys (with both stated and a
    survey sigma above 0, each checked against the final model's REML components)."""
    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.discrepancy.engine import diagnose
    from montecarlo.discrepancy.noise_estimation import check_components

    if AUTO in (pixel, survey):
        d, used, found = diagnose_ground_auto(data, camera, pixel, survey, refraction, alpha)
        return d, used["pixel_sigma_px"], used["survey_sigma_m"], {
            "noise_estimate": report_entry(used, found)}
    px, m = float(pixel), float(survey)
    d = diagnose(ge.ground_problem(data, camera, px, m, refraction), alpha)
    extra: dict[str, Any] = {"stated_noise": {"pixel sigma px": px, "survey sigma m": m}}
    if m > 0:
        stated = {"pixel_sigma_px": px, "survey_sigma_m": m}
        extra["noise_components"] = check_components(
            list(stated), ge.whitened_noise_components(data, camera, px, m, refraction),
            stated, d.after)
    return d, px, m, extra
