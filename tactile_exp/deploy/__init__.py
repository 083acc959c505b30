"""A finished job outside this package: an MLflow pyfunc model (``mlflow_model``, served by
``mlflow models serve``, registered in the Model Registry) and ONNX networks (``onnx_export``).

``python -m tactile_exp.deploy --help`` is the command line; docs/deployment.md the guide.
"""
