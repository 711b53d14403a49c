"""Lab 4: correct alternatives (see ``solutions/alternatives/__init__.py``)."""

from course.grading.mutants import Mutant

M = "lab4_march"

ALTERNATIVES = [
    Mutant(
        name="hg_textbook_in_float64",
        module=M,
        function="henyey_greenstein",
        find="cos_theta = cos_theta.clamp(-1, 1)\n"
        "    base = torch.where(\n"
        "        g >= 0, (1 - g) ** 2 + 2 * g * (1 - cos_theta), "
        "(1 + g) ** 2 - 2 * g * (1 + cos_theta)\n"
        "    )\n"
        "    return (1 - g) * (1 + g) / (4 * math.pi * base * base.sqrt())",
        replace="dtype = torch.result_type(cos_theta, g)\n"
        "    c = cos_theta.to(torch.float64).clamp(-1, 1)\n"
        "    g = g.to(torch.float64) if isinstance(g, torch.Tensor) else float(g)\n"
        "    value = (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * c) ** 1.5)\n"
        "    return value.to(dtype)",
        tests="henyey_greenstein",
        why="the textbook form, whose 1 + g^2 - 2 g cos cancels near the peak, computed in "
        "float64 (where the cancellation costs nothing a float32 result can see) and "
        "rounded once",
    ),
]
