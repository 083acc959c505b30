"""The Hydra edge beside ``__main__``: what runs inside Hydra (the sweep callback and a sweep
job's bookkeeping), above the engine it calls; ``runtime/`` stays the bottom (processes)."""
