"""Reference results: standard RL and imitation on every paper system's training task, at fixed
budgets, with learning curves (``python -m satenv.bench.learning``, :mod:`satenv.bench.learning.cli`).

* :mod:`~satenv.bench.learning.grid`: the runs, budgets, checkpoints and test seeds;
* :mod:`~satenv.bench.learning.trainers`: each algorithm with the project's trainers;
* :mod:`~satenv.bench.learning.runner`: one run and the resumable evaluation log;
* :mod:`~satenv.bench.learning.results`: ``results.json`` from the log;
* :mod:`~satenv.bench.learning.render`: the docs page "Reference results" from ``results.json``;
* :mod:`~satenv.bench.learning.datasets`: the controllers' episodes as Minari datasets.
"""
