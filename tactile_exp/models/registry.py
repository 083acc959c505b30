"""The ``model`` registry: what model files import to register themselves (no implementations
are imported here, so ``import tactile_exp.models.base`` stays free of torch)."""

from tactile_exp.models.base import Model
from tactile_exp.registry import Registry

MODELS: Registry[Model] = Registry(
    "model",
    Model,
    modules=(
        "tactile_exp.models.estimator",  # any scikit-learn-style estimator, named in YAML
        "tactile_exp.models.googlenet",
        "tactile_exp.models.haptic_cnn",
        "tactile_exp.models.haptic_lstm",
        "tactile_exp.models.linear",
        "tactile_exp.models.linear_svm",  # Chu et al.'s classifier (rows A-F)
        "tactile_exp.models.random_guess",
    ),
)
