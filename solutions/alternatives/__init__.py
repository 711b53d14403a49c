"""Correct alternative solutions: another way a student may rightly write a function (float64
inside and rounded once, another loop order, another valid tree, another correct formula),
each applied to the reference as a find/replace (``course.grading.mutants.Mutant``). Every
one must keep every point of the tests its ``tests`` expression selects: a grader that fails
one of them tests the reference's incidental choices, not the docstring's promises
(``tests/meta/test_alternatives.py``)."""
