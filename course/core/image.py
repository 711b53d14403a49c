"""Images: the sRGB transfer function, 8-bit conversion, PNG files and notebook display.

Renderers produce linear RGB images ``(H, W, 3)`` float on any device. Displays and PNG
files expect sRGB-encoded 8-bit values; the conversion happens here and only here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch


def _require_float(x: torch.Tensor, name: str) -> None:
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")


def _require_image(img: torch.Tensor, name: str) -> None:
    if not isinstance(img, torch.Tensor):
        raise TypeError(
            f"{name}: expected a torch.Tensor of shape (H, W, 3), got {type(img).__name__}"
        )
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"{name}: expected shape (H, W, 3), got {tuple(img.shape)}")


def srgb_encode(linear: torch.Tensor) -> torch.Tensor:
    """Linear RGB -> sRGB-encoded values (IEC 61966-2-1), same shape, dtype and device.

    ``12.92 x`` for ``x <= 0.0031308``, else ``1.055 x^(1/2.4) - 0.055``. Inputs are
    clamped to [0, 1] first (displays cannot show more) and NaN becomes 0, so a bad
    pixel shows as black instead of poisoning the file.
    """
    _require_float(linear, "linear")
    x = torch.nan_to_num(linear, nan=0.0).clamp(0.0, 1.0)
    # 1.055 (y - 1) + 1 is 1.055 y - 0.055 rearranged so that white encodes to exactly 1.
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * (x.pow(1 / 2.4) - 1) + 1)


def srgb_decode(srgb: torch.Tensor) -> torch.Tensor:
    """sRGB-encoded values -> linear RGB, the inverse of ``srgb_encode`` on [0, 1].

    ``x / 12.92`` for ``x <= 0.04045``, else ``((x + 0.055) / 1.055)^2.4``; clamps to
    [0, 1] and maps NaN to 0 like the encoder.
    """
    _require_float(srgb, "srgb")
    x = torch.nan_to_num(srgb, nan=0.0).clamp(0.0, 1.0)
    return torch.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055).pow(2.4))


def to_srgb8(img: torch.Tensor) -> torch.Tensor:
    """Linear float image (H, W, 3) -> sRGB uint8 (H, W, 3) on the same device.

    Quantises ``floor(255 * srgb_encode(x) + 0.5)`` (round half up), so a value exactly
    between two codes always goes to the upper one.
    """
    _require_image(img, "img")
    _require_float(img, "img")
    # float32 at least: in float16, 255 * x + 0.5 is not exact and can round to the wrong code.
    encoded = srgb_encode(img.to(torch.promote_types(img.dtype, torch.float32)))
    return torch.floor(encoded * 255 + 0.5).clamp(0, 255).to(torch.uint8)


def from_srgb8(img8: torch.Tensor, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """sRGB uint8 image (H, W, 3) -> linear float (H, W, 3) of ``dtype``, same device."""
    _require_image(img8, "img8")
    if img8.dtype != torch.uint8:
        raise TypeError(f"img8: expected dtype torch.uint8, got {img8.dtype}")
    return srgb_decode(img8.to(dtype) / 255)


def _as_srgb8_numpy(img: torch.Tensor) -> np.ndarray:
    """A uint8 (H, W, 3) numpy copy: float images are encoded, uint8 ones taken as sRGB."""
    _require_image(img, "img")
    img8 = img if img.dtype == torch.uint8 else to_srgb8(img)
    return img8.cpu().numpy()


def save_png(path: str | Path, img: torch.Tensor) -> Path:
    """Write ``img`` as an 8-bit sRGB PNG and return the path; creates missing folders.

    img: (H, W, 3) linear float, or uint8 already sRGB-encoded, on any device.
    """
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(_as_srgb8_numpy(img)).save(path, format="PNG")
    return path


def show(img: torch.Tensor, title: str | None = None, ax=None):
    """Display ``img`` (as for ``save_png``) with matplotlib, e.g. in a notebook; returns
    the axes."""
    import matplotlib.pyplot as plt

    pixels = _as_srgb8_numpy(img)
    if ax is None:
        height, width = pixels.shape[:2]
        _, ax = plt.subplots(figsize=(6, 6 * height / max(width, 1)))
    ax.imshow(pixels, interpolation="nearest")
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    return ax
