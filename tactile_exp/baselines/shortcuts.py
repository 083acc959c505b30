"""The baselines' shortcuts: work that gives the plain per-trial code's numbers, done once.

The authors' per-trial static features of every trial come from one batched eigendecomposition
per table (``static.static_matrix``: split-independent, so shared by rows A, B, E, F and all
adjectives); the SVM grid standardises each CV draw once for every C (the draws on threads);
every trial's HMM log-likelihoods are computed once per fitted chains (shared by rows C-F); an
adjective's 16 chains are fitted on threads, each as it would be alone. The plain code (one
trial-EP at a time, one pipeline per (C, draw), chains one after the other) is kept in
``tests/baselines_oracles.py`` as the oracle the tests, and ``bench/bench_baselines.py --rows``,
compare these with; it is not a runtime path.
"""
