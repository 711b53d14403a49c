"""The autograder: pytest plugin, sandboxed worker, runner, catalog, feedback, mutants."""
