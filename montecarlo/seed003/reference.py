"""Seed 003's measuring procedure: INS readings relative to a reference the INS sets up itself.

Section 3.2 of seed 003: the INS, powered up and self-aligned, autocollimates the central and the
roll (right, 90 deg) reference mirrors "to obtain the reference axis", then the measured mirrors.
Its readings are attitudes relative to that reference frame ``R``:

* ``y_R = C_c e_y``: the INS axis (not the optical axis) at the central reference mirror;
* ``x_R = s * normalize(C_r e_y - (C_r e_y . y_R) y_R)``: the INS axis at the roll mirror, made
  orthogonal to ``y_R``; ``s = +1`` for a roll mirror on the right, ``-1`` on the left;
* ``z_R = x_R x y_R``; ``C_R^n = [x_R y_R z_R]``;
* the reading at mirror k is ``C_k^R = (C_R^n)^T C_k``, decomposed Z-X-Y like an attitude.

``C_k`` is the INS attitude autocollimated on mirror k (``C_k u = C_t^n direction(az_k, el_k)``,
:func:`montecarlo.seed003.model.autocollimate`) at the INS's own absolute roll ``phi_k``. The
relative readings do not depend on the heading of the theodolite frame, so it is zero here and
all directions are in the theodolite frame t. Because ``R`` is built from the INS axis, it
turns with the offsets (gamma, lambda) and with the rolls at the two reference pointings; to first
order (:func:`first_order_readings`) it is the small rotation ``(-lambda_c, s lambda_r, gamma_c)``
about (x, y, z), so lambda does not drop out of relative readings.

References
----------
seed 003, section 3.1 (fixture: central reference mirror, roll mirror at 90 deg on the right) and
section 3.2 (procedure); docs/reference/collimation.md ("The paper's procedure").
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.seed003.model import (
    attitude_angles,
    attitude_matrix,
    autocollimate,
    azimuth_elevation,
    direction,
    wrap,
)

FloatArray = NDArray[np.float64]

SIDES = {"right": 1.0, "left": -1.0}
"""Sign ``s`` of ``x_R`` for the roll mirror's side (the text states right; the data decide,
:mod:`montecarlo.seed003.conventions`)."""


def _t(C: FloatArray) -> FloatArray:
    return np.swapaxes(C, -1, -2)


def attitude_at(axis_az: ArrayLike, axis_el: ArrayLike, az: ArrayLike, el: ArrayLike,
                roll: ArrayLike) -> FloatArray:
    """INS attitude autocollimated on the mirror ``direction(az, el)`` at roll ``roll``.

    ``C = attitude_matrix(psi, theta, roll)`` with ``C u = direction(az, el)``,
    ``u = direction(axis_az, axis_el)``; heading relative to the theodolite zero. Shape (..., 3, 3).

    Parameters
    ----------
    axis_az, axis_el : array_like [rad]
        Offsets gamma, lambda of the optical axis (broadcast against the mirrors).
    az, el : array_like [rad]
        Mirror normal in the theodolite frame.
    roll : array_like [rad]
        The INS's absolute roll at this pointing.

    References
    ----------
    seed 003, section 2 (autocollimation fixes the optical axis, not the roll about it).
    """
    heading, pitch = autocollimate(direction(axis_az, axis_el), direction(az, el), roll)
    return attitude_matrix(heading, pitch, np.broadcast_to(roll, np.shape(heading)))


def frame_from_axes(axis_center: ArrayLike, axis_roll: ArrayLike, side: float = 1.0
                    ) -> FloatArray:
    """``C_R = [x_R y_R z_R]`` (columns) from the axis at the centre and at the roll mirror.

    ``y_R = axis_center``, ``x_R = side * normalize(axis_roll - (axis_roll . y_R) y_R)``,
    ``z_R = x_R x y_R``. Shape (..., 3, 3).

    References
    ----------
    seed 003, section 3.2 ("autocollimate the central and the right reference mirrors to obtain
    the reference axis").
    """
    y = np.asarray(axis_center, float)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    a = np.asarray(axis_roll, float)
    x = a - np.sum(a * y, axis=-1, keepdims=True) * y
    x = side * x / np.linalg.norm(x, axis=-1, keepdims=True)
    x, y = np.broadcast_arrays(x, y)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def reference_frame(C_center: ArrayLike, C_roll: ArrayLike, side: float = 1.0) -> FloatArray:
    """``C_R^n`` from the INS attitudes at the central and the roll reference mirror.

    Uses the INS axes ``C e_y`` (:func:`frame_from_axes`), not the optical axes.
    """
    return frame_from_axes(np.asarray(C_center)[..., :, 1], np.asarray(C_roll)[..., :, 1], side)


def relative_readings(axis_az: ArrayLike, axis_el: ArrayLike, az: ArrayLike, el: ArrayLike,
                      roll: ArrayLike, center: tuple[ArrayLike, ArrayLike, ArrayLike],
                      roll_mirror: tuple[ArrayLike, ArrayLike, ArrayLike], side: float = 1.0,
                      roll_is_relative: bool = False, reference_error: ArrayLike | None = None
                      ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Exact INS readings (heading, pitch, roll relative to ``R``) at the measured mirrors.

    ``C_k^R = (C_R^n)^T C_k`` decomposed Z-X-Y, with ``C_R^n`` from the attitudes at the two
    reference pointings (:func:`reference_frame`). With ``roll_is_relative`` the roll given for
    the measured mirrors is the relative roll (as read); the attitude is then solved in ``R``
    directly: ``C_k^R u = (C_R^n)^T direction(az, el)``.

    Parameters
    ----------
    axis_az, axis_el : array_like [rad]
        gamma, lambda; shaped to broadcast against the mirrors (e.g. (k, 1) for k models).
    az, el, roll : array_like, shape (..., m) [rad]
        Theodolite angles of the measured mirrors and the INS roll there (absolute, or relative
        with ``roll_is_relative``).
    center, roll_mirror : (az, el, roll) [rad]
        Theodolite angles of the central and the roll reference mirror and the INS's absolute
        roll at those pointings; shaped like ``axis_az``.
    side : +1 (roll mirror on the right, as the text states) or -1 (left).
    reference_error : array_like, shape (..., 4) [rad], optional
        Errors of the INS's heading and pitch readings at the central, then at the roll
        reference pointing, the leading shape like ``axis_az``'s. The INS builds ``R`` from the
        axes it read there, ``direction(heading + e_h, pitch + e_p)``, so these errors enter
        every relative reading of the calibration alike. None: read without error.

    Returns
    -------
    heading, pitch, roll : ndarray, shape (..., m) [rad]

    References
    ----------
    seed 003, section 3.2 (the procedure); docs/reference/collimation.md ("The paper's procedure").
    """
    C_c = attitude_at(axis_az, axis_el, *center)
    C_r = attitude_at(axis_az, axis_el, *roll_mirror)
    if reference_error is None:
        C_R = reference_frame(C_c, C_r, side)
    else:
        e = np.asarray(reference_error, float)
        read = []
        for j, C in enumerate((C_c, C_r)):
            heading, pitch = azimuth_elevation(C[..., :, 1])  # of the INS axis there
            read.append(direction(heading + e[..., 2 * j], pitch + e[..., 2 * j + 1]))
        C_R = frame_from_axes(read[0], read[1], side)
    if roll_is_relative:
        w = np.matmul(_t(C_R), direction(az, el)[..., None])[..., 0]
        heading, pitch = autocollimate(direction(axis_az, axis_el), w, roll)
        return heading, pitch, np.broadcast_to(np.asarray(roll, float), heading.shape)
    return attitude_angles(_t(C_R) @ attitude_at(axis_az, axis_el, az, el, roll))


def relative_from_absolute(ins_az: ArrayLike, ins_el: ArrayLike, ins_roll: ArrayLike,
                           center: tuple[float, float, float],
                           roll_mirror: tuple[float, float, float], side: float = 1.0
                           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Relative readings from absolute INS attitudes (heading, pitch, roll) [rad].

    ``C_R^n`` is built from the absolute readings at the reference mirrors ``center`` and
    ``roll_mirror`` (heading, pitch, roll each). The relative heading and pitch depend only on
    the absolute headings and pitches (they are the direction of the INS axis); the relative roll
    also on the rolls.

    References
    ----------
    seed 003, section 3.2.
    """
    C_R = reference_frame(attitude_matrix(*center), attitude_matrix(*roll_mirror), side)
    return attitude_angles(_t(C_R) @ attitude_matrix(ins_az, ins_el, ins_roll))


def first_order_readings(axis_az: ArrayLike, axis_el: ArrayLike, az: ArrayLike, el: ArrayLike,
                         roll: ArrayLike = 0.0, az_center: ArrayLike = 0.0,
                         roll_center: ArrayLike = 0.0, roll_roll: ArrayLike = 0.0,
                         side: float = 1.0) -> tuple[FloatArray, FloatArray]:
    """Relative heading and pitch to first order in the offsets (reference mirrors horizontal).

    With ``alpha = az - az_center`` and the offsets seen at each pointing turned by its absolute
    roll, ``gamma_j = gamma cos phi_j + lambda sin phi_j``,
    ``lambda_j = lambda cos phi_j - gamma sin phi_j`` (j = k, c, r)::

        heading ~ alpha - gamma_k / cos el + gamma_c
                  + tan el (lambda_c sin alpha - s lambda_r cos alpha)
        pitch   ~ el - lambda_k + lambda_c cos alpha + s lambda_r sin alpha

    For a level mount on the paper's layout this is: azimuth mirrors (el = 0) read
    ``heading ~ alpha`` (gamma drops out) and ``pitch ~ -lambda (1 - cos alpha - s sin alpha)``;
    pitch mirrors (alpha = 0) read ``heading ~ -gamma (1/cos el - 1) - s lambda tan el`` and
    ``pitch ~ el``. Exact in the rolls; the error is second order in gamma, lambda.

    Parameters
    ----------
    axis_az, axis_el, az, el, roll : array_like [rad]
    az_center : azimuth of the central reference mirror [rad]; the roll mirror at
        ``az_center + s 90 deg``, both at elevation 0.
    roll_center, roll_roll : absolute INS roll at the two reference pointings [rad].
    side : +1 right, -1 left.

    Returns
    -------
    heading, pitch : ndarray [rad]

    References
    ----------
    seed 003, section 3.2; derived in docs/reference/collimation.md ("First-order form").
    """
    g, lam = np.asarray(axis_az, float), np.asarray(axis_el, float)

    def turned(phi):
        phi = np.asarray(phi, float)
        return g * np.cos(phi) + lam * np.sin(phi), lam * np.cos(phi) - g * np.sin(phi)

    g_k, l_k = turned(roll)
    g_c, l_c = turned(roll_center)
    _, l_r = turned(roll_roll)
    alpha = wrap(np.asarray(az, float) - az_center)
    el = np.asarray(el, float)
    heading = (alpha - g_k / np.cos(el) + g_c
               + np.tan(el) * (l_c * np.sin(alpha) - side * l_r * np.cos(alpha)))
    pitch = el - l_k + l_c * np.cos(alpha) + side * l_r * np.sin(alpha)
    return heading, pitch


def corrected_readings(heading: ArrayLike, pitch: ArrayLike, roll: ArrayLike,
                       axis_az: float, axis_el: float, center: tuple[float, float, float],
                       roll_mirror: tuple[float, float, float], side: float = 1.0
                       ) -> tuple[FloatArray, FloatArray]:
    """Heading and pitch of the optical axis in the corrected reference frame [rad].

    The relative readings ``(heading, pitch, roll)`` at a mirror and at the two reference mirrors
    (``center``, ``roll_mirror``) give the INS attitudes in ``R``; turned by the offsets, the
    optical axis ``C^R u`` at the mirror is expressed in the frame :func:`frame_from_axes` builds
    from the optical axes at the two reference mirrors: the reference the procedure would have
    set up had the INS read its optical axis. Error-free, this is the mirror normal relative to
    the central and the roll mirror (:func:`theodolite_relative`).

    References
    ----------
    seed 003, section 2 ("the INS axis converted into an axis system coaxial with the
    autocollimator's optical axis") and section 3.2 (Table 1's corrected INS values).
    """
    u = direction(axis_az, axis_el)
    optical = [attitude_matrix(*att) @ u for att in (center, roll_mirror)]
    frame = frame_from_axes(optical[0], optical[1], side)
    axis = np.matmul(attitude_matrix(heading, pitch, roll), u)
    return azimuth_elevation(np.matmul(axis, frame))


def theodolite_relative(az: ArrayLike, el: ArrayLike, center: tuple[float, float],
                        roll_mirror: tuple[float, float], side: float = 1.0
                        ) -> tuple[FloatArray, FloatArray]:
    """Mirror normals relative to the frame of the central and the roll mirror's normals [rad].

    What a perfect INS with a perfect optical axis would read at each mirror
    (:func:`frame_from_axes` of the reference normals).
    """
    frame = frame_from_axes(direction(*center), direction(*roll_mirror), side)
    return azimuth_elevation(np.matmul(direction(az, el), frame))


def roll_mirror_azimuth(az_center: ArrayLike, side: float = 1.0) -> FloatArray:
    """Nominal roll-mirror azimuth ``az_center + s 90 deg`` [rad] (seed 003, section 3.1)."""
    return np.asarray(az_center, float) + side * math.pi / 2
