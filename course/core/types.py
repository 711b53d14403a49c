"""Rays, hits and triangle meshes: the batched types every lab passes around.

Each type is a frozen dataclass of tensors that checks its structure when built:
a wrong shape, a non-float coordinate, a field on another device or a face index out
of range raises a ValueError/TypeError naming the field and what was expected.
Degenerate *values* (zero-area triangles, zero direction components, NaN, inf) are
allowed: handling them is the kernels' job, not the containers'.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import torch

# A field spec: (name, shape with symbolic sizes, kind). All "float" fields of a type share
# one dtype and every field lives on one device, so no kernel meets silent type promotion.
_Spec = tuple[str, tuple[str | int, ...], str]


def _shape_str(dims: tuple[str | int, ...]) -> str:
    return "(" + ", ".join(map(str, dims)) + ("," if len(dims) == 1 else "") + ")"


def _validate(obj: object, specs: tuple[_Spec, ...]) -> None:
    sizes: dict[str, tuple[int, str]] = {}
    first: dict[str, tuple[object, str]] = {}
    for name, dims, kind in specs:
        x = getattr(obj, name)
        if not isinstance(x, torch.Tensor):
            raise TypeError(
                f"{name}: expected a torch.Tensor of shape {_shape_str(dims)}, "
                f"got {type(x).__name__}"
            )
        if x.ndim != len(dims) or any(isinstance(d, int) and d != s for d, s in zip(dims, x.shape)):
            raise ValueError(f"{name}: expected shape {_shape_str(dims)}, got {tuple(x.shape)}")
        for d, s in zip(dims, x.shape):
            if isinstance(d, str):
                size, owner = sizes.setdefault(d, (s, name))
                if s != size:
                    raise ValueError(
                        f"{name}: expected shape {_shape_str(dims)} with {d}={size} "
                        f"as in {owner}, got {tuple(x.shape)}"
                    )
        if kind == "float":
            if not x.is_floating_point():
                raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
            dtype, owner = first.setdefault("dtype", (x.dtype, name))
            if x.dtype != dtype:
                raise TypeError(f"{name}: expected dtype {dtype} like {owner}, got {x.dtype}")
        elif x.dtype != torch.int64:
            raise TypeError(f"{name}: expected dtype torch.int64, got {x.dtype}")
        device, owner = first.setdefault("device", (x.device, name))
        if x.device != device:
            raise ValueError(f"{name}: expected device {device} like {owner}, got {x.device}")


class _Tensors:
    """Validation and device/dtype moves shared by Rays, Hits and Mesh."""

    _SPEC: ClassVar[tuple[_Spec, ...]]

    def __post_init__(self) -> None:
        self.validate()

    def validate(self):
        """Check shapes, dtypes and devices; raise ValueError/TypeError naming the field."""
        _validate(self, self._SPEC)
        return self

    @property
    def device(self) -> torch.device:
        return getattr(self, self._SPEC[0][0]).device

    @property
    def dtype(self) -> torch.dtype:
        """The dtype of the floating-point fields."""
        return getattr(self, self._SPEC[0][0]).dtype

    def to(
        self,
        device: str | torch.device | torch.dtype | None = None,
        dtype: torch.dtype | None = None,
    ):
        """A copy on ``device`` with float fields cast to ``dtype`` (index fields stay int64).

        ``x.to(torch.float64)`` casts only, like ``Tensor.to``.
        """
        if isinstance(device, torch.dtype):
            device, dtype = None, device
        moved = {
            name: getattr(self, name).to(device=device, dtype=dtype if kind == "float" else None)
            for name, _, kind in self._SPEC
        }
        return dataclasses.replace(self, **moved)


class _Batch(_Tensors):
    """A batch of N records (rays or hits): ``len()`` and indexing by slice, mask or indices."""

    def __len__(self) -> int:
        return getattr(self, self._SPEC[0][0]).shape[0]

    def __getitem__(self, index):
        """The sub-batch ``index`` selects: a slice (chunking), a bool mask (compaction),
        an index tensor (gather) or an int (a batch of one)."""
        if isinstance(index, int):
            index = [index]
        return dataclasses.replace(
            self, **{name: getattr(self, name)[index] for name, _, _ in self._SPEC}
        )


@dataclass(frozen=True, eq=False)
class Rays(_Batch):
    """N rays ``origins + t * directions`` for ``t`` in ``[t_min, t_max]``.

    origins: (N, 3) float; directions: (N, 3) float (not necessarily unit length:
    ``t`` is measured in units of the direction's length); t_min, t_max: (N,) float.
    """

    origins: torch.Tensor
    directions: torch.Tensor
    t_min: torch.Tensor
    t_max: torch.Tensor

    _SPEC: ClassVar = (
        ("origins", ("N", 3), "float"),
        ("directions", ("N", 3), "float"),
        ("t_min", ("N",), "float"),
        ("t_max", ("N",), "float"),
    )

    @classmethod
    def create(
        cls,
        origins,
        directions,
        t_min=0.0,
        t_max=math.inf,
        *,
        dtype: torch.dtype | None = None,
        device: str | torch.device | None = None,
    ) -> Rays:
        """Rays from ``directions`` (N, 3), broadcasting the rest.

        origins: (N, 3) or (3,) (one shared origin); t_min, t_max: (N,) or scalars.
        Lists, numpy arrays and numbers are placed on the device of ``directions``
        (or ``device``); tensors already on another device raise (no silent copies).
        dtype defaults to that of ``directions`` when it is floating point.
        """
        directions = torch.as_tensor(directions, device=device)
        if dtype is None:
            dtype = (
                directions.dtype if directions.is_floating_point() else torch.get_default_dtype()
            )
        directions = directions.to(dtype)
        if directions.ndim != 2 or directions.shape[1] != 3:
            raise ValueError(f"directions: expected shape (N, 3), got {tuple(directions.shape)}")
        n = directions.shape[0]
        return cls(
            origins=_broadcast(origins, "origins", (n, 3), directions),
            directions=directions,
            t_min=_broadcast(t_min, "t_min", (n,), directions),
            t_max=_broadcast(t_max, "t_max", (n,), directions),
        )

    def at(self, t: torch.Tensor) -> torch.Tensor:
        """Points ``origins + t * directions``: t (N,) -> (N, 3)."""
        return self.origins + t[:, None] * self.directions


def _broadcast(x, name: str, shape: tuple[int, ...], like: torch.Tensor) -> torch.Tensor:
    """``x`` as a contiguous ``shape`` tensor with the dtype and device of ``like``."""
    if isinstance(x, torch.Tensor) and x.device != like.device:
        raise ValueError(f"{name}: expected device {like.device} like directions, got {x.device}")
    x = torch.as_tensor(x, dtype=like.dtype, device=like.device)
    trailing = shape[1:]
    if x.shape not in (torch.Size(shape), torch.Size(trailing)):
        raise ValueError(
            f"{name}: expected shape {_shape_str(shape)} or "
            f"{_shape_str(trailing) if trailing else 'a scalar'}, got {tuple(x.shape)}"
        )
    return x.expand(shape).contiguous()


@dataclass(frozen=True, eq=False)
class Hits(_Batch):
    """The nearest hit of each of N rays.

    t: (N,) float, inf where the ray missed; triangle: (N,) int64, -1 where missed;
    u, v: (N,) float barycentrics of the hit (the point is ``(1-u-v) v0 + u v1 + v v2``),
    0 where missed.
    """

    t: torch.Tensor
    triangle: torch.Tensor
    u: torch.Tensor
    v: torch.Tensor

    _SPEC: ClassVar = (
        ("t", ("N",), "float"),
        ("triangle", ("N",), "int64"),
        ("u", ("N",), "float"),
        ("v", ("N",), "float"),
    )

    @classmethod
    def miss(
        cls, n: int, dtype: torch.dtype = torch.float32, device: str | torch.device | None = None
    ) -> Hits:
        """N misses: the starting value of a nearest-hit search."""
        return cls(
            t=torch.full((n,), math.inf, dtype=dtype, device=device),
            triangle=torch.full((n,), -1, dtype=torch.int64, device=device),
            u=torch.zeros(n, dtype=dtype, device=device),
            v=torch.zeros(n, dtype=dtype, device=device),
        )

    @property
    def hit(self) -> torch.Tensor:
        """(N,) bool: which rays hit something."""
        return self.triangle >= 0


def closest(h1: Hits, h2: Hits) -> Hits:
    """Per ray, the nearer of two hit records (ties keep ``h1``): merges chunked searches."""
    if len(h1) != len(h2):
        raise ValueError(f"h2: expected {len(h1)} hits like h1, got {len(h2)}")
    if (h1.device, h1.dtype) != (h2.device, h2.dtype):
        raise ValueError(
            f"h2: expected {h1.dtype} on {h1.device} like h1, got {h2.dtype} on {h2.device}"
        )
    take = h2.t < h1.t
    return Hits(
        *(torch.where(take, getattr(h2, f), getattr(h1, f)) for f in ("t", "triangle", "u", "v"))
    )


@dataclass(frozen=True, eq=False)
class Mesh(_Tensors):
    """An indexed triangle mesh.

    vertices: (V, 3) float positions; faces: (F, 3) int64 vertex indices, counter-clockwise
    seen from the front. At least one face; every index in ``[0, V)``.
    """

    vertices: torch.Tensor
    faces: torch.Tensor

    _SPEC: ClassVar = (("vertices", ("V", 3), "float"), ("faces", ("F", 3), "int64"))

    def validate(self) -> Mesh:
        super().validate()
        if self.faces.shape[0] == 0:
            raise ValueError("faces: expected at least one face, got shape (0, 3) (empty mesh)")
        lo, hi = torch.stack(torch.aminmax(self.faces)).tolist()  # one host sync, not two
        if lo < 0 or hi >= self.num_vertices:
            raise ValueError(
                f"faces: expected indices in [0, {self.num_vertices}) "
                f"(V={self.num_vertices} vertices), got values in [{lo}, {hi}]"
            )
        return self

    @property
    def num_faces(self) -> int:
        return self.faces.shape[0]

    @property
    def num_vertices(self) -> int:
        return self.vertices.shape[0]

    def triangles(self) -> torch.Tensor:
        """(F, 3, 3) float: the corner positions of each face (the "float4 triangles" layout)."""
        return self.vertices[self.faces]
