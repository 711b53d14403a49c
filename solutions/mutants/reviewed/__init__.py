"""Generated mutants that survive the graders, reviewed, one file per lab (``labN.py``, a
dict ``EQUIVALENT``): each is equivalent to the reference for every input the contract
allows, or changes only what the contract leaves free, and its reason quotes the docstring
sentence that allows it (the docstring says so first where it did not). ``rtcourse mutants
--generated`` counts these as neither killed nor survived. Ids are
``module:function:kind:n`` (see course.grading.mutate)."""
