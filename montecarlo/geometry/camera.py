"""Ideal pinhole camera of seed 000, section 1.1: pixels <-> equivalent angles <-> directions.

Frame ``a`` (the product frame) has y along the optical axis and x, z parallel to the focal plane. A
pixel coordinate is measured from the image centre: ``f_mx`` along x (positive to the right),
``f_mz`` along z (positive up). The text calls the pixel count that scales x ``f_x`` and the one
that scales z ``f_z`` but labels them the other way round (docs/reference/conventions.md); here
``n_x`` is the pixel count across x (the yaw field of view) and ``n_z`` across z (the pitch field of
view).

Two equivalent forms are provided:

* the paper's trigonometric form, through the equivalent yaw/pitch angles of eqs. (3)-(4);
* the direct vector form: the pixel coordinates are the tangent-plane coordinates of the target
  direction ``u`` in frame a, ``f_mx = k_x u_x / u_y`` and ``f_mz = k_z u_z / u_y`` with
  ``k = n / (2 tan(fov / 2))`` pixels per unit tangent (eqs. (1)-(2) combined).

All functions broadcast over leading axes; vectors have their components on the last axis.

References
----------
seed 000: Ding Tao, "Aiming line calibration technique of strapdown photoelectric equipment",
2014, eqs. (1)-(4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Camera:
    """Field of view and detector size of an ideal pinhole sensor.

    Parameters
    ----------
    fov_yaw : float or array_like [rad]
        Full field of view about z (across the image x axis), in (0, pi).
    fov_pitch : float or array_like [rad]
        Full field of view about x (across the image z axis), in (0, pi).
    n_x, n_z : float or array_like [px]
        Pixel counts across x and across z.

    Arrays describe one camera per trial and broadcast against the trial axes. Values are
    stored as floats (or float arrays) whatever numbers they were given as.
    """

    fov_yaw: float | FloatArray
    fov_pitch: float | FloatArray
    n_x: float | FloatArray
    n_z: float | FloatArray

    def __post_init__(self) -> None:
        for name in ("fov_yaw", "fov_pitch", "n_x", "n_z"):
            value = np.asarray(getattr(self, name), float)
            object.__setattr__(self, name, float(value) if value.ndim == 0 else value)
        for name in ("fov_yaw", "fov_pitch"):
            value = np.asarray(getattr(self, name), float)
            if not np.all((value > 0.0) & (value < np.pi)):
                raise ValueError(f"{name} must lie in (0, pi) rad, got {value!r}")
        for name in ("n_x", "n_z"):
            value = np.asarray(getattr(self, name), float)
            if not np.all(np.isfinite(value) & (value > 0)):
                raise ValueError(f"{name} must be a positive pixel count, got {value!r}")

    @classmethod
    def from_degrees(
        cls, fov_yaw_deg: ArrayLike, fov_pitch_deg: ArrayLike, n_x: ArrayLike, n_z: ArrayLike
    ) -> Camera:
        """Build a camera from fields of view in degrees (the units of data sheets)."""
        return cls(np.radians(fov_yaw_deg), np.radians(fov_pitch_deg), np.asarray(n_x, float),
                   np.asarray(n_z, float))

    @property
    def k_x(self) -> FloatArray:
        """Pixels per unit tangent along x: ``n_x / (2 tan(fov_yaw / 2))`` [px]."""
        return self.n_x / (2.0 * np.tan(self.fov_yaw / 2.0))

    @property
    def k_z(self) -> FloatArray:
        """Pixels per unit tangent along z: ``n_z / (2 tan(fov_pitch / 2))`` [px]."""
        return self.n_z / (2.0 * np.tan(self.fov_pitch / 2.0))


def focal_plane_point(
    f_mx: ArrayLike, f_mz: ArrayLike, camera: Camera, L: float = 1.0
) -> FloatArray:
    """Point N of the focal plane at distance ``L`` that images at pixel (f_mx, f_mz).

    Parameters
    ----------
    f_mx, f_mz : array_like [px]
        Pixel coordinates from the image centre.
    camera : Camera
    L : float [m]
        Distance of the focal plane from the focus (any positive scale).

    Returns
    -------
    ndarray, shape (..., 3) [m]
        ``[x_N, y_N, z_N]`` in frame a.

    References
    ----------
    seed 000, eq. (1).
    """
    f_mx, f_mz = np.broadcast_arrays(np.asarray(f_mx, float), np.asarray(f_mz, float))
    x_n = 2.0 * L * f_mx / camera.n_x * np.tan(camera.fov_yaw / 2.0)  # seed 000, eq. (1)
    z_n = 2.0 * L * f_mz / camera.n_z * np.tan(camera.fov_pitch / 2.0)  # seed 000, eq. (1)
    return np.stack([x_n, np.full_like(x_n, L), z_n], axis=-1)


def direction_from_equivalent_angles(psi_m: ArrayLike, theta_m: ArrayLike) -> FloatArray:
    """Unit direction in frame a of the ray with equivalent yaw ``psi_m`` and pitch ``theta_m``.

    Frame a rotated first by ``psi_m`` about z and then by ``theta_m`` about x carries its y axis
    onto the ray: ``R_M'^a = [-sin psi_m cos theta_m, cos psi_m cos theta_m, sin theta_m]``, which
    is also the second row of the matrix of eq. (7).

    Returns
    -------
    ndarray, shape (..., 3)

    References
    ----------
    seed 000, section 1.1 (the vector R_M'^a before eq. (2)) and eq. (8).
    """
    psi_m, theta_m = np.broadcast_arrays(np.asarray(psi_m, float), np.asarray(theta_m, float))
    cos_t = np.cos(theta_m)
    return np.stack([-np.sin(psi_m) * cos_t, np.cos(psi_m) * cos_t, np.sin(theta_m)], axis=-1)


def equivalent_angles_from_pixels(
    f_mx: ArrayLike, f_mz: ArrayLike, camera: Camera
) -> tuple[FloatArray, FloatArray]:
    """Equivalent measurement angles of a pixel, paper's trigonometric form.

    Parameters
    ----------
    f_mx, f_mz : array_like [px]
    camera : Camera

    Returns
    -------
    psi_m, theta_m : ndarray [rad]
        Equivalent yaw (about z) and pitch (about x), both in (-pi/2, pi/2).

    References
    ----------
    seed 000, eq. (3).

    Examples
    --------
    The trigonometric route of eqs. (3)-(4) gives the same direction as the vector form:

    >>> import numpy as np
    >>> cam = Camera.from_degrees(90.0, 90.0, 512, 512)
    >>> angles = equivalent_angles_from_pixels(128.0, 64.0, cam)
    >>> bool(np.allclose(direction_from_equivalent_angles(*angles),
    ...                  direction_from_pixels(128.0, 64.0, cam), atol=1e-15))
    True
    """
    tx = 2.0 * np.asarray(f_mx, float) / camera.n_x * np.tan(camera.fov_yaw / 2.0)
    tz = 2.0 * np.asarray(f_mz, float) / camera.n_z * np.tan(camera.fov_pitch / 2.0)
    psi_m = np.arctan(-tx)  # seed 000, eq. (3)
    theta_m = np.arctan(tz / np.sqrt(tx**2 + 1.0))  # seed 000, eq. (3)
    return psi_m, theta_m


def pixels_from_equivalent_angles(
    psi_m: ArrayLike, theta_m: ArrayLike, camera: Camera
) -> tuple[FloatArray, FloatArray]:
    """Pixel coordinates of the ray with equivalent angles (psi_m, theta_m).

    Parameters
    ----------
    psi_m, theta_m : array_like [rad]
    camera : Camera

    Returns
    -------
    f_mx, f_mz : ndarray [px]

    References
    ----------
    seed 000, eq. (4) (and the pixel equations after eq. (16)).
    """
    psi_m = np.asarray(psi_m, float)
    theta_m = np.asarray(theta_m, float)
    f_mx = -camera.n_x * np.tan(psi_m) / (2.0 * np.tan(camera.fov_yaw / 2.0))  # eq. (4)
    f_mz = (
        camera.n_z * np.tan(theta_m) / (2.0 * np.cos(psi_m) * np.tan(camera.fov_pitch / 2.0))
    )  # seed 000, eq. (4)
    return f_mx, f_mz


def small_angle_equivalent_angles(
    f_mx: ArrayLike, f_mz: ArrayLike, camera: Camera
) -> tuple[FloatArray, FloatArray]:
    """Engineering approximation of eq. (3) for a small field of view and small ``f_mx``.

    Returns
    -------
    psi_m, theta_m : ndarray [rad]
        ``-f_mx / n_x * fov_yaw`` and ``f_mz / n_z * fov_pitch``.

    References
    ----------
    seed 000, the unnumbered approximation after eq. (3).
    """
    psi_m = -np.asarray(f_mx, float) / camera.n_x * camera.fov_yaw
    theta_m = np.asarray(f_mz, float) / camera.n_z * camera.fov_pitch
    return psi_m, theta_m


def pixels_from_direction(u: ArrayLike, camera: Camera) -> tuple[FloatArray, FloatArray]:
    """Pixel coordinates of a direction in frame a, direct vector form (no trigonometry).

    ``f_mx = k_x u_x / u_y`` and ``f_mz = k_z u_z / u_y``; ``u`` need not be a unit vector.
    Directions with ``u_y <= 0`` (behind the sensor) give meaningless numbers: check them with
    :func:`in_front` first.

    Parameters
    ----------
    u : array_like, shape (..., 3)
    camera : Camera

    Returns
    -------
    f_mx, f_mz : ndarray, shape (...) [px]

    References
    ----------
    seed 000, eqs. (1)-(2) combined; equal to eq. (4) applied to the angles of eq. (10).

    Examples
    --------
    Seed 000's camera (90 x 90 deg, 512 x 512 px) has 256 px per unit tangent, so a direction
    45 deg to the right lies on the detector's right edge:

    >>> import numpy as np
    >>> cam = Camera.from_degrees(90.0, 90.0, 512, 512)
    >>> np.round(pixels_from_direction([1.0, 1.0, 0.0], cam), 9)
    array([256.,   0.])
    """
    u = np.asarray(u, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return camera.k_x * u[..., 0] / u[..., 1], camera.k_z * u[..., 2] / u[..., 1]


def direction_from_pixels(f_mx: ArrayLike, f_mz: ArrayLike, camera: Camera) -> FloatArray:
    """Unit direction in frame a imaged at pixel (f_mx, f_mz), direct vector form.

    Returns
    -------
    ndarray, shape (..., 3)
        ``[f_mx / k_x, 1, f_mz / k_z]`` normalised; equal to
        ``direction_from_equivalent_angles(*equivalent_angles_from_pixels(...))``.

    References
    ----------
    seed 000, eqs. (1)-(3) combined.

    Examples
    --------
    The round trip with :func:`pixels_from_direction`:

    >>> import numpy as np
    >>> cam = Camera.from_degrees(60.0, 40.0, 640, 480)
    >>> u = direction_from_pixels(100.0, -50.0, cam)
    >>> np.round(pixels_from_direction(u, cam), 9)
    array([100., -50.])
    """
    f_mx, f_mz = np.broadcast_arrays(np.asarray(f_mx, float), np.asarray(f_mz, float))
    v = np.stack([f_mx / camera.k_x, np.ones_like(f_mx), f_mz / camera.k_z], axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def in_front(u: ArrayLike) -> NDArray[np.bool_]:
    """True where the direction ``u`` (shape (..., 3), frame a) points in front of the sensor."""
    return np.asarray(u, float)[..., 1] > 0.0


def in_field_of_view(f_mx: ArrayLike, f_mz: ArrayLike, camera: Camera) -> NDArray[np.bool_]:
    """True where the pixel (f_mx, f_mz) [px] lies on the detector (edges included)."""
    return (np.abs(f_mx) <= camera.n_x / 2.0) & (np.abs(f_mz) <= camera.n_z / 2.0)
