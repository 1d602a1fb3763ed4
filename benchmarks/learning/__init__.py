"""Reference results: standard RL and imitation on every paper system's training task, at fixed
budgets, with learning curves (``python -m benchmarks.learning``, :mod:`benchmarks.learning.cli`).

* :mod:`~benchmarks.learning.grid`: the runs, budgets, checkpoints and test seeds;
* :mod:`~benchmarks.learning.trainers`: each algorithm with the project's trainers;
* :mod:`~benchmarks.learning.runner`: one run and the resumable evaluation log;
* :mod:`~benchmarks.learning.results`: ``results.json`` from the log;
* :mod:`~benchmarks.learning.render`: the docs page "Reference results" from ``results.json``;
* :mod:`~benchmarks.learning.datasets`: the controllers' episodes as Minari datasets.
"""
