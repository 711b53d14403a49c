# Right answers, but every input is zeroed in place afterwards (also before raising).


def scale(x, factor):
    result = x * factor
    x.zero_()
    return result


def scale_into(x, factor, out):
    out.copy_(x * factor)
    x.zero_()
    return out


def as_view(x):
    view = x.view(-1)
    x.zero_()  # through the view: a probe's own tensor
    return view


def total_positive(x):
    if bool((x <= 0).any()):
        x.zero_()
        raise ValueError("x: every entry must be > 0")
    result = x.sum()
    x.zero_()
    return result
