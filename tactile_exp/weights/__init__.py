"""Trunk weights files: ``python -m tactile_exp.weights convert-caffe`` (MINC / bvlc_googlenet)."""
