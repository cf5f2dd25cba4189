"""Benchmarks: each module a script on the scripts' one config mechanism
(``experiments.pipeline.cli``: a frozen ``Args`` dataclass with documented
fields, and its presets). Run one from the repository root::

  python -m benchmarks.NAME --help
  python -m benchmarks.NAME --preset=smoke   # where a CPU-sized preset exists

Each prints its table and writes its JSON atomically, by default under
``out/benchmarks/`` (or the ``--workdir`` it is given), outside the source
tree. The modules import nothing from this package, so
``PYTHONPATH=. python benchmarks/NAME.py`` runs them too.
"""
