"""Cameras: pinhole (``look_at``) and orthographic, in a right-handed, +Y-up world.

Camera space follows OpenGL: the camera looks along its ``forward`` axis (camera-space -Z), ``right``
is +X and ``up`` is +Y. Pixel ``(row i, column j)`` of an ``(H, W)`` image has its centre at
normalised device coordinates ``x = 2 (j + 0.5) / W - 1`` (left to right) and
``y = 1 - 2 (i + 0.5) / H`` (top to bottom), so row 0 is the top of the image.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from warptex._validate import as_float


@dataclass(frozen=True)
class Camera:
    """A camera: position, orthonormal frame, projection and image size.

    Attributes:
        eye: camera position, world space, ``(3,)`` float64.
        forward, right, up: orthonormal view frame (``right = forward × up``), ``(3,)`` each.
        resolution: ``(height, width)`` in pixels.
        fov_y: vertical field of view in degrees (pinhole); ``None`` for orthographic.
        ortho_height: world-space height of the view (orthographic); ``None`` for pinhole.
        strata: samples per pixel side of a supersampled camera (:meth:`supersampled`): each
            ``strata × strata`` block of ``resolution`` is one image pixel, 1 for none.
    """

    eye: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    resolution: tuple[int, int]
    fov_y: float | None = None
    ortho_height: float | None = None
    strata: int = 1

    @property
    def orthographic(self) -> bool:
        return self.ortho_height is not None

    @property
    def half_extent(self) -> tuple[float, float]:
        """Half width and half height of the image plane at distance 1 (pinhole) or in world units."""
        h, w = self.resolution
        half_h = self.ortho_height / 2 if self.orthographic else math.tan(math.radians(self.fov_y) / 2)
        return half_h * w / h, half_h

    @property
    def pixel_resolution(self) -> tuple[int, int]:
        """``(height, width)`` of the image: ``resolution`` over ``strata``."""
        return self.resolution[0] // self.strata, self.resolution[1] // self.strata

    def supersampled(self, samples: int) -> "Camera":
        """This camera taking ``samples`` (1, 4, 9, 16, ...: ``s²``) stratified samples per pixel:
        a camera of ``s``-times the resolution whose ``s × s`` blocks are this camera's pixels.

        The pixel is cut into ``s × s`` strata, one sample in each, placed so that no two samples of
        a pixel share a column or a row of the ``s² × s²`` sub-grid (an n-rooks pattern; for 4
        samples the rotated grid of 4× MSAA): near-horizontal and near-vertical edges get ``s² + 1``
        coverage levels, not ``s + 1``. Sample ``(a, b)`` (column, row stratum) sits at
        ``x = (a + (s - 1 - b + 0.5) / s) / s``, ``y = (b + (a + 0.5) / s) / s`` of the pixel
        (``y`` downward); every pixel has the same pattern, so the image has no noise.
        """
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1 or math.isqrt(int(samples)) ** 2 != samples:
            raise ValueError(f"Camera.supersampled(): samples must be a square number of samples per pixel (1, 4, 9, 16, ...), got {samples!r}")
        if self.strata != 1:
            raise ValueError(f"Camera.supersampled(): the camera is supersampled already ({self.strata ** 2} samples per pixel)")
        s = math.isqrt(int(samples))
        return dataclasses.replace(self, resolution=(self.resolution[0] * s, self.resolution[1] * s), strata=s)

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Primary rays through every pixel centre (every sample of a supersampled camera):
        origins and unnormalised directions, ``[H, W, 3]``.

        A pinhole ray's direction is ``forward + x·right·hx + y·up·hy`` (unit length along
        ``forward``), so the hit distance along it is the view-space depth.
        """
        h, w = self.resolution
        hx, hy = self.half_extent
        s = self.strata
        rows, cols = np.arange(h)[:, None], np.arange(w)[None, :]
        shift = lambda k: ((k % s) + 0.5) / s - 0.5  # noqa: E731 (the stratum's shift, kernels/raster.py)
        x = (2 * (cols + 0.5 - shift(rows)) / w - 1)[..., None]
        y = (1 - 2 * (rows + 0.5 + shift(cols)) / h)[..., None]
        offset = x * hx * self.right + y * hy * self.up
        if self.orthographic:
            return self.eye + offset, np.broadcast_to(self.forward, (h, w, 3)).copy()
        return np.broadcast_to(self.eye, (h, w, 3)).copy(), self.forward + offset


#: The up vector when none is given: world +Y; looking straight down (or up) along it, -Z (or +Z),
#: so that a top-down view has +X to the right and -Z (a map's north, glTF's back) at the top.
DEFAULT_UP = (0.0, 1.0, 0.0)


def _frame(func: str, eye, target, up):
    fallback = up is None
    vectors = []
    for name, value in (("eye", eye), ("target", target), ("up", DEFAULT_UP if fallback else up)):
        try:
            v = np.asarray(value, np.float64).reshape(-1)
        except (TypeError, ValueError):  # strings, objects, ragged sequences
            raise ValueError(f"{func}(): {name} must be 3 finite numbers, got {value!r}") from None
        if v.shape != (3,) or not np.isfinite(v).all():
            raise ValueError(f"{func}(): {name} must be 3 finite numbers, got {v.tolist()}")
        vectors.append(v)
    eye, target, up = vectors
    forward = target - eye
    if np.linalg.norm(forward) < 1e-12:
        raise ValueError(f"{func}(): eye and target must differ, both are {eye.tolist()}")
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if fallback and np.linalg.norm(right) < 1e-9:  # looking along +-Y
        up = np.array([0.0, 0.0, -1.0 if forward[1] < 0 else 1.0])
        right = np.cross(forward, up)
    if np.linalg.norm(up) == 0:
        raise ValueError(f"{func}(): up must not be zero, got {up.tolist()}")
    if np.linalg.norm(right) < 1e-9 * np.linalg.norm(up):
        raise ValueError(f"{func}(): up {up.tolist()} must not be parallel to the view direction {forward.tolist()}")
    right /= np.linalg.norm(right)
    return eye, forward, right, np.cross(right, forward)


def checked_resolution(func: str, resolution) -> tuple[int, int]:
    """``resolution`` as ``(height, width)`` ints > 0, or a ValueError naming ``func``."""
    try:
        h, w = resolution
    except (TypeError, ValueError):
        raise ValueError(f"{func}(): resolution must be (height, width), got {resolution!r}") from None
    if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0 for v in (h, w)):
        raise ValueError(f"{func}(): resolution must be two positive ints (height, width), got {resolution!r}")
    return int(h), int(w)


def look_at(eye, target, up=None, fov_y: float = 45.0, resolution=(512, 512)) -> Camera:
    """A pinhole camera at ``eye`` looking at ``target``.

    Args:
        eye, target: world-space points, 3 numbers each.
        up: world direction that appears upward in the image (not parallel to the view); ``None``:
            +Y, or, for a view straight down (up) the Y axis, -Z (+Z): see :data:`DEFAULT_UP`.
        fov_y: vertical field of view in degrees, in ``(0, 180)``.
        resolution: ``(height, width)`` in pixels.
    """
    eye, forward, right, cam_up = _frame("look_at", eye, target, up)
    fov = as_float("look_at", "fov_y", fov_y)
    if not 0.0 < fov < 180.0:
        raise ValueError(f"look_at(): fov_y must be in (0, 180) degrees, got {fov}")
    return Camera(eye, forward, right, cam_up, checked_resolution("look_at", resolution), fov_y=fov)


def orthographic(eye, target, up=None, height: float = 2.0, resolution=(512, 512)) -> Camera:
    """An orthographic camera at ``eye`` looking at ``target``, seeing ``height`` world units
    vertically; ``up`` as :func:`look_at` takes it."""
    eye, forward, right, cam_up = _frame("orthographic", eye, target, up)
    extent = as_float("orthographic", "height", height)
    if extent <= 0:
        raise ValueError(f"orthographic(): height must be positive, got {extent}")
    return Camera(eye, forward, right, cam_up, checked_resolution("orthographic", resolution), ortho_height=extent)
