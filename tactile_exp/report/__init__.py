"""The report: Table I, Fig. 5, Fig. 6 and Table III regenerated from tracked runs
(``python -m tactile_exp.report``, see ``cli``)."""
