"""pytest: the package's docstring examples run as tests; ``python -m montecarlo`` is not one."""

collect_ignore = ["montecarlo/__main__.py"]
