"""A pinhole camera: OpenGL look-at and perspective matrices, and one primary ray per pixel.

Conventions (OpenGL): right-handed world, the camera looks down its -z axis with +y up;
clip space maps the view frustum to normalised device coordinates in [-1, 1]^3 (z = -1 at
the near plane). Pixel (row, col) has its centre at image coordinates
``(x, y) = (col + 0.5, row + 0.5)``; row 0 is the top of the image, so
``x = (ndc_x + 1) / 2 * width`` and ``y = (1 - ndc_y) / 2 * height``.

Matrices are built in float64 and cast at the end: their entries mix scales (eye positions
of 1e5 next to unit vectors) and cost nothing to compute accurately.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from course.core.device import default_device
from course.core.types import Rays


def _vec3(x, name: str) -> torch.Tensor:
    v = torch.as_tensor(x, dtype=torch.float64, device="cpu")
    if v.shape != (3,):
        raise ValueError(f"{name}: expected 3 coordinates, got shape {tuple(v.shape)}")
    if not torch.isfinite(v).all():
        raise ValueError(f"{name}: expected finite coordinates, got {v.tolist()}")
    return v


def _camera_axes(eye, target, up) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Orthonormal right, true-up and backward (+z) axes of a camera, float64 (3,) each."""
    eye, target, up = _vec3(eye, "eye"), _vec3(target, "target"), _vec3(up, "up")
    forward = target - eye
    if forward.norm() == 0:
        raise ValueError(f"target: must differ from eye, both are {eye.tolist()}")
    forward = forward / forward.norm()
    if up.norm() == 0:
        raise ValueError(
            f"up: the vector is zero, {up.tolist()}; give the direction that "
            f"should point up in the image, e.g. (0, 1, 0)"
        )
    right = torch.linalg.cross(forward, up)
    # A near-zero cross product means up is (anti)parallel to the view direction: no roll.
    if right.norm() <= 1e-12 * up.norm():
        raise ValueError(
            f"up: must not be parallel to the view direction "
            f"{forward.tolist()} (target - eye, normalised), got {up.tolist()}"
        )
    right = right / right.norm()
    return right, torch.linalg.cross(right, forward), -forward


def look_at(eye, target, up, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """The (4, 4) world-to-camera matrix of ``gluLookAt``.

    eye, target, up: 3 coordinates each (sequence or tensor). The camera sits at ``eye``,
    looks toward ``target`` (its -z axis) with ``up`` projected to its +y axis.
    The rotation part is orthonormal and ``view @ [eye, 1] = [0, 0, 0, 1]``.
    """
    right, true_up, back = _camera_axes(eye, target, up)
    rotation = torch.stack([right, true_up, back])
    view = torch.eye(4, dtype=torch.float64)
    view[:3, :3] = rotation
    view[:3, 3] = -rotation @ _vec3(eye, "eye")
    return view.to(dtype)


def perspective(
    fov_y_deg: float, aspect: float, near: float, far: float, dtype: torch.dtype = torch.float64
) -> torch.Tensor:
    """The (4, 4) camera-to-clip matrix of ``gluPerspective``.

    fov_y_deg: vertical field of view in degrees, in (0, 180); aspect: width / height;
    0 < near < far; ``far = inf`` gives the infinite-far-plane limit. After the divide by w,
    z = -near maps to ndc z = -1 and z = -far to +1.
    """
    _check_fov(fov_y_deg, "fov_y_deg")
    if not aspect > 0 or math.isinf(aspect):
        raise ValueError(f"aspect: expected a positive finite width/height ratio, got {aspect}")
    _check_depth_range(near, far)
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2)
    # The far = inf limit of (far + near) / (near - far) and 2 far near / (near - far).
    z_scale = -1.0 if math.isinf(far) else (far + near) / (near - far)
    z_offset = -2.0 * near if math.isinf(far) else 2.0 * far * near / (near - far)
    return torch.tensor(
        [
            [f / aspect, 0.0, 0.0, 0.0],
            [0.0, f, 0.0, 0.0],
            [0.0, 0.0, z_scale, z_offset],
            [0.0, 0.0, -1.0, 0.0],
        ],
        dtype=torch.float64,
    ).to(dtype)


def _check_fov(fov: float, name: str) -> None:
    if not 0 < fov < 180:
        raise ValueError(f"{name}: expected a field of view in (0, 180) degrees, got {fov}")


def _check_depth_range(near: float, far: float) -> None:
    if not 0 < near < math.inf:
        raise ValueError(f"near: expected a positive finite distance, got {near}")
    if not far > near:
        raise ValueError(f"far: expected a distance greater than near={near}, got {far}")


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking from ``eye`` at ``target``.

    fov_y: vertical field of view in degrees; width, height: image size in pixels;
    near, far: clip distances (used by the projection matrix, i.e. the rasterizer).
    Use ``dataclasses.replace(camera, width=..., height=...)`` to render at another size.
    """

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_y: float = 45.0
    width: int = 256
    height: int = 256
    near: float = 0.01
    far: float = 1000.0

    def __post_init__(self) -> None:
        for name in ("eye", "target", "up"):
            object.__setattr__(self, name, tuple(_vec3(getattr(self, name), name).tolist()))
        for name in ("width", "height"):
            size = getattr(self, name)
            if isinstance(size, bool) or not isinstance(size, int) or size <= 0:
                raise ValueError(f"{name}: expected a positive integer pixel count, got {size!r}")
        _check_fov(self.fov_y, "fov_y")
        _check_depth_range(self.near, self.far)
        _camera_axes(self.eye, self.target, self.up)  # rejects eye == target and a parallel up

    @property
    def aspect(self) -> float:
        return self.width / self.height

    def view(self, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """(4, 4) world-to-camera matrix."""
        return look_at(self.eye, self.target, self.up, dtype)

    def projection(self, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """(4, 4) camera-to-clip matrix."""
        return perspective(self.fov_y, self.aspect, self.near, self.far, dtype)

    def view_projection(self, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """(4, 4) world-to-clip matrix ``projection @ view`` (multiplied in float64)."""
        return (self.projection() @ self.view()).to(dtype)


def primary_rays(
    camera: Camera, device: str | torch.device | None = None, dtype: torch.dtype = torch.float32
) -> Rays:
    """One ray per pixel, ``height * width`` rays in row-major order (row 0 at the top).

    Ray ``row * width + col`` leaves the eye through the centre of pixel (row, col);
    directions are unit length, ``t_min = 0`` and ``t_max = inf``. Directions are
    computed in float64 and then cast, so low-precision rays are correctly rounded.
    """
    device = default_device(device)
    right, true_up, back = (
        a.to(device) for a in _camera_axes(camera.eye, camera.target, camera.up)
    )
    half_h = math.tan(math.radians(camera.fov_y) / 2)
    half_w = half_h * camera.aspect
    cols = torch.arange(camera.width, dtype=torch.float64, device=device)
    rows = torch.arange(camera.height, dtype=torch.float64, device=device)
    # Pixel centres on the image plane at distance 1 in front of the eye.
    x = (2 * (cols + 0.5) / camera.width - 1) * half_w  # (W,) left to right
    y = (1 - 2 * (rows + 0.5) / camera.height) * half_h  # (H,) top to bottom
    directions = x[None, :, None] * right + y[:, None, None] * true_up - back  # (H, W, 3)
    directions = directions.reshape(-1, 3)
    directions = directions / directions.norm(dim=1, keepdim=True)
    eye = torch.tensor(camera.eye, dtype=torch.float64, device=device)
    return Rays.create(eye, directions.to(dtype), 0.0, math.inf)
