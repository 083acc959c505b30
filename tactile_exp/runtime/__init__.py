"""The processes a job or a sweep runs in: worker pools (``workers``), SIGTERM as an exception
(``termination``), the Hydra sweep callback (``sweep``) and what ``/proc`` says about processes,
with the one way to stop child processes (``processes``); the process's freed heap handed back
(``memory``) and one BLAS thread for small products (``blas``)."""
