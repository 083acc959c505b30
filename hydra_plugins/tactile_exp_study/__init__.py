"""tactile_exp's Hydra plugins: the ``study`` sweeper (issue 28)."""
