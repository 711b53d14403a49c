"""The autograder's fixtures (``impl``, ``device``) and markers (``points``, ``task``,
``gpu``, ``slow``) come from :mod:`course.grading.plugin`, enabled for every run in
pyproject.toml. ``--impl labs|solutions|PATH`` picks the implementation under test."""

# The toy course and the hostile submissions are inputs of tests/meta, not tests.
collect_ignore = ["meta/toycourse", "meta/hostile"]
