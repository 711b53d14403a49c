"""Operation counts and live-value estimates against counts worked by hand."""

import pytest
import torch

from course.measure.accounting import LECTURE_COUNTS, OpCounts, count_ops, live_values

# Sizes that differ from each other and from 3, so lane dims are unambiguous.
N, M = 7, 5


def vectors(*shape, count=2):
    generator = torch.Generator().manual_seed(0)
    return [torch.randn(*shape, generator=generator) for _ in range(count)]


def arithmetic(counts: OpCounts) -> dict[str, float]:
    """The non-zero categories, for compact assertions."""
    row = {
        "mul": counts.mul,
        "add": counts.add,
        "div": counts.div,
        "sqrt": counts.sqrt,
        "fma": counts.fma,
        "compare": counts.compare,
        "abs": counts.abs,
        "select": counts.select,
        "other": counts.other,
    }
    return {name: value for name, value in row.items() if value}


# --- count_ops on expressions counted by hand ---------------------------------------------


def test_mul_then_add():
    a, b, c = vectors(N, count=3)
    counts = count_ops(lambda a, b, c: a * b + c, a, b, c)
    assert arithmetic(counts) == {"mul": 1, "add": 1}
    assert counts.lanes == N


def test_addcmul_is_one_fused_mul_add():
    a, b, c = vectors(N, count=3)
    counts = count_ops(torch.addcmul, c, a, b)
    assert arithmetic(counts) == {"mul": 1, "add": 1, "fma": 1}


def test_scaled_add_is_fused():
    a, b = vectors(N)
    assert arithmetic(count_ops(lambda a, b: torch.add(a, b, alpha=2), a, b)) == {
        "mul": 1,
        "add": 1,
        "fma": 1,
    }


@pytest.mark.parametrize(
    "fn, expected",
    [
        (torch.sqrt, {"sqrt": 1}),
        (torch.rsqrt, {"sqrt": 1}),
        (lambda x: x**0.5, {"sqrt": 1}),
        (lambda x: x**2, {"mul": 1}),
        (lambda x: 1 / x, {"div": 1}),
        (torch.reciprocal, {"div": 1}),
        (lambda x: x / 2, {"mul": 1}),
        (torch.abs, {"abs": 1}),
        (torch.exp, {"other": 1}),
        (lambda x: -x, {}),
        (lambda x: 1 - x, {"add": 1}),
    ],
    ids=["sqrt", "rsqrt", "pow_half", "square", "one_over", "reciprocal", "div_const", "abs",
         "exp", "neg_free", "rsub"],
)  # fmt: skip
def test_unary(fn, expected):
    (x,) = vectors(N, count=1)
    assert arithmetic(count_ops(fn, x.abs() + 1)) == expected


def test_division_of_tensors():
    a, b = vectors(N)
    assert arithmetic(count_ops(torch.div, a, b)) == {"div": 1}


@pytest.mark.parametrize(
    "fn, expected",
    [
        (lambda a, b: a < b, {"compare": 1}),
        (lambda a, b: a >= b, {"compare": 1}),
        (torch.minimum, {"compare": 1}),
        (torch.max, {"compare": 1}),
        (lambda a, b: a.clamp(0, 1), {"compare": 2}),
        (lambda a, b: a.clamp(min=0), {"compare": 1}),
        (lambda a, b: torch.where(a < b, a, b), {"compare": 1, "select": 1}),
    ],
    ids=["lt", "ge", "minimum", "max_binary", "clamp_both", "clamp_min", "where"],
)
def test_comparisons_and_selects(fn, expected):
    a, b = vectors(N)
    assert arithmetic(count_ops(fn, a, b)) == expected


def test_sum_of_three_is_two_adds():
    (v,) = vectors(N, 3, count=1)
    assert arithmetic(count_ops(lambda v: v.sum(-1), v)) == {"add": 2}


def test_mean_and_norm():
    (v,) = vectors(N, 3, count=1)
    assert arithmetic(count_ops(lambda v: v.mean(-1), v)) == {"add": 2, "div": 1}
    assert arithmetic(count_ops(lambda v: torch.linalg.norm(v, dim=-1), v)) == {
        "mul": 3,
        "add": 2,
        "sqrt": 1,
    }


@pytest.mark.parametrize(
    "dot",
    [
        lambda a, b: (a * b).sum(-1),
        lambda a, b: torch.einsum("ni,ni->n", a, b),
        lambda a, b: torch.linalg.vecdot(a, b),
        lambda a, b: (a.unsqueeze(-2) @ b.unsqueeze(-1)).squeeze(-1).squeeze(-1),
    ],
    ids=["mul_sum", "einsum", "vecdot", "batched_matmul"],
)
def test_dot_products_are_three_mul_two_add(dot):
    a, b = vectors(N, 3)
    assert arithmetic(count_ops(dot, a, b)) == {"mul": 3, "add": 2}


def test_matrix_times_vectors():
    (v,) = vectors(N, 3, count=1)
    matrix = torch.eye(3)
    # Each of the 3 outputs per lane: 3 mul, 2 add.
    assert arithmetic(count_ops(lambda v: v @ matrix, v, lanes=N)) == {"mul": 9, "add": 6}


def manual_cross(a, b):
    ax, ay, az = a.unbind(-1)
    bx, by, bz = b.unbind(-1)
    return torch.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], dim=-1)


def rolled_cross(a, b):
    return a[:, [1, 2, 0]] * b[:, [2, 0, 1]] - a[:, [2, 0, 1]] * b[:, [1, 2, 0]]


@pytest.mark.parametrize(
    "cross",
    [
        lambda a, b: torch.linalg.cross(a, b),
        lambda a, b: torch.cross(a, b, dim=-1),
        manual_cross,
        rolled_cross,
    ],
    ids=["linalg_cross", "torch_cross", "unbind_stack", "fancy_index"],
)
def test_cross_product_is_six_mul_three_sub_per_vector(cross):
    a, b = vectors(N, 3)
    torch.testing.assert_close(cross(a, b), torch.linalg.cross(a, b))
    assert arithmetic(count_ops(cross, a, b, lanes=N)) == {"mul": 6, "add": 3}


def test_index_and_mask_arithmetic_is_free():
    (x,) = vectors(N, count=1)
    index = torch.arange(N)
    assert arithmetic(count_ops(lambda i: (i + 1) * 2, index)) == {}
    assert arithmetic(count_ops(lambda x: (x > 0) & (x < 1), x)) == {"compare": 2}


def test_data_movement_is_free():
    (x,) = vectors(N, count=1)

    def shuffle(x):
        both = torch.cat([torch.stack([x, x]), x[None]]).clone()
        return both.to(torch.float64)[torch.tensor([2, 0])].flip(0)[0]

    assert arithmetic(count_ops(shuffle, x)) == {}


# --- lanes ------------------------------------------------------------------------------------


def test_broadcast_rays_against_triangles_default_to_pair_lanes():
    (rays,) = vectors(N, 1, 3, count=1)
    (triangles,) = vectors(1, M, 3, count=1)
    counts = count_ops(lambda r, t: (r * t).sum(-1), rays, triangles)
    assert counts.lanes == N * M
    assert arithmetic(counts) == {"mul": 3, "add": 2}
    explicit = count_ops(lambda r, t: (r * t).sum(-1), rays, triangles, lanes=(N, M))
    assert explicit == counts


def test_per_triangle_work_is_amortised_over_rays():
    (origins,) = vectors(N, 1, 3, count=1)
    v0, v1 = vectors(1, M, 3)

    def f(o, v0, v1):
        edge = v1 - v0  # (1, M, 3): 3 M subtractions, shared by the N rays
        return ((o - v0) * edge).sum(-1)

    counts = count_ops(f, origins, v0, v1)
    assert counts.add == pytest.approx(3 / N + 3 + 2)
    assert counts.mul == 3


def test_lanes_must_be_positive():
    (x,) = vectors(N, count=1)
    with pytest.raises(ValueError, match="lanes"):
        count_ops(torch.exp, x, lanes=0)
    with pytest.raises(ValueError, match="lanes"):
        count_ops(lambda x: float(x.sum()), x)


# --- a whole kernel ---------------------------------------------------------------------------


def moller_trumbore(o, d, v0, v1, v2):
    """Textbook Moller-Trumbore for paired rays and triangles, all (K, 3)."""
    e1, e2 = v1 - v0, v2 - v0  # 6 sub
    p = torch.linalg.cross(d, e2)  # 6 mul 3 sub
    inv_det = 1.0 / (e1 * p).sum(-1)  # 3 mul 2 add, 1 div
    s = o - v0  # 3 sub
    u = (s * p).sum(-1) * inv_det  # 4 mul 2 add
    q = torch.linalg.cross(s, e1)  # 6 mul 3 sub
    v = (d * q).sum(-1) * inv_det  # 4 mul 2 add
    t = (e2 * q).sum(-1) * inv_det  # 4 mul 2 add
    return t, u, v


def test_moller_trumbore_counted_by_hand():
    args = vectors(11, 3, count=5)
    counts = count_ops(moller_trumbore, *args)
    assert arithmetic(counts) == {"mul": 27, "add": 23, "div": 1}
    assert counts.lanes == 11


# --- the lecture's cycle bound ----------------------------------------------------------------


@pytest.mark.parametrize(
    "name, bound, cycles",
    [
        ("plane + area", 4 * (39 + 14), (248, 404)),
        ("Moller-Trumbore", 4 * (23 + 1), (132, 224)),
        ("Woop unit triangle", 4 * (20 + 0), (116, 196)),
    ],
)
def test_lecture_cycle_numbers(name, bound, cycles):
    counts = LECTURE_COUNTS[name]
    assert counts.cycles_bound() == bound
    assert counts.cycles_range() == cycles


def test_cycle_bound_values():
    assert OpCounts(mul=39, add=53, div=1).cycles_bound() == 212
    assert OpCounts(mul=23, add=24, div=1).cycles_bound() == 96
    assert OpCounts(mul=20, add=20, div=1).cycles_bound() == 80


def test_cycle_bound_with_more_muls_than_adds():
    # 10 muls and no adds issue in 10 x 4 cycles: nothing to fuse, nothing left over.
    assert OpCounts(mul=10).cycles_bound() == 40


def test_fused_ops_do_not_change_the_bound_but_narrow_the_range():
    fused = OpCounts(mul=4, add=4, fma=4)
    assert fused.cycles_bound() == OpCounts(mul=4, add=4).cycles_bound() == 16
    assert fused.cycles_range() == (16, 16)


def test_table_lists_every_variant():
    table = OpCounts.table(LECTURE_COUNTS)
    lines = table.splitlines()
    assert lines[0].startswith("| variant | mul | add/sub")
    assert len(lines) == 2 + len(LECTURE_COUNTS)
    assert "| Moller-Trumbore | 23 | 24 |" in table
    assert "248-404" in table


# --- live_values --------------------------------------------------------------------------------


def test_mul_add_keeps_three_values():
    a, b = vectors(N)
    estimate = live_values(lambda a, b: (a * b) + a, a, b)
    # a, b and a * b; the sum takes the place of the product, which dies right after it.
    assert estimate.peak == 3
    assert estimate.inputs == 2
    assert estimate.peak_after == 0 and estimate.ops[0] == "mul"
    assert estimate.timeline == (2, 3, 3)
    # With b dead after its only use, two registers suffice.
    assert estimate.peak_last_use == 2


def chain_kept(a):
    x = a * 2
    y = x * 3
    z = y * 4
    return z * 5


def chain_freed(a):
    x = a * 2
    y = x * 3
    del x
    z = y * 4
    del y
    return z * 5


def test_freeing_temporaries_early_lowers_the_peak():
    (a,) = vectors(N, count=1)
    kept, freed = live_values(chain_kept, a), live_values(chain_freed, a)
    assert kept.peak == 4  # a, x, y, z
    assert freed.peak == 2  # a and the latest value
    # A register allocator frees each value after its last use either way.
    assert kept.peak_last_use == freed.peak_last_use == 1


def test_rays_and_triangles_count_their_own_values_per_pair():
    origins, directions = vectors(N, 3)
    (triangles,) = vectors(M, 3, 3, count=1)

    def plane_distance(o, d, tri):
        v0 = tri[:, 0]
        return ((o[:, None] - v0) * d[:, None]).sum(-1)  # (N, M)

    estimate = live_values(plane_distance, origins, directions, triangles)
    assert estimate.lane_shape == (N, M)
    assert estimate.inputs == 6 + 9  # a ray, a triangle
    assert estimate.peak == 15 + 3  # plus one (N, M, 3) temporary
    assert estimate.timeline[-1] == 15 + 1  # plus the result


def test_views_add_no_values():
    (v,) = vectors(N, 3, count=1)

    def first_plus_second(v):
        x, y, _ = v.unbind(-1)
        return x + y

    estimate = live_values(first_plus_second, v)
    assert estimate.inputs == 3
    assert estimate.peak == 4


def test_moller_trumbore_register_estimate():
    args = vectors(11, 3, count=5)
    estimate = live_values(moller_trumbore, *args)
    assert estimate.inputs == 15
    assert estimate.timeline[-1] == 15 + 3  # the inputs and t, u, v
    # Named temporaries stay alive in Python; freed at their last use, it is close to the
    # lecture's budget of 23 registers.
    assert estimate.peak_last_use < estimate.peak
    assert 15 < estimate.peak_last_use <= 23
